%% The event path: the observer tap (SPEC §10), and the runtime's own
%% resilience around it: the wiring server's crashes, self-calls, inject's
%% errors, reset and the engine's defaults.
-module(toroco_event_path_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [sensor/2, actuator/2, await_values/2, wait_until/2]).

all() ->
    [{group, tap}, {group, resilience}].

groups() ->
    [{tap, [], [event_shapes, names_filter, kinds_filter, lifecycle_events,
                slow_subscriber_loses_and_counts, dropped_reported_without_later_events,
                batch_delivery_same_events, slow_batch_subscriber_loses_and_counts,
                per_source_order, unsubscribe_stops_events, dead_subscriber_is_unsubscribed,
                bad_options_refused, no_subscriber_no_tap_state, burst_goes_in_batches,
                idle_subscription_costs_nothing, network_hears_through_pg,
                flush_takes_in_every_emission, unsubscribe_takes_in_every_emission,
                flush_takes_in_the_whole_path, flush_of_an_unknown_subscription,
                feeder_is_inspectable, feeder_not_starved_by_busy_processes]},
     {resilience, [], [wiring_server_crashes_100_times_under_load, inject_into_own_output_is_refused,
                       inject_unknown_and_stopped_names, restarts_counted_from_lifecycle,
                       reset_cancels_named_timeouts, unknown_events_fall_to_the_engine,
                       quiet_path_hibernates_again_after_events,
                       failed_first_start_in_a_new_layer,
                       rewired_router_takes_its_configuration_from_the_call,
                       wiring_table_written_by_the_wiring_server_only]}].

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    Config.

end_per_testcase(_Case, _Config) ->
    toroco_test_lib:stop().

%%====================================================================
%% The tap
%%====================================================================

