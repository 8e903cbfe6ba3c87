%% @doc What Braitenberg's vehicles share: two readings in, one wheel law
%% out. `toroco_lib_fear' and `toroco_lib_love' are the two callback
%% modules; this module is their common engine (ports, states, emission).
%%
%% A vehicle's module exports `law/3': `(Left, Right, Params) -> {LeftWheel,
%% RightWheel}'; the module, not a fun, is kept, so a hot reload of the
%% vehicle takes effect at once.
%%
%% Each vehicle keeps its two readings, `left' and `right' (numbers, e.g.
%% the light sensors' 0..1023); while either reaches `threshold' it latches
%% the law's `{Left, Right}' (emitted when it changes), and below it lets go
%% so lower layers can search.
-module(toroco_lib_braitenberg).

-export([interface/0, init/3, handle_input/4]).

-spec interface() -> #{inputs := [left | right], outputs := [motors]}.
interface() -> #{inputs => [left, right], outputs => [motors]}.

-spec init(term(), [toroco_lib_params:spec()], module()) ->
          {ok, dark, map()} | {error, toroco_lib_params:error()}.
init(Params, Specs, Vehicle) ->
    case toroco_lib_params:check(Params, Specs) of
        {ok, P} -> {ok, dark, P#{left => 0, right => 0, last => none, vehicle => Vehicle}};
        {error, _} = Error -> Error
    end.

-spec handle_input(left | right, term(), dark | lit, map()) -> toroco_behavior:result().
handle_input(Side, Reading, _State, P) when is_number(Reading) ->
    #{left := L, right := R, threshold := T, last := Last, vehicle := V} = P1 = P#{Side := Reading},
    case max(L, R) >= T of
        true ->
            {Wl, Wr} = V:law(L, R, P1),
            {Actions, Last1} = toroco_lib_drive:set(toroco_lib_drive:wheels(Wl, Wr), Last),
            {next_state, lit, P1#{last := Last1}, Actions};
        false ->
            {Actions, Last1} = toroco_lib_drive:release(Last),
            {next_state, dark, P1#{last := Last1}, Actions}
    end;
handle_input(_Side, _Other, _State, _P) ->
    keep_state_and_data.
