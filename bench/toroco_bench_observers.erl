%% The benchmark's observers section (`make bench', TOROCO_BENCH_ONLY=observers
%% runs it alone): what watching the robot costs its event path. The chain
%% of toroco_bench (source → relay → sink) runs with no observer and with
%% each observer in turn, in the same run, for several rounds:
%%   - one tap subscriber taking every event (a plain process reading
%%     `{toroco_event, Ref, Event}');
%%   - the same subscriber with room for one event (`buffer => 1'): the
%%     producers tap every event and drop nearly all of them, so the row is
%%     what tapping costs the event path itself, the subscriber's own work
%%     left out;
%%   - the dashboard with one connected page (the suites' WebSocket client,
%%     which reads and decodes every frame as a page does), its flight
%%     recorder on;
%%   - the flight recorder alone (toroco_live with no dashboard listening);
%%   - recording every topic to MCAP (with the flight recorder).
%% Each case gives the closed loop's p50 and the open-loop throughput
%% (window 1000); recording also runs at the thesis' 10 ms pacing (events
%% dropped); the dashboard's page updates are counted at 1 kHz input. The
%% table shows each figure's median over the rounds and its ratio to no
%% observer's median. TOROCO_BENCH_OBSERVERS=tap,recording (say) runs those
%% cases only, beside no observer. scripts/bench runs the section twice:
%% with the machine's schedulers, and with one (`+S 1', the board's count),
%% each with a table of its own.
-module(toroco_bench_observers).
-export([main/1, live/0]).

main([Dir]) ->
    Quick = toroco_bench:setup(Dir),
    N = case Quick of true -> 2000; false -> 10000 end,
    Window = case Quick of true -> 50000; false -> 300000 end,
    Paced = case Quick of true -> 300; false -> 3000 end,
    Rounds = case Quick of true -> 3; false -> 5 end,
    File = filename:join(Dir, "observers.mcap"),
    toroco_bench:warm_up(),
    Cases = case os:getenv("TOROCO_BENCH_OBSERVERS") of
                false -> [none, tap, tap_full, dashboard, flight, recording];
                Only -> [none | [list_to_existing_atom(C) || C <- string:lexemes(Only, ",")]]
            end,
    Runs = lists:append([[run(Case, N, Window, File) || Case <- Cases] || _ <- lists:seq(1, Rounds)]),
    PacedRuns = lists:append([[paced(Case, Paced, File) || Case <- [none, recording],
                                                           lists:member(Case, Cases)]
                              || _ <- lists:seq(1, Rounds)]),
    Page = case lists:member(dashboard, Cases) of
               true -> page_at_1khz(case Quick of true -> 5; false -> 30 end);
               false -> none
           end,
    table(Cases, Runs, PacedRuns, Page, N, Window, Paced, Rounds, Dir),
    halt(0).

%%====================================================================
%% Runs
%%====================================================================

%% One case: the closed loop, then the open loop, each on a fresh chain
%% with the observer started after it.
run(Case, N, Window, File) ->
    toroco_bench:chain(closed, N),
    {Closed, _} = observed(Case, File, fun() -> toroco_bench:run(closed, N, N * 20 + 10000) end),
    toroco_bench:chain({window, 100}, Window),
    {Open, Dropped} = observed(Case, File, fun() -> toroco_bench:run({window, 1000}, Window, 120000) end),
    #{case_ => Case, p50 => pct(lists:sort(maps:get(lat, Closed)), 0.5),
      rate => Window / (maps:get(wall_ns, Open) / 1.0e9),
      lost => maps:get(lost, Closed, 0) + maps:get(lost, Open, 0), dropped => Dropped}.

paced(Case, N, File) ->
    toroco_bench:chain(none, N),
    {R, Dropped} = observed(Case, File, fun() -> toroco_bench:run({paced, 10}, N, N * 20 + 10000) end),
    #{case_ => Case, p50 => pct(lists:sort(maps:get(lat, R)), 0.5), lost => maps:get(lost, R, 0),
      dropped => Dropped}.

%% Runs Fun with the observer of Case on; returns its result and the
%% events the observer lost (dropped by the tap, or by a recording).
observed(none, _File, Fun) ->
    {Fun(), 0};