%% s.v -> b.in ; b.out -> a.in
chain() ->
    sensor(s, [v]),
    ok = toroco:add_behavior(b, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(b, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{in => [{b, out}]}).

%% Every event that comes until none has come for `Gap' ms.
events(Ref, Gap) ->
    receive {toroco_event, Ref, E} -> [E | events(Ref, Gap)]
    after Gap -> []
    end.

await_event(Ref, Pred, Timeout) ->
    Deadline = erlang:monotonic_time(millisecond) + Timeout,
    await_event_until(Ref, Pred, Deadline).

await_event_until(Ref, Pred, Deadline) ->
    Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
    receive
        {toroco_event, Ref, E} ->
            case Pred(E) of
                true -> E;
                false -> await_event_until(Ref, Pred, Deadline)
            end
    after Left -> ct:fail({no_event_matching, Pred})
    end.

event_shapes() ->
    [{doc, "Emit, deliver and router events have the shapes of SPEC §10, with nanosecond system times."}].
event_shapes(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{}),
    T0 = erlang:system_time(nanosecond),
    ok = toroco:inject({s, v}, {set, 7}),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 2000),
    %% Events of different sources may come in either order (SPEC §10):
    %% each is looked for among all that came.
    Set = flushed(Ref),
    [{emit, T1, {s, v}, send, {set, 7}}] = [E || E = {emit, _, {s, v}, _, _} <- Set],
    true = T1 >= T0 andalso T1 =< erlang:system_time(nanosecond),
    [{emit, _, {b, out}, set, 7}] = [E || E = {emit, _, {b, out}, _, _} <- Set],
    [{deliver, _, {a, in}, 7}] = [E || E = {deliver, _, {a, in}, _} <- Set],
    {router, _, {a, in}, #{winner := {b, out}, holds := [{{b, out}, infinity}],
                           latches := [{{b, out}, 7}]}} = lists:last([E || E = {router, _, {a, in}, _} <- Set]),
    ok = toroco:inject({s, v}, unset),
    ok = wait_until(fun() -> winner(a) =:= none end, 2000),
    Unset = flushed(Ref),
    [{emit, _, {b, out}, unset, none}] = [E || E = {emit, _, {b, out}, _, _} <- Unset],
    {router, _, {a, in}, #{winner := none, holds := [], latches := []}} =
        lists:last([E || E = {router, _, {a, in}, _} <- Unset]).

winner(Name) ->
    #{inputs := #{in := #{winner := W}}} = toroco:inspect(Name),
    W.

%% Every event emitted so far, in the order they came.
flushed(Ref) ->
    ok = toroco:flush_events(Ref),
    taken(Ref).

%% The events in the mailbox now.
taken(Ref) ->
    receive {toroco_event, Ref, E} -> [E | taken(Ref)]
    after 0 -> []
    end.

flush_takes_in_every_emission() ->
    [{doc, "flush_events/1 returns once every event emitted before it is in the subscriber's "
      "mailbox: 300 emissions, the last just before the call, are all there, in order."}].
flush_takes_in_every_emission(_Config) ->
    sensor(s, [v]),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [s]}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 300)],
    Values = [V || {emit, _, {s, v}, send, V} <- flushed(Ref)],
    Values = lists:seq(1, 300).

unsubscribe_takes_in_every_emission() ->
    [{doc, "unsubscribe_events/1 returns once every event emitted before it is in the "
      "subscriber's mailbox, and none comes after."}].
unsubscribe_takes_in_every_emission(_Config) ->
    sensor(s, [v]),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [s], delivery => batch}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 300)],
    ok = toroco:unsubscribe_events(Ref),
    Batches = fun Take() -> receive {toroco_events, Ref, Es} -> Es ++ Take() after 0 -> [] end end,
    Values = [V || {emit, _, {s, v}, send, V} <- Batches()],
    Values = lists:seq(1, 300),
    ok = toroco:inject({s, v}, late),
    toroco_test_lib:nothing_arrives(fun({toroco_events, R, _}) -> R =:= Ref; (_) -> false end,
                                    100, {events_after_unsubscribe, Ref}).

flush_takes_in_the_whole_path() ->
    [{doc, "flush_events/1 takes in the events of every process of the path: after 200 values "
      "reached the actuator, each one's emissions (sensor, relay) and deliveries (relay, "
      "actuator) are there."}].
flush_takes_in_the_whole_path(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit, deliver]}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 200)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 200 end, 5000),
    Events = flushed(Ref),
    [{{b, in}, 200}, {{a, in}, 200}, {{s, v}, 200}, {{b, out}, 200}] =
        [{Src, length([x || E <- Events, element(1, E) =:= Kind, element(3, E) =:= Src])}
         || {Kind, Src} <- [{deliver, {b, in}}, {deliver, {a, in}}, {emit, {s, v}}, {emit, {b, out}}]].

flush_of_an_unknown_subscription() ->
    [{doc, "flush_events/1 of a reference that is no subscription is an error naming it."}].
flush_of_an_unknown_subscription(_Config) ->
    Ref = make_ref(),
    {error, {unknown_subscription, Ref}} = toroco:flush_events(Ref).

feeder_not_starved_by_busy_processes() ->
    [{doc, "While twice as many normal-priority processes as schedulers spin, every event "
      "still reaches the subscriber without a flush: the low-priority feeder is interleaved "
      "with them, not starved."}].
feeder_not_starved_by_busy_processes(_Config) ->
    sensor(s, [v]),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [s]}),
    Spinners = [spawn(fun Spin() -> Spin() end)
                || _ <- lists:seq(1, 2 * erlang:system_info(schedulers_online))],
    try
        [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 50)],
        Values = [V || {emit, _, {s, v}, send, V} <- take_events(Ref, 50, [])],
        Values = lists:seq(1, 50)
    after
        [exit(P, kill) || P <- Spinners]
    end.

feeder_is_inspectable() ->
    [{doc, "A subscription's feeder is an OTP process: sys:get_state/1 shows its state and data."}].
feeder_is_inspectable(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{}),
    {State, Data} = sys:get_state(toroco_tap:feeder(Ref)),
    true = lists:member(State, [waiting, holding]),
    feed = element(1, Data),
    ok = toroco:unsubscribe_events(Ref).

names_filter() ->
    [{doc, "names keeps the events emitted by, delivered to, routed for or happening to those names."}].
names_filter(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{names => [a]}),
    ok = toroco:inject({s, v}, hello),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 2000),
    All = flushed(Ref),
    [{deliver, _, {a, in}, hello}] = [E || E <- All, element(1, E) =:= deliver],
    [] = [E || E <- All, element(1, E) =:= emit],
    [] = [E || E <- All, element(1, E) =/= emit, element(1, element(3, E)) =/= a].

kinds_filter() ->
    [{doc, "kinds keeps only the events of those kinds."}].
kinds_filter(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [deliver]}),
    ok = toroco:inject({s, v}, x),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 2000),
    Events = flushed(Ref),
    [{deliver, _, {a, in}, x}, {deliver, _, {b, in}, x}] =
        lists:sort(fun(A, B) -> element(3, A) =< element(3, B) end, Events).

lifecycle_events() ->
    [{doc, "Starts, suspends, resumes, resets, crashes and stops are lifecycle events."}].
lifecycle_events(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [lifecycle]}),
    ok = toroco:suspend_behavior(b),
    {lifecycle, _, b, suspended} = await_event(Ref, fun(_) -> true end, 2000),
    ok = toroco:resume_behavior(b),
    {lifecycle, _, b, resumed} = await_event(Ref, fun(_) -> true end, 2000),
    ok = toroco:add_behavior(c, tb_relay, #{}),
    {lifecycle, _, c, started} = await_event(Ref, fun(_) -> true end, 2000),
    ok = toroco:inject({s, v}, crash),
    {lifecycle, _, b, stopped} = await_event(Ref, fun(_) -> true end, 2000),
    {lifecycle, _, b, restarted} = await_event(Ref, fun(_) -> true end, 2000),
    ok = toroco:set_reset(c, [{s, v}]),
    ok = toroco:inject({s, v}, go),
    {lifecycle, _, c, reset} = await_event(Ref, fun(E) -> element(3, E) =:= c end, 2000),
    ok = toroco:remove_behavior(c),
    {lifecycle, _, c, stopped} = await_event(Ref, fun(E) -> element(3, E) =:= c end, 2000).

slow_subscriber_loses_and_counts() ->
    [{doc, "A subscriber that does not read keeps at most about `buffer' events; every event is received or counted."}].
slow_subscriber_loses_and_counts(_Config) ->
    slow_subscriber(event).

slow_batch_subscriber_loses_and_counts() ->
    [{doc, "A batch subscriber that does not read keeps at most about `buffer' events in its "
      "batches; every event is received or counted."}].
slow_batch_subscriber_loses_and_counts(_Config) ->
    slow_subscriber(batch).

%% 5000 emissions while a subscriber (of Delivery) with room for 100 does
%% not read: its mailbox holds at most about 100 events, then it reads, and
%% what it got and what it was told it lost add up to 5000, in order.
slow_subscriber(Delivery) ->
    sensor(s, [v]),
    Parent = self(),
    N = 5000,
    Buffer = 100,
    Sub = spawn_link(fun() ->
                             {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], buffer => Buffer,
                                                                   delivery => Delivery}),
                             Parent ! {subscribed, self()},
                             receive read -> ok end,
                             Parent ! {counted, self(), count(Ref, N, {0, 0, []})}
                     end),
    receive {subscribed, Sub} -> ok end,
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, N)],
    Queued = fun() ->
                     {messages, Ms} = process_info(Sub, messages),
                     length([E || {toroco_event, _, E} <- Ms])
                         + lists:sum([length(Es) || {toroco_events, _, Es} <- Ms])
             end,
    ok = wait_until(fun() -> Queued() > 0 end, 2000),
    true = Queued() =< Buffer + 1,
    Sub ! read,
    receive {counted, Sub, {Received, Dropped, Seq}} ->
            ct:pal("received ~b, dropped ~b of ~b (buffer ~b)", [Received, Dropped, N, Buffer]),
            N = Received + Dropped,
            true = Dropped > 0,
            Seq = lists:sort(Seq)                       % in emission order
    after 10000 -> ct:fail(no_count)
    end.

