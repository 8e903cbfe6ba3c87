%% @doc Braitenberg's vehicle 2a, fear: each sensor drives the wheel on its
%% own side faster the more it reads, so the robot turns away from the
%% source and flees it, faster the nearer it is.
%%
%% Inputs: `left', `right' (readings, e.g. the light sensors' 0..1023).
%% Outputs: `motors', latched `{speed + gain x left / full_scale, speed +
%% gain x right / full_scale}' while a reading is at or above `threshold',
%% unset below (see `toroco_lib_braitenberg').
%%
%% Parameters: `speed' [30], `gain' [70], `full_scale' [1023],
%% `threshold' [40].
%%
%% Usual layer: above `wander', below `avoid'.
-module(toroco_lib_fear).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, law/3]).

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{speed, speed, 30}, {gain, speed, 70}, {full_scale, pos_number, 1023},
     {threshold, non_neg_number, 40}].

-spec interface() -> #{inputs := [left | right], outputs := [motors]}.
interface() -> toroco_lib_braitenberg:interface().

-spec init(map()) -> {ok, dark, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    toroco_lib_braitenberg:init(Params, params(), ?MODULE).

-spec handle_input(left | right, term(), dark | lit, map()) -> toroco_behavior:result().
handle_input(Side, Reading, State, P) ->
    toroco_lib_braitenberg:handle_input(Side, Reading, State, P).

%% @doc The wheel law (see the module doc).
-spec law(number(), number(), map()) -> {number(), number()}.
law(L, R, #{speed := S, gain := G, full_scale := F}) ->
    {S + G * L / F, S + G * R / F}.
