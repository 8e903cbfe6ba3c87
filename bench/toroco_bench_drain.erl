%% Benchmark helper (toroco_bench_profile): a gen_statem that takes N
%% messages and tells its parent, to time gen_statem's own loop.
-module(toroco_bench_drain).
-behaviour(gen_statem).
-export([callback_mode/0, init/1, handle_event/4]).

callback_mode() -> handle_event_function.

init({Parent, N}) -> {ok, taking, {Parent, N}}.

handle_event(info, _, _, {Parent, 1}) ->
    Parent ! {drained, self()},
    {keep_state, {Parent, 0}};
handle_event(info, _, _, {Parent, N}) ->
    {keep_state, {Parent, N - 1}}.