%% Received, dropped and the values received, until they add up to N (or
%% nothing more comes for 3 s).
count(_Ref, N, {R, D, Seq}) when R + D >= N ->
    {R, D, lists:reverse(Seq)};
count(Ref, N, Acc) ->
    receive
        {toroco_event, Ref, E} -> count(Ref, N, counted(E, Acc));
        {toroco_events, Ref, Es} -> count(Ref, N, lists:foldl(fun counted/2, Acc, Es))
    after 3000 -> {R, D, Seq} = Acc, {R, D, lists:reverse(Seq)}
    end.

counted({dropped, K}, {R, D, Seq}) -> {R, D + K, Seq};
counted({emit, _, _, send, I}, {R, D, Seq}) -> {R + 1, D, [I | Seq]}.

batch_delivery_same_events() ->
    [{doc, "With delivery => batch a subscriber gets the events a subscriber taking them one "
      "at a time gets, each source's in the same order, several to a message."}].
batch_delivery_same_events(_Config) ->
    chain(),
    {ok, One} = toroco:subscribe_events(#{kinds => [emit, deliver]}),
    {ok, Many} = toroco:subscribe_events(#{kinds => [emit, deliver], delivery => batch}),
    N = 1000,
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, N)],
    %% each value: emitted by s and b, delivered to b and a
    Singles = take_events(One, 4 * N, []),
    {Messages, Batched} = take_batches(Many, 4 * N, 0, []),
    ct:pal("~b events in ~b messages", [length(Batched), Messages]),
    BySource = fun(Es) -> maps:groups_from_list(fun(E) -> element(3, E) end, Es) end,
    true = BySource(Singles) =:= BySource(Batched),
    [{s, v}, {b, out}] = lists:usort(fun(X, Y) -> X >= Y end,
                                     [Src || {emit, _, Src, send, _} <- Batched]),
    true = Messages < N.

