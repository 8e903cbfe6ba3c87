%% A test behavior that latches `out' at start and crashes after `after_ms'
%% (a layer failing in a loop, to be taken out).
-module(tl_crasher).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4, handle_event/4]).

interface() -> #{inputs => [], outputs => [out]}.

init(P = #{after_ms := Ms}) ->
    {ok, running, P, [{set, #{out => up}}, {state_timeout, Ms, crash}]}.

handle_input(_, _, _, _) -> keep_state_and_data.

handle_event(state_timeout, crash, _S, _D) -> exit(crash_loop).
