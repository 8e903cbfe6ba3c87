%% @doc A level held: the last value of input `in', latched on output
%% `out' (`set'). Between a sensor that sends only changes (the IR
%% sensors' near and far) and the behavior that reacts to them, it makes
%% the level something a restarted behavior gets back at once: its router
%% hands the new incarnation the latch (SPEC §4), where a sent change is
%% gone. The robustness lab found the need (doc/lab.md, "What the lab
%% found").
-module(torobot_latch).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [in], outputs := [out]}.
interface() ->
    #{inputs => [in], outputs => [out]}.

-spec init(map()) -> {ok, holding, map()}.
init(Params) ->
    {ok, holding, Params}.

-spec handle_input(in, term(), holding, map()) -> toroco_behavior:result().
handle_input(in, V, _State, _P) ->
    {keep_state_and_data, [{set, #{out => V}}]}.