take_events(_Ref, 0, Acc) ->
    lists:reverse(Acc);
take_events(Ref, K, Acc) ->
    receive {toroco_event, Ref, E} -> take_events(Ref, K - 1, [E | Acc])
    after 5000 -> ct:fail({missing, K, events})
    end.

take_batches(_Ref, K, M, Acc) when K =< 0 ->
    {M, lists:append(lists:reverse(Acc))};
take_batches(Ref, K, M, Acc) ->
    receive {toroco_events, Ref, Es} -> take_batches(Ref, K - length(Es), M + 1, [Es | Acc])
    after 5000 -> ct:fail({missing, K, events})
    end.

dropped_reported_without_later_events() ->
    [{doc, "{dropped, N} reaches a subscriber as soon as it reads again, even if no later event comes."}].
dropped_reported_without_later_events(_Config) ->
    sensor(s, [v]),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], buffer => 5}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 50)],
    %% Read what is there, then nothing more is emitted.
    Got = fun Loop(R, D) ->
                  receive
                      {toroco_event, Ref, {dropped, K}} -> Loop(R, D + K);
                      {toroco_event, Ref, {emit, _, _, _, _}} -> Loop(R + 1, D)
                  after 1000 -> {R, D}
                  end
          end(0, 0),
    {Received, Dropped} = Got,
    50 = Received + Dropped,
    true = Dropped > 0.

per_source_order() ->
    [{doc, "Per source, events arrive in emission order."}].
per_source_order(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [deliver], names => [a]}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 500)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 500 end, 5000),
    Values = [V || {deliver, _, {a, in}, V} <- flushed(Ref)],
    Values = lists:seq(1, 500).

unsubscribe_stops_events() ->
    [{doc, "After unsubscribe_events/1, no event of that subscription is sent."}].
unsubscribe_stops_events(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{}),
    ok = toroco:unsubscribe_events(Ref),
    _ = events(Ref, 100),
    ok = toroco:inject({s, v}, x),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 2000),
    [] = events(Ref, 200),
    ok = toroco:unsubscribe_events(Ref).

dead_subscriber_is_unsubscribed() ->
    [{doc, "A subscriber that dies is unsubscribed: the network's processes drop its sinks."}].
