%% @doc An actuator that records every delivery, for tests and the shell.
%%
%% `toroco:add_device(A, toroco_fake_actuator, #{inputs => [In]})'; then
%% {@link history/1} gives `[{In, Value, MonotonicMs}]' oldest first, {@link
%% clear/1} forgets it, and {@link await/3} blocks until a predicate on the
%% history holds (checked at each delivery) or the timeout passes. Option
%% `max_history' (default 100000) bounds the record; older entries are dropped.
-module(toroco_fake_actuator).
-behaviour(toroco_device).

-export([history/1, clear/1, await/3]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2]).

-type history() :: [{atom(), term(), integer()}].
-export_type([history/0]).

%%====================================================================
%% API
%%====================================================================

-spec history(atom()) -> history().
history(A) ->
    toroco_device:call(A, history, 5000).

-spec clear(atom()) -> ok.
clear(A) ->
    toroco_device:call(A, clear, 5000).

%% @doc Waits until `Pred(History)' is true; `{error, timeout}' otherwise.
-spec await(atom(), fun((history()) -> boolean()), timeout()) -> ok | {error, timeout}.
await(A, Pred, Timeout) ->
    try toroco_device:call(A, {await, Pred, deadline(Timeout)}, Timeout)
    catch exit:{timeout, _} -> {error, timeout}
    end.

deadline(infinity) -> infinity;
deadline(T) -> erlang:monotonic_time(millisecond) + T.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [atom()], outputs := []}.
interface(#{inputs := Ins}) when is_list(Ins) -> #{inputs => Ins, outputs => []};
interface(Opts) -> error({bad_option, {inputs, maps:get(inputs, Opts, missing)}}).

-spec init(atom(), map()) -> {ok, recording, map()}.
init(_Name, Opts) ->
    {ok, recording, #{rev => [], n => 0, max => maps:get(max_history, Opts, 100000),
                      waiters => []}}.

-spec handle_input(atom(), term(), recording, map()) -> toroco_behavior:result().
handle_input(In, V, _State, D = #{rev := Rev, n := N, max := Max, waiters := Ws}) ->
    Rev1 = [{In, V, toroco_clock:now_ms()} | Rev],
    {Rev2, N2} = case N + 1 > Max of
                     true -> {lists:sublist(Rev1, Max), Max};
                     false -> {Rev1, N + 1}
                 end,
    case Ws of
        [] -> {keep_state, D#{rev := Rev2, n := N2}};
        _ ->
            {Replies, Ws1} = check(Ws, lists:reverse(Rev2)),
            {keep_state, D#{rev := Rev2, n := N2, waiters := Ws1}, Replies}
    end.

-spec handle_event(gen_statem:event_type(), term(), recording, map()) -> toroco_behavior:result().
handle_event({call, From}, history, _S, #{rev := Rev}) ->
    {keep_state_and_data, [{reply, From, lists:reverse(Rev)}]};
handle_event({call, From}, clear, _S, D) ->
    {keep_state, D#{rev := [], n := 0}, [{reply, From, ok}]};
handle_event({call, From}, {await, Pred, Deadline}, _S, D = #{rev := Rev, waiters := Ws}) ->
    case catch Pred(lists:reverse(Rev)) of
        true -> {keep_state_and_data, [{reply, From, ok}]};
        _ -> {keep_state, D#{waiters := [{From, Pred, Deadline} | Ws]}}
    end.

-spec info(recording, map()) -> map().
info(_S, #{n := N, waiters := Ws}) ->
    #{deliveries => N, waiters => length(Ws)}.

%% Waiters whose predicate now holds are answered; expired ones are dropped
%% (their caller has already given up).
check(Ws, History) ->
    Now = erlang:monotonic_time(millisecond),
    lists:foldl(fun({From, Pred, Deadline} = W, {Rs, Keep}) ->
                        case catch Pred(History) of
                            true -> {[{reply, From, ok} | Rs], Keep};
                            _ when Deadline =/= infinity, Deadline < Now -> {Rs, Keep};
                            _ -> {Rs, [W | Keep]}
                        end
                end, {[], []}, Ws).
