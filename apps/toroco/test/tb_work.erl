%% A test behavior that does real work for each input: on an integer N it
%% hashes a kilobyte 200 times (some hundred microseconds of CPU), then
%% sends N + 1 on `out'.
-module(tb_work).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, working, P}.

handle_input(in, N, _S, _D) when is_integer(N) ->
    _ = lists:foldl(fun(_, Acc) -> crypto:hash(sha256, [Acc, binary:copy(<<1>>, 1024)]) end,
                    <<>>, lists:seq(1, 200)),
    {keep_state_and_data, [{send, #{out => N + 1}}]};
handle_input(in, _V, _S, _D) ->
    keep_state_and_data.
