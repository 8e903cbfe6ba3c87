%% Overload: a sensor emitting far faster than its receiver can handle
%% (issue: reliability). With `buffer => all' (the default) nothing is lost and
%% the receiver's mailbox grows with the backlog; with `buffer => latest' the
%% receiver gets the newest value each time it is ready, its mailbox stays at
%% one message per input, and the values in between are skipped.
%%
%% The receiver is slow because it waits on a timer for each input (it uses no
%% CPU meanwhile), and the sender emits in bursts between 1 ms sleeps, so the
%% bounds hold however the two cores are shared: the receiver can never take
%% more than one input per ?WORK_MS, the sender emits ?BATCH per sleep.
-module(toroco_overload_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

suite() -> [{timetrap, {minutes, 2}}].

all() -> [all_keeps_everything_and_grows, latest_stays_bounded].

init_per_testcase(_, Config) ->
    ok = toroco_test_lib:start(),
    Config.

end_per_testcase(_, _Config) ->
    toroco_test_lib:stop().

-define(EVENTS, 2000).
-define(WORK_MS, 2).          % the receiver's wait per input
-define(BATCH, 50).           % events emitted a burst, a burst a millisecond at most

%% Emits ?EVENTS values (1..?EVENTS) in bursts much faster than the receiver
%% takes them and samples the receiver's mailbox after each one; returns
%% {MaxMailbox, Delivered values in order}.
run(Buffer) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [v]}),
    ok = toroco:add_behavior(slow, tb_relay, #{}),
    ok = toroco:add_device(a, toroco_fake_actuator, #{inputs => [in]}),
    ok = toroco:set_inputs(slow, #{in => #{sources => [{s, v}], buffer => Buffer}}),
    ok = toroco:set_inputs(a, #{in => [{slow, out}]}),
    Slow = whereis(toroco_names:process(slow)),
    Peak = atomics:new(1, []),
    Burst = fun(B) ->
                    [begin
                         ok = toroco:inject({s, v}, {sleep, ?WORK_MS, I}),
                         {_, Q} = erlang:process_info(Slow, message_queue_len),
                         atomics:put(Peak, 1, max(atomics:get(Peak, 1), Q))
                     end || I <- lists:seq((B - 1) * ?BATCH + 1, B * ?BATCH)]
            end,
    _ = toroco_test_lib:pace(Burst, ?EVENTS div ?BATCH, 1),
    Max = atomics:get(Peak, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> H =/= [] andalso element(2, lists:last(H)) =:= ?EVENTS end,
                                    ?EVENTS * ?WORK_MS * 4 + 5000),
    Delivered = [V || {_, V, _} <- toroco_fake_actuator:history(a)],
    ct:pal("buffer ~p: ~p events in bursts of ~p, receiver waiting ~p ms each: "
           "max mailbox ~p, delivered ~p",
           [Buffer, ?EVENTS, ?BATCH, ?WORK_MS, Max, length(Delivered)]),
    {Max, Delivered}.

all_keeps_everything_and_grows() ->
    [{doc, "buffer => all: every event is delivered; the backlog sits in the receiver's mailbox."}].
all_keeps_everything_and_grows(_) ->
    {Max, Delivered} = run(all),
    %% every value, in emission order
    ?assertEqual(lists:seq(1, ?EVENTS), Delivered),
    ?assert(Max > ?EVENTS div 2),
    {comment, io_lib:format("max mailbox ~p, delivered ~p/~p", [Max, length(Delivered), ?EVENTS])}.

latest_stays_bounded() ->
    [{doc, "buffer => latest: the mailbox stays at one input, the newest value always arrives."}].
latest_stays_bounded(_) ->
    {Max, Delivered} = run(latest),
    ?assert(Max =< 1),
    ?assert(length(Delivered) < ?EVENTS div 4),
    %% skipped values are older ones: what arrives only gets newer, and ends
    %% with the newest
    ?assertEqual(lists:usort(Delivered), Delivered),
    ?assertEqual(?EVENTS, lists:last(Delivered)),
    {comment, io_lib:format("max mailbox ~p, delivered ~p/~p", [Max, length(Delivered), ?EVENTS])}.
