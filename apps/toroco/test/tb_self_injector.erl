%% A test behavior that, on any input, injects into its own output from its
%% callback and sends what `toroco:inject/2' answered.
-module(tb_self_injector).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, waiting, P}.

handle_input(in, _V, _S, _D) ->
    Answer = toroco:inject({b, out}, self),
    {keep_state_and_data, [{send, #{out => Answer}}]}.
