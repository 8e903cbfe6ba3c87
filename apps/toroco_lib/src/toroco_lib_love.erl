%% @doc Braitenberg's vehicle 3a, love: each sensor slows the wheel on its
%% own side the more it reads, so the robot turns towards the source and
%% slows as it nears it, coming to rest facing it where the readings reach
%% `rest_level'.
%%
%% Inputs: `left', `right' (readings, e.g. the light sensors' 0..1023).
%% Outputs: `motors', latched `{speed x (1 - left / rest_level), speed x (1 -
%% right / rest_level)}' (each at least 0) while a reading is at or above
%% `threshold', unset below (see `toroco_lib_braitenberg').
%%
%% Parameters: `speed' [60], `rest_level' [500], `threshold' [40].
%%
%% Usual layer: above `wander', below `avoid'.
-module(toroco_lib_love).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, law/3]).

-spec params() -> [toroco_lib_params:spec()].
params() -> [{speed, pos_speed, 60}, {rest_level, pos_number, 500},
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
law(L, R, #{speed := S, rest_level := Rest}) ->
    {S * max(0.0, 1 - L / Rest), S * max(0.0, 1 - R / Rest)}.
