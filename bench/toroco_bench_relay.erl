%% Benchmark relay: passes each input on as a momentary event.
-module(toroco_bench_relay).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, relaying, P}.

handle_input(in, V, _S, _D) -> {keep_state_and_data, [{send, #{out => V}}]}.