observed(tap, _File, Fun) ->
    subscribed(#{}, Fun);
observed(tap_full, _File, Fun) ->
    subscribed(#{buffer => 1}, Fun);
observed(dashboard, _File, Fun) ->
    live(),
    {ok, #{http := Port}} = toroco_live:start(#{http => 0, foxglove => off}),
    Client = toroco_live_test_client:ws(Port, ""),
    {ok, _} = toroco_live_test_client:ws_next(Client, fun(#{<<"type">> := T}) -> T =:= <<"state">> end,
                                              5000),
    R = Fun(),
    #{tap_dropped := Dropped} = toroco_live_hub:stats(),
    toroco_live_test_client:ws_close(Client),
    ok = toroco_live:stop(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {R, Dropped};
observed(flight, _File, Fun) ->
    live(),
    R = Fun(),
    #{dropped := Dropped} = toroco_rec:window(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {R, Dropped};
observed(recording, File, Fun) ->
    live(),
    ok = toroco_live:record(File, #{}),
    R = Fun(),
    {ok, #{dropped := Dropped}} = toroco_live:stop_recording(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {R, Dropped}.

%% The recorders only: no dashboard or bridge listening.
live() ->
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_live),
    ok.

%% Runs Fun with a plain process subscribed to every event (Opts).
subscribed(Opts, Fun) ->
    Parent = self(),
    Reader = spawn(fun() ->
                           {ok, Ref} = toroco:subscribe_events(Opts),
                           Parent ! {self(), subscribed},
                           read(Ref, 0)
                   end),
    receive {Reader, subscribed} -> ok end,
    R = Fun(),
    Reader ! {stop, self()},
    receive {Reader, Dropped} -> {R, Dropped} end.

read(Ref, Dropped) ->
    receive
        {toroco_event, Ref, {dropped, K}} -> read(Ref, Dropped + K);
        {toroco_event, Ref, _} -> read(Ref, Dropped);
        {stop, From} -> From ! {self(), Dropped}
    end.

%% State frames a connected page gets a second while a sensor emits at
%% 1 kHz into a relay.
page_at_1khz(Secs) ->
    toroco_bench:chain(none, 10),
    ok = toroco:add_device(bench_eye, toroco_fake_sensor, #{outputs => [v]}),
    ok = toroco:add_behavior(bench_relay, toroco_bench_relay, #{layer => 0}),
    ok = toroco:set_inputs(bench_relay, #{in => [{bench_eye, v}]}),
    live(),
    {ok, #{http := Port}} = toroco_live:start(#{http => 0, foxglove => off}),
    Client = toroco_live_test_client:ws(Port, ""),
    Feeder = spawn_link(fun() -> feed(erlang:monotonic_time(millisecond), 0) end),
    T0 = erlang:monotonic_time(millisecond),
    Frames = frames(Client, T0 + Secs * 1000, 0),
    unlink(Feeder), exit(Feeder, kill),
    toroco_live_test_client:ws_close(Client),
    ok = toroco_live:stop(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    Frames / Secs.

feed(T0, K) ->
    ok = toroco:inject({bench_eye, v}, K),
    case T0 + K + 1 - erlang:monotonic_time(millisecond) of
        Wait when Wait > 0 -> receive after Wait -> ok end;
        _ -> ok
    end,
    feed(T0, K + 1).

frames(Client, End, F) ->
    case End - erlang:monotonic_time(millisecond) of
        Left when Left > 0 ->
            receive
                {wsc, Client, #{<<"type">> := <<"state">>}} -> frames(Client, End, F + 1);
                {wsc, Client, _} -> frames(Client, End, F)
            after Left -> F
            end;
        _ -> F
    end.

%%====================================================================
%% The table
%%====================================================================

table(Cases, Runs, PacedRuns, Page, N, Window, Paced, Rounds, Dir) ->
    Of = fun(Case, Rs) -> [R || R = #{case_ := C} <- Rs, C =:= Case] end,
    Med = fun(K, Rs) -> median([maps:get(K, R) || R <- Rs]) end,
    None = Of(none, Runs),
    P50None = Med(p50, None), RateNone = Med(rate, None),
    PacedNone = Med(p50, Of(none, PacedRuns)),
    Row = fun(Case) ->
                  Rs = Of(Case, Runs),
                  P50 = Med(p50, Rs), Rate = Med(rate, Rs),
                  Pace = case Of(Case, PacedRuns) of
                             [] -> "–";
                             Ps -> io_lib:format("~.1f (×~.2f), ~w dropped",
                                                 [Med(p50, Ps) / 1000, Med(p50, Ps) / max(1, PacedNone),
                                                  lists:sum([maps:get(dropped, P) || P <- Ps])])
                         end,
                  io_lib:format("| ~ts | ~.1f | ×~.2f | ~w | ×~.2f | ~ts | ~w | ~w |~n",
                                [label(Case), P50 / 1000, P50 / max(1, P50None), round(Rate),
                                 Rate / max(1.0, RateNone), Pace,
                                 lists:sum([maps:get(dropped, R) || R <- Rs]),
                                 lists:sum([maps:get(lost, R) || R <- Rs])])
          end,
    Scheds = erlang:system_info(schedulers_online),
    Title = case Scheds of
                1 -> "## Observers on one scheduler (the board's count)";
                _ -> "## Observers"
            end,
    Text = [io_lib:format("~n~ts~n~nThe chain source → relay → sink with no observer and "
                          "with each observer, in turn, ~b rounds in the same run; medians over "
                          "the rounds; ~ts. Closed loop ~b events, open loop (window "
                          "1000) ~b events, 10 ms pacing ~b events.~n~n",
                          [Title, Rounds, case Scheds of 1 -> "one scheduler"; _ -> integer_to_list(Scheds) ++ " schedulers" end,
                           N, Window, Paced]),
            "| observer | closed-loop p50 µs | p50 vs none | open-loop events/s | throughput vs none "
            "| 10 ms pacing p50 µs, dropped | events the observer dropped (all rounds) | lost on the robot |\n",
            "|---|---:|---:|---:|---:|---|---:|---:|\n",
            [Row(C) || C <- Cases],
            case Page of
                none -> [];
                _ -> io_lib:format("~nThe dashboard's page at 1 kHz sensor input: ~.1f state frames "
                                   "a second.~n", [Page])
            end],
    io:format("~ts", [Text]),
    File = case Scheds of 1 -> "observers_one_scheduler.md"; _ -> "observers.md" end,
    ok = file:write_file(filename:join(Dir, File), unicode:characters_to_binary(Text)).

label(none) -> "none";
label(tap) -> "one tap subscriber taking every event";
label(tap_full) -> "the same with room for 1 event (what tapping costs the producers)";
label(dashboard) -> "dashboard with one connected page";
label(flight) -> "flight recorder alone";
label(recording) -> "recording every topic".

median(Xs) ->
    lists:nth((length(Xs) + 1) div 2, lists:sort(Xs)).

pct([], _) -> 0;
pct(Sorted, P) -> lists:nth(max(1, round(P * length(Sorted))), Sorted).
