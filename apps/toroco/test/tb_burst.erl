%% A test behavior that emits a burst: on an integer N it sends 1 to N on
%% `out', in one callback.
-module(tb_burst).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, bursting, P}.

handle_input(in, N, _S, _D) when is_integer(N) ->
    {keep_state_and_data, [{send, #{out => I}} || I <- lists:seq(1, N)]};
handle_input(in, _V, _S, _D) ->
    keep_state_and_data.
