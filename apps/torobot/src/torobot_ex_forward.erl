%% @doc The lowest behavior of the line follower (thesis §4.1.6): drive
%% straight on. It `set's its `velocity' output once, from `init/1', to the
%% wheel velocities of param `velocity' (default `{50, 50}', left and right
%% in −100..100); the latch is what the motors fall back to whenever no turn
%% holds.
-module(torobot_ex_forward).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [], outputs => [velocity]}.

-spec init(map()) -> {ok, driving, map(), toroco_behavior:actions()}.
init(Params) ->
    {ok, driving, Params, [{set, #{velocity => maps:get(velocity, Params, {50, 50})}}]}.

-spec handle_input(atom(), term(), driving, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _Data) ->
    keep_state_and_data.
