%% A test behavior: latches on `out' whatever comes on `in'.
-module(toroco_live_relay).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(_Params) -> {ok, waiting, #{}}.

handle_input(in, V, _S, D) -> {next_state, relaying, D, [{set, #{out => V}}]}.
