%% A test behavior that latches `value' on `out' at start and crashes after
%% `after_ms' (a top layer failing in a loop).
-module(tb_crasher).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4, handle_event/4]).

interface() -> #{inputs => [], outputs => [out]}.

init(P = #{value := V, after_ms := Ms}) ->
    {ok, running, P, [{set, #{out => V}}, {state_timeout, Ms, crash}]}.

handle_input(_, _, _, _) -> keep_state_and_data.

handle_event(state_timeout, crash, _S, _D) -> exit(crash_loop).
