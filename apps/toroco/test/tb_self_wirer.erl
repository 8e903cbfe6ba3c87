%% A test behavior that re-wires the network from inside its own callback:
%% on `wire' it wires actuator `a' to its own output (a latched source), on
%% `bogus' it emits on an output it never declared.
-module(tb_self_wirer).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, waiting, P}.

handle_input(in, wire, _S, _D) ->
    ok = toroco:set_inputs(a, #{in => [{self_wirer, out}]}),
    keep_state_and_data;
handle_input(in, bogus, _S, _D) ->
    {keep_state_and_data, [{send, #{nope => 1}}]};
handle_input(in, _, _S, _D) ->
    keep_state_and_data.
