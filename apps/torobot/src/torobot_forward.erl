%% @doc The Torobot's lowest behavior: drive straight ahead.
%%
%% Layer 0 of the Torobot's wiring (`config/torobot.wiring'). It sets a
%% latched `{Speed, Speed}' on `motors' at start and never changes it, so
%% the motors fall back to going forward whenever every higher behavior has
%% unset: the router re-delivers this latch when the last suppression lifts.
%%
%% Params: `speed' (servo units, -100..100; default 80).
-module(torobot_forward).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [], outputs := [motors]}.
interface() ->
    #{inputs => [], outputs => [motors]}.

-spec init(map()) -> {ok, cruising, map(), toroco_behavior:actions()}.
init(Params) ->
    Speed = maps:get(speed, Params, 80),
    {ok, cruising, Params, [{set, #{motors => {Speed, Speed}}}]}.

-spec handle_input(atom(), term(), cruising, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _Data) ->
    keep_state_and_data.
