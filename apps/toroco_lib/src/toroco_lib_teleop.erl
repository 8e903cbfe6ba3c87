%% @doc Teleop: a person's commands from a link override everything while
%% they come.
%%
%% Inputs: `command', from a `toroco_tcp_link' or `toroco_udp_link' output
%% (or any source): `{Left, Right}', `[Left, Right]' (JSON arrays), a map
%% with `left' and `right' (atom or binary keys), or `stop' / `<<"stop">>'
%% / `null' to hand the robot back at once. Outputs: `motors': each command
%% latched (clamped to `max_speed'); unset when `timeout_ms' pass with no
%% command, or on stop. Other values are ignored.
%%
%% Parameters: `timeout_ms' [500], `max_speed' [100].
%%
%% Usual layer: the top; wired first at the motors, so it overrides while
%% active and the robot's own layers come back when the person stops.
-module(toroco_lib_teleop).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, handle_event/4]).

-spec params() -> [toroco_lib_params:spec()].
params() -> [{timeout_ms, ms, 500}, {max_speed, pos_speed, 100}].

-spec interface() -> #{inputs := [command], outputs := [motors]}.
interface() -> #{inputs => [command], outputs => [motors]}.

-spec init(map()) -> {ok, idle, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, P} -> {ok, idle, P};
        {error, _} = Error -> Error
    end.

-spec handle_input(command, term(), idle | active, map()) -> toroco_behavior:result().
handle_input(command, Value, State, #{timeout_ms := T, max_speed := Max} = P) ->
    case wheels(Value) of
        {L, R} ->
            Clamp = fun(V) -> max(-Max, min(Max, V)) end,
            {next_state, active, P,
             [{set, #{motors => toroco_lib_drive:wheels(Clamp(L), Clamp(R))}},
              {state_timeout, T, release}]};
        stop when State =:= active ->
            {next_state, idle, P, [{unset, [motors]}]};
        _ ->
            keep_state_and_data
    end.

-spec handle_event(gen_statem:event_type(), term(), idle | active, map()) ->
          toroco_behavior:result().
handle_event(state_timeout, release, active, P) ->
    {next_state, idle, P, [{unset, [motors]}]};
handle_event(_Type, _Content, _State, _P) ->
    keep_state_and_data.

wheels({L, R}) when is_number(L), is_number(R) -> {L, R};
wheels([L, R]) when is_number(L), is_number(R) -> {L, R};
wheels(#{left := L, right := R}) when is_number(L), is_number(R) -> {L, R};
wheels(#{<<"left">> := L, <<"right">> := R}) when is_number(L), is_number(R) -> {L, R};
wheels(Stop) when Stop =:= stop; Stop =:= <<"stop">>; Stop =:= null -> stop;
wheels(_) -> ignore.
