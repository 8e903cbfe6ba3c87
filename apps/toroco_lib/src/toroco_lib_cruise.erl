%% @doc Cruise: drive straight ahead, for ever. The bottom of most robots:
%% whatever the layers above let go of, the robot goes on forward.
%%
%% Inputs: none. Outputs: `motors', `{Speed, Speed}' latched at start, so
%% the motors' router re-delivers it whenever every higher source lets go.
%%
%% Parameters: `speed' [60], -100..100.
%%
%% Usual layer: 0.
-module(toroco_lib_cruise).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4]).

-spec params() -> [toroco_lib_params:spec()].
params() -> [{speed, speed, 60}].

-spec interface() -> #{inputs := [], outputs := [motors]}.
interface() -> #{inputs => [], outputs => [motors]}.

-spec init(map()) -> {ok, cruising, map(), toroco_behavior:actions()}
                         | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, #{speed := S} = P} ->
            {ok, cruising, P, [{set, #{motors => toroco_lib_drive:wheels(S, S)}}]};
        {error, _} = Error ->
            Error
    end.

-spec handle_input(atom(), term(), cruising, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _P) -> keep_state_and_data.
