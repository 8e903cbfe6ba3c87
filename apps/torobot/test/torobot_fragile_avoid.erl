%% A planted weakness for the robustness lab's suite: torobot_avoid, but
%% a new incarnation believes it is already turning, so one restarted
%% during a turn ignores the near reading its router hands it again and
%% never latches its turn: forward drives on into the wall.
-module(torobot_fragile_avoid).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

interface() ->
    torobot_avoid:interface().

init(Params) ->
    {ok, _Clear, P} = torobot_avoid:init(Params),
    {ok, turning, P}.

handle_input(Input, Level, State, P) ->
    torobot_avoid:handle_input(Input, Level, State, P).
