%% @doc Avoid: spin away from what the range sensors see near, until
%% nothing is near. The classic level-1 behavior of Brooks' robots.
%%
%% Inputs: `left', `right', `front', each a range reading (metres, or
%% `near'/`far' levels, see `toroco_lib_range'); any may stay unwired.
%% Outputs: `motors': a latched spin while something is near, unset when
%% nothing is.
%%
%% The spin's side is chosen when the first sensor turns near (away from a
%% near `left' or `right'; `prefer' for `front' alone or both sides) and
%% kept until every sensor is far again, so the robot does not dither in a
%% corner.
%%
%% Parameters: `near' [0.25] metres, `far' [0.32] (the hysteresis; not
%% below `near'), `spin' [50] (wheel speed of the spin), `prefer' [left]
%% (`left' | `right').
%%
%% Usual layer: 1, above `wander' or `cruise'; below a seeker that must
%% touch its target.
-module(toroco_lib_avoid).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4]).

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{near, metres, 0.25}, {far, metres, 0.32}, {spin, pos_speed, 50},
     {prefer, {one_of, [left, right]}, left}].

-spec interface() -> #{inputs := [left | right | front], outputs := [motors]}.
interface() -> #{inputs => [left, right, front], outputs => [motors]}.

-spec init(map()) -> {ok, clear, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, #{near := Near, far := Far} = P} when Far < Near ->
            toroco_lib_params:refuse(far, P);
        {ok, P} ->
            {ok, clear, P#{levels => #{left => far, right => far, front => far}}};
        {error, _} = Error ->
            Error
    end.

-spec handle_input(left | right | front, term(), clear | {spinning, left | right}, map()) ->
          toroco_behavior:result().
handle_input(Side, Reading, State, #{levels := Levels, near := Near, far := Far} = P) ->
    Levels1 = Levels#{Side := toroco_lib_range:level(Reading, maps:get(Side, Levels), Near, Far)},
    P1 = P#{levels := Levels1},
    case {State, [S || S <- [left, right, front], maps:get(S, Levels1) =:= near]} of
        {clear, []} ->
            {keep_state, P1};
        {clear, NearSides} ->
            Dir = away(NearSides, maps:get(prefer, P)),
            {next_state, {spinning, Dir}, P1,
             [{set, #{motors => toroco_lib_drive:spin(Dir, maps:get(spin, P))}}]};
        {{spinning, _}, []} ->
            {next_state, clear, P1, [{unset, [motors]}]};
        {{spinning, _}, _} ->
            {keep_state, P1}
    end.

away([left], _Prefer) -> right;
away([right], _Prefer) -> left;
away(_Sides, Prefer) -> Prefer.
