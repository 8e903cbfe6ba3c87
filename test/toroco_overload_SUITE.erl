%% Overload: a sensor emitting ten times faster than its receiver can handle
%% (issue: reliability). With `buffer => all' (the default) nothing is lost and
%% the receiver's mailbox grows with the backlog; with `buffer => latest' the
%% receiver gets the newest value each time it is ready, its mailbox stays at
%% one message per input, and the values in between are skipped.
-module(toroco_overload_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

suite() -> [{timetrap, {minutes, 2}}].

all() -> [all_keeps_everything_and_grows, latest_stays_bounded].

init_per_testcase(_, Config) ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    Config.

end_per_testcase(_, _Config) ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
    ok.

-define(EVENTS, 2000).
-define(WORK_MS, 2).          % the receiver's cost per input

%% Emits ?EVENTS values at ten times the receiver's rate and samples the
%% receiver's mailbox; returns {MaxMailbox, Delivered}.
run(Buffer) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [v]}),
    ok = toroco:add_behavior(slow, tb_relay, #{}),
    ok = toroco:add_device(a, toroco_fake_actuator, #{inputs => [in]}),
    ok = toroco:set_inputs(slow, #{in => #{sources => [{s, v}], buffer => Buffer}}),
    ok = toroco:set_inputs(a, #{in => [{slow, out}]}),
    Slow = whereis(toroco_names:process(slow)),
    Period = ?WORK_MS * 1000 div 10,                    % µs between events
    T0 = erlang:monotonic_time(microsecond),
    Max = lists:foldl(fun(I, M) ->
                              ok = toroco:inject({s, v}, {sleep, ?WORK_MS, I}),
                              pace(T0 + I * Period),
                              {_, Q} = erlang:process_info(Slow, message_queue_len),
                              max(M, Q)
                      end, 0, lists:seq(1, ?EVENTS)),
    ok = toroco_fake_actuator:await(a, fun(H) -> H =/= [] andalso element(2, lists:last(H)) =:= ?EVENTS end,
                                    ?EVENTS * ?WORK_MS * 2 + 5000),
    Delivered = length(toroco_fake_actuator:history(a)),
    ct:pal("buffer ~p: ~p events at 10x the receiver's rate: max mailbox ~p, delivered ~p",
           [Buffer, ?EVENTS, Max, Delivered]),
    {Max, Delivered}.

pace(Until) ->
    case erlang:monotonic_time(microsecond) < Until of
        true -> pace(Until);
        false -> ok
    end.

all_keeps_everything_and_grows() ->
    [{doc, "buffer => all: every event is delivered; the backlog sits in the receiver's mailbox."}].
all_keeps_everything_and_grows(_) ->
    {Max, Delivered} = run(all),
    ?EVENTS = Delivered,
    true = Max > ?EVENTS div 2,
    {comment, io_lib:format("max mailbox ~p, delivered ~p/~p", [Max, Delivered, ?EVENTS])}.

latest_stays_bounded() ->
    [{doc, "buffer => latest: the mailbox stays at one input, the newest value always arrives."}].
latest_stays_bounded(_) ->
    {Max, Delivered} = run(latest),
    true = Max =< 1,
    true = Delivered < ?EVENTS div 4,
    {comment, io_lib:format("max mailbox ~p, delivered ~p/~p", [Max, Delivered, ?EVENTS])}.
