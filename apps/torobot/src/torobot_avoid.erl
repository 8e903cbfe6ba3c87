%% @doc Turn away from a wall one IR sensor sees: the Torobot's
%% `avoid_left' and `avoid_right' (layer 1).
%%
%% The `ir' input is wired to one output of the IR sensor device, which
%% sends `1' when the reading rises past its near threshold and `0' when it
%% falls past its far threshold (the hysteresis is the PRU's, not ours). On
%% near the behavior sets its `turn' on `motors', latched, so it suppresses
%% `forward' for as long as the wall is near; on far it unsets and lower
%% layers come back. The two avoids inhibit each other in the wiring: in a
%% corner, or on a semi-oblique approach where both sensors read near, the
%% one that turned first keeps turning and the other waits (thesis §5.2.2).
%%
%% Params: `turn', the `{Left, Right}' wheel velocities of the turn
%% (default `{50, -50}', a spin to the right: right for a wall on the left).
-module(torobot_avoid).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [ir], outputs := [motors]}.
interface() ->
    #{inputs => [ir], outputs => [motors]}.

-spec init(map()) -> {ok, clear, map()}.
init(Params) ->
    {ok, clear, maps:merge(#{turn => {50, -50}}, Params)}.

-spec handle_input(ir, term(), clear | turning, map()) -> toroco_behavior:result().
handle_input(ir, Level, clear, #{turn := Turn} = P) when Level =:= 1; Level =:= near ->
    {next_state, turning, P, [{set, #{motors => Turn}}]};
handle_input(ir, Level, turning, P) when Level =:= 0; Level =:= far ->
    {next_state, clear, P, [{unset, [motors]}]};
handle_input(ir, _Level, _State, _P) ->
    keep_state_and_data.