dead_subscriber_is_unsubscribed(_Config) ->
    chain(),
    Sub = spawn(fun() -> {ok, _} = toroco:subscribe_events(#{}), receive stop -> ok end end),
    ok = wait_until(fun() -> toroco_tap:current() =/= [] end, 2000),
    Sub ! stop,
    ok = wait_until(fun() -> toroco_tap:current() =:= [] end, 2000),
    ok = wait_until(fun() -> tap_of(b) =:= #{} end, 2000).

bad_options_refused() ->
    [{doc, "Bad subscription options are refused with a reason naming them."}].
bad_options_refused(_Config) ->
    {error, {bad_kind, bogus}} = toroco:subscribe_events(#{kinds => [bogus]}),
    {error, {bad_buffer, 0}} = toroco:subscribe_events(#{buffer => 0}),
    {error, {bad_names, x}} = toroco:subscribe_events(#{names => x}),
    {error, {bad_option, colour}} = toroco:subscribe_events(#{colour => red}),
    {error, {bad_delivery, sometimes}} = toroco:subscribe_events(#{delivery => sometimes}),
    {error, {bad_options, nope}} = toroco:subscribe_events(nope),
    [] = toroco_tap:current().

no_subscriber_no_tap_state() ->
    [{doc, "With no subscriber the network's processes hold no sink: nothing to send, nothing to look up."}].
no_subscriber_no_tap_state(_Config) ->
    chain(),
    #{} = tap_of(b),
    0 = map_size(tap_of(b)),
    {ok, Ref} = toroco:subscribe_events(#{}),
    ok = wait_until(fun() -> map_size(tap_of(b)) > 0 end, 2000),
    ok = toroco:unsubscribe_events(Ref),
    ok = wait_until(fun() -> tap_of(b) =:= #{} end, 2000).

burst_goes_in_batches() ->
    [{doc, "A burst of 500 emissions reaches the subscription's feeder in at most 10 messages; the subscriber gets all 500, in order."}].
burst_goes_in_batches(_Config) ->
    sensor(s, [v]),
    ok = toroco:add_behavior(burst, tb_burst, #{layer => 1}),
    ok = toroco:set_inputs(burst, #{in => [{s, v}]}),
    {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [burst]}),
    Feeder = toroco_tap:feeder(Ref),
    1 = erlang:trace(Feeder, true, ['receive']),
    ok = toroco:inject({s, v}, 500),
    Values = [V || {emit, _, {burst, out}, send, V} <- take_events(Ref, 500, [])],
    Values = lists:seq(1, 500),
    _ = erlang:trace(Feeder, false, ['receive']),
    Batches = length([M || {trace, F, 'receive', M} <- traces(), F =:= Feeder,
                           element(1, M) =:= '$toroco_tap_batch']),
    ct:pal("~b messages to the feeder for 500 events", [Batches]),
    true = Batches >= 1 andalso Batches =< 10.

traces() ->
    receive {trace, _, _, _} = T -> [T | traces()]
    after 0 -> []
    end.

idle_subscription_costs_nothing() ->
    [{doc, "A subscription with nothing to carry costs no polling: its feeder is not scheduled at all."}].
idle_subscription_costs_nothing(_Config) ->
    chain(),
    {ok, Ref} = toroco:subscribe_events(#{}),
    Feeder = toroco_tap:feeder(Ref),
    %% Each router reports its state to a new subscription first.
    [_, _] = [R || {router, _, R, _} <- flushed(Ref)],
    ok = wait_until(fun() -> process_info(Feeder, status) =:= {status, waiting} end, 2000),
    1 = erlang:trace(Feeder, true, [running]),
    %% Three of the old watcher's idle periods (50 ms) without an event: at
    %% most the one scheduling that takes the trace flags in.
    Ins = fun Count(N) ->
                  receive {trace, Feeder, in, _} -> Count(N + 1);
                          {trace, Feeder, out, _} -> Count(N)
                  after 300 -> N
                  end
          end(0),
    true = Ins =< 1,
    _ = erlang:trace(Feeder, false, [running]),
    ok = toroco:inject({s, v}, x),
    {deliver, _, {a, in}, x} = await_event(Ref, fun(E) -> element(1, E) =:= deliver andalso
                                                          element(3, E) =:= {a, in} end, 2000).

network_hears_through_pg() ->
    [{doc, "Behaviors, devices and routers are the members of the tap's pg group, so a subscription change reaches each of them and nothing else."}].
network_hears_through_pg(_Config) ->
    chain(),
    Members = lists:sort(pg:get_local_members(toroco_tap_pg, network)),
    Expected = lists:sort([whereis(toroco_names:process(N)) || N <- [s, b, a]] ++
                          [whereis(toroco_names:router(R, I)) || {R, I} <- [{b, in}, {a, in}]]),
    Expected = Members,
    B = whereis(toroco_names:process(b)),
    ok = toroco:remove_behavior(b),
    ok = wait_until(fun() -> not lists:member(B, pg:get_local_members(toroco_tap_pg, network)) end,
                    2000).

%% The sinks the engine of `Name' holds (the engine's record, field `tap').
tap_of(Name) ->
    {_, E} = sys:get_state(toroco_names:process(Name)),
    lists:last([F || F <- tuple_to_list(E), is_map(F)]).

%%====================================================================
%% Resilience
%%====================================================================

wiring_server_crashes_100_times_under_load() ->
    [{doc, "Killing the wiring server 100 times under 1 kHz input: the actuator obeys the same wiring, inspect() unchanged."}].
wiring_server_crashes_100_times_under_load(_Config) ->
    sensor(s, [v]),
    sensor(low, [v]),
    ok = toroco:add_behavior(b, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(b, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{in => [{b, out}, {low, v}]}),
    ok = toroco:inject({low, v}, floor, #{latch => true}),
    Before = toroco:inspect(),
    BeforeA = maps:without([inputs, device], toroco:inspect(a)),
    Feeder = toroco_test_lib:paced(fun(I) -> ok = toroco:inject({s, v}, I) end, infinity, 1),
    Killed = [begin
                  Pid = whereis(toroco_wiring),
                  exit(Pid, kill),
                  ok = wait_until(fun() -> is_pid(whereis(toroco_wiring)) andalso whereis(toroco_wiring) =/= Pid end, 2000),
                  %% the feed reaches the actuator beside the new incarnation
                  Seen = length(toroco_fake_actuator:history(a)),
                  ok = toroco_fake_actuator:await(a, fun(H) -> length(H) > Seen end, 2000),
                  Pid
              end || _ <- lists:seq(1, 100)],
    %% a hundred incarnations were killed, each a new one, and none is left
    100 = length(lists:usort(Killed)),
    false = lists:any(fun erlang:is_process_alive/1, Killed),
    false = lists:member(whereis(toroco_wiring), Killed),
    ok = toroco_test_lib:stop_paced(Feeder),
    Before = toroco:inspect(),
    BeforeA = maps:without([inputs, device], toroco:inspect(a)),
    %% The robot kept obeying the wiring: b's events won over low's latch,
    %% and when b lets go, low's latch comes back.
    H = toroco_fake_actuator:history(a),
    Relayed = [V || {in, V, _} <- H, is_integer(V)],
    ct:pal("~b values relayed to the actuator while the wiring server was killed 100 times",
           [length(Relayed)]),
    true = length(Relayed) > 100,
    Relayed = lists:sort(Relayed),
    ok = toroco:inject({s, v}, {hold, last, 10}),
    ok = toroco_fake_actuator:await(a, fun(Hs) -> element(2, lists:last(Hs)) =:= floor end, 2000),
    %% And the wiring server still works.
    ok = toroco:add_behavior(c, tb_relay, #{}),
    ok = toroco:set_inputs(c, #{in => [{s, v}]}).

inject_into_own_output_is_refused() ->
    [{doc, "A behavior injecting into its own output from a callback gets {error, {self_call, Name}}, not a deadlock."}].
inject_into_own_output_is_refused(_Config) ->
    sensor(s, [v]),
    ok = toroco:add_behavior(b, tb_self_injector, #{}),
    ok = toroco:set_inputs(b, #{in => [{s, v}]}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{b, out}]}),
    ok = toroco:inject({s, v}, go),
    ok = toroco_fake_actuator:await(a, fun(H) -> [V || {_, V, _} <- H] =:= [{error, {self_call, b}}] end, 2000).

inject_unknown_and_stopped_names() ->
    [{doc, "inject names an unknown emitter or output in its error."}].
inject_unknown_and_stopped_names(_Config) ->
    sensor(s, [v]),
    {error, {unknown_name, nobody}} = toroco:inject({nobody, v}, 1),
    {error, {unknown_output, {s, w}}} = toroco:inject({s, w}, 1),
    {error, {bad_source, oops}} = toroco:inject(oops, 1).

restarts_counted_from_lifecycle() ->
    [{doc, "Restart counts come from lifecycle, whatever the log level."}].
restarts_counted_from_lifecycle(_Config) ->
    Level = maps:get(level, logger:get_primary_config()),
    ok = logger:set_primary_config(level, emergency),
    try
        chain(),
        0 = toroco_restarts:count(b),
        [begin
             Pid = whereis(toroco_names:process(b)),
             ok = toroco:inject({s, v}, crash),
             ok = wait_until(fun() -> is_pid(whereis(toroco_names:process(b))) andalso
                                          whereis(toroco_names:process(b)) =/= Pid end, 2000)
         end || _ <- [1, 2]],
        %% counted by the new incarnation as it starts, a moment after its name is taken
        ok = wait_until(fun() -> toroco_restarts:count(b) =:= 2 end, 2000)
    after
        logger:set_primary_config(level, Level)
    end.

reset_cancels_named_timeouts() ->
    [{doc, "Reset cancels the generic named timeouts the old run set: they never fire after it."}].
reset_cancels_named_timeouts(_Config) ->
    sensor(s, [v]),
    sensor(r, [go]),
    ok = toroco:add_behavior(b, tb_timer, #{params => #{ms => 300}}),
    ok = toroco:set_inputs(b, #{in => [{s, v}]}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{b, out}]}),
    ok = toroco:set_reset(b, [{r, go}]),
    %% Without a reset the timer fires.
    ok = toroco:inject({s, v}, arm),
    ok = toroco_fake_actuator:await(a, fun(H) -> [V || {_, V, _} <- H] =:= [ticked] end, 2000),
    %% Armed, then reset: it must not fire. The arm and the reset come
    %% through two routers, so the reset is sent once b is seen armed (a
    %% first reset brings it back to idle, where the test can tell).
    State = fun() ->
                    try sys:get_state(toroco_names:process(b), 1000) of {St, _} -> St
                    catch exit:_ -> unknown
                    end
            end,
    ok = toroco:inject({r, go}, first),
    toroco_test_lib:wait_until(fun() -> State() =:= idle end, 2000),
    ok = toroco:inject({s, v}, arm),
    toroco_test_lib:wait_until(fun() -> State() =:= armed end, 2000),
    ok = toroco:inject({r, go}, now),
    {error, timeout} = toroco_fake_actuator:await(a, fun(H) -> length(H) > 1 end, 800),
    [ticked] = toroco_test_lib:values(a).

quiet_path_hibernates_again_after_events() ->
    [{doc, "A behavior and its input's router hibernate when quiet, wake for the events of the "
      "path (which take the engine's short way), and hibernate again once quiet: each wake "
      "arms the idle tick again."}].
quiet_path_hibernates_again_after_events(_Config) ->
    Old = application:get_env(toroco, hibernate_after_ms),
    ok = application:set_env(toroco, hibernate_after_ms, 100),
    try
        chain(),
        Procs = [whereis(toroco_names:process(b)), whereis(toroco_names:router(b, in))],
        %% Looked at every 400 ms: a look is a signal the process handles
        %% itself, which costs it reductions, and looks at every tick (50
        %% ms here) would keep it from ever seeming idle.
        Asleep = fun() -> [process_info(P, current_function) || P <- Procs]
                              =:= [{current_function, {erlang, hibernate, 3}} || _ <- Procs]
                 end,
        Sleeps = fun() -> ok = toroco_test_lib:poll(Asleep, 10000, 400) end,
        [begin
             Sleeps(),
             ok = toroco:inject({s, v}, Round),
             await_values(a, lists:seq(1, Round))
         end || Round <- [1, 2, 3]],
        Sleeps()
    after
        toroco_test_lib:restore_env(toroco, hibernate_after_ms, Old)
    end.

unknown_events_fall_to_the_engine() ->
    [{doc, "A handle_event/4 without a clause for an event leaves it to the engine: calls get unknown_call."}].
unknown_events_fall_to_the_engine(_Config) ->
    ok = toroco:add_behavior(b, tb_timer, #{}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{b, out}]}),
    Pid = whereis(toroco_names:process(b)),
    {error, {unknown_call, {b, what}}} = gen_statem:call(Pid, what, 1000),
    Pid ! something_else,
    Pid ! ping,
    ok = toroco_fake_actuator:await(a, fun(H) -> [V || {_, V, _} <- H] =:= [pong] end, 2000),
    Pid = whereis(toroco_names:process(b)).

rewired_router_takes_its_configuration_from_the_call() ->
    [{doc, "A router being re-wired takes its new configuration with the wiring server's call: "
      "its row in the wiring table gone (or not writable by a stranger) when it takes the "
      "call in, it keeps running with its new sources."}].
rewired_router_takes_its_configuration_from_the_call(_Config) ->
    sensor(s1, [v]),
    sensor(s2, [v]),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{s1, v}]}),
    Router = whereis(toroco_names:router(a, in)),
    %% The router takes the call in only once resumed: meanwhile the row
    %% goes, as anything that takes it (a stranger could, while the table
    %% was public) would make it go.
    ok = sys:suspend(Router),
    Self = self(),
    spawn_link(fun() -> Self ! {changed, toroco:set_inputs(a, #{in => [{s2, v}, {s1, v}]})} end),
    ok = wait_until(fun() -> element(2, process_info(Router, message_queue_len)) > 0 end, 2000),
    _ = (catch ets:delete(toroco_wiring, {router, {a, in}})),
    ok = sys:resume(Router),
    ok = receive {changed, Reply} -> Reply after 10000 -> ct:fail(no_answer) end,
    Router = whereis(toroco_names:router(a, in)),
    ok = toroco:inject({s2, v}, from_s2),
    await_values(a, [from_s2]).

wiring_table_written_by_the_wiring_server_only() ->
    [{doc, "The wiring table is read by anyone and written only by the wiring server, in each "
      "incarnation: a stranger's write is refused; after a kill of the server the new one "
      "writes it, with the wiring it had."}].
wiring_table_written_by_the_wiring_server_only(_Config) ->
    sensor(s, [v]),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{s, v}]}),
    {ok, _} = toroco_wiring:lookup({router, {a, in}}),
    {'EXIT', {badarg, _}} = (catch ets:insert(toroco_wiring, {stranger, row})),
    {'EXIT', {badarg, _}} = (catch ets:delete(toroco_wiring, {router, {a, in}})),
    Old = whereis(toroco_wiring),
    exit(Old, kill),
    ok = wait_until(fun() -> is_pid(whereis(toroco_wiring)) andalso whereis(toroco_wiring) =/= Old end,
                    2000),
    ok = toroco:set_inputs(a, #{in => []}),
    error = toroco_wiring:lookup({router, {a, in}}),
    ok = toroco:set_inputs(a, #{in => [{s, v}]}),
    true = ets:info(toroco_wiring, owner) =:= whereis(toroco_wiring),
    ok = toroco:inject({s, v}, after_kill),
    await_values(a, [after_kill]).

failed_first_start_in_a_new_layer() ->
    [{doc, "A behavior whose init fails, first in a new layer, is refused; the next add to that layer works."}].
failed_first_start_in_a_new_layer(_Config) ->
    %% tb_crasher needs `value' and `after_ms': without them init/1 fails.
    {error, {start_failed, {c, _}}} = toroco:add_behavior(c, tb_crasher, #{layer => 7}),
    #{behaviors := []} = toroco:inspect(),
    ok = toroco:add_behavior(b, tb_relay, #{layer => 7}),
    #{layers := #{7 := [b]}} = toroco:inspect(),
    Wiring = whereis(toroco_wiring),
    ok = toroco:add_behavior(d, tb_relay, #{layer => 7}),
    Wiring = whereis(toroco_wiring).
