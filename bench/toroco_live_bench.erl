%% The dashboard's benchmark (a section of `make bench' of its own):
%%   1. the closed loop of toroco_bench (source → relay → sink) without the
%%      dashboard (no tap subscriber: the reference), with the dashboard and
%%      no page open (its hub subscribes to the tap for /metrics and the
%%      events per wire), and with one browser-like WebSocket client
%%      subscribed, taken in turn in the same run;
%%   2. the page's update rate while a fake sensor emits at 1 kHz;
%%   3. the node's memory over time meanwhile (one sample a second).
%% The client is the suites' WebSocket client: it reads and decodes every
%% frame, as a page does. TOROCO_BENCH_QUICK=1 runs shorter tests.
-module(toroco_live_bench).
-export([main/1]).

main([Dir]) ->
    Quick = toroco_bench:setup(Dir),
    {ok, _} = application:ensure_all_started(toroco_hw),
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_live),
    {ok, #{http := Port}} = toroco_live:start(#{http => 0, foxglove => off}),
    %% Long enough runs for the page to be pushed many states meanwhile.
    N = case Quick of true -> 20000; false -> 100000 end,
    io:format("~n## Dashboard (toroco_live)~n~nOTP ~s, ~w schedulers; figures are only "
              "comparable within one run, on a quiet machine~n",
              [erlang:system_info(otp_release), erlang:system_info(schedulers_online)]),
    Rounds = case Quick of true -> 2; false -> 3 end,
    Loops = lists:append([[closed_loop(off, Port, N), closed_loop(none, Port, N),
                           closed_loop(client, Port, N)]
                          || _ <- lists:seq(1, Rounds)]),
    loop_table(Loops, N, Dir),
    Secs = case Quick of true -> 20; false -> 300 end,
    live_table(at_1khz(Port, Secs), Secs, Dir),
    halt(0).

%%====================================================================
%% 1. Closed loop, with and without a page
%%====================================================================

closed_loop(off, Port, N) ->
    ok = toroco_live:stop(),
    R = closed_loop(none, Port, N),
    {ok, _} = toroco_live:start(#{http => Port, foxglove => off}),
    R#{with := off};
closed_loop(With, Port, N) ->
    Client = case With of
                 none -> none;
                 client -> C = toroco_live_test_client:ws(Port, ""), C
             end,
    ok = toroco:add_behavior(src, toroco_bench_source, #{layer => 1}),
    ok = toroco:add_behavior(relay, toroco_bench_relay, #{layer => 0}),
    Src = whereis(toroco_names:process(src)),
    ok = toroco:add_device(sink, toroco_bench_sink,
                           #{expect => N, mode => closed, source => Src, controller => self()}),
    ok = toroco:set_inputs(relay, #{in => [{src, out}]}),
    ok = toroco:set_inputs(sink, #{in => [{relay, out}]}),
    _ = drain(Client, 0),
    W0 = erlang:monotonic_time(nanosecond),
    Src ! {run, closed, N},
    Lats = receive {sink_done, _, _End, L} -> lists:sort(L) after N * 20 + 10000 -> [] end,
    Ns = erlang:monotonic_time(nanosecond) - W0,
    Frames = drain(Client, 0),
    _ = [toroco:remove_behavior(B) || B <- [src, relay]],
    ok = toroco:remove_device(sink),
    case Client of none -> ok; _ -> toroco_live_test_client:ws_close(Client) end,
    #{with => With, lats => Lats, ns => Ns, frames => Frames}.

drain(none, N) -> N;
drain(C, N) ->
    receive {wsc, C, _} -> drain(C, N + 1) after 0 -> N end.

loop_table(Rows, N, Dir) ->
    Us = fun(X) -> X / 1000 end,
    Line = fun(#{with := W, lats := L, ns := Ns, frames := F}) ->
                   io_lib:format("| ~s | ~.1f | ~.1f | ~.1f | ~w | ~w |~n",
                                 [case W of off -> "no dashboard"; none -> "dashboard, no page";
                                      client -> "one WS client" end,
                                  Us(pct(L, 0.5)), Us(pct(L, 0.99)),
                                  Us(lists:sum(L) / max(1, length(L))),
                                  round(length(L) / (Ns / 1.0e9)), F])
           end,
    Text = [io_lib:format("~n### Closed loop (~w events a run), runs in turn~n~n", [N]),
            "| page | p50 µs | p99 µs | avg µs | events/s | state frames the client got |\n",
            "|---|---:|---:|---:|---:|---:|\n", [Line(R) || R <- Rows],
            ratio(Rows)],
    out(Text, Dir, "live_closed_loop").

ratio(Rows) ->
    Avg = fun(W, K) -> Xs = [K(R) || R = #{with := X} <- Rows, X =:= W],
                       lists:sum(Xs) / max(1, length(Xs)) end,
    P50 = fun(#{lats := L}) -> pct(L, 0.5) end,
    Rate = fun(#{lats := L, ns := Ns}) -> length(L) / (Ns / 1.0e9) end,
    io_lib:format("~nAgainst no dashboard: with one client p50 latency ×~.2f, throughput ×~.2f; "
                  "with the dashboard and no page p50 ×~.2f, throughput ×~.2f~n",
                  [Avg(client, P50) / max(1, Avg(off, P50)),
                   Avg(client, Rate) / max(1.0, Avg(off, Rate)),
                   Avg(none, P50) / max(1, Avg(off, P50)),
                   Avg(none, Rate) / max(1.0, Avg(off, Rate))]).

pct([], _) -> 0;
pct(Sorted, P) -> lists:nth(max(1, round(P * length(Sorted))), Sorted).

%%====================================================================
%% 2, 3. The page at 1 kHz sensor input, and memory over time
%%====================================================================

at_1khz(Port, Secs) ->
    ok = toroco:add_device(bench_eye, toroco_fake_sensor, #{outputs => [v]}),
    %% A relay, not a fake actuator: that one keeps every delivery.
    ok = toroco:add_behavior(bench_relay, toroco_bench_relay, #{layer => 0}),
    ok = toroco:set_inputs(bench_relay, #{in => [{bench_eye, v}]}),
    Client = toroco_live_test_client:ws(Port, ""),
    Feeder = spawn_link(fun() -> feed(erlang:monotonic_time(millisecond), 0) end),
    T0 = erlang:monotonic_time(millisecond),
    Samples = sample(Client, T0, Secs, []),
    unlink(Feeder), exit(Feeder, kill),
    toroco_live_test_client:ws_close(Client),
    Stats = toroco_live_hub:stats(),
    _ = toroco:remove_device(bench_eye), _ = toroco:remove_behavior(bench_relay),
    #{samples => lists:reverse(Samples), stats => Stats}.

%% One event a millisecond, on absolute deadlines.
feed(T0, K) ->
    ok = toroco:inject({bench_eye, v}, K),
    Next = T0 + K + 1,
    case Next - erlang:monotonic_time(millisecond) of
        Wait when Wait > 0 -> receive after Wait -> ok end;
        _ -> ok
    end,
    feed(T0, K + 1).

%% Each second: state frames the client got, bytes, node memory.
sample(_Client, _T0, 0, Acc) -> Acc;
sample(Client, T0, Left, Acc) ->
    End = T0 + (length(Acc) + 1) * 1000,
    {Frames, Bytes} = count(Client, End, 0, 0),
    erlang:garbage_collect(),
    Mem = erlang:memory(total),
    sample(Client, T0, Left - 1, [{Frames, Bytes, Mem} | Acc]).

count(Client, End, F, B) ->
    case End - erlang:monotonic_time(millisecond) of
        Left when Left > 0 ->
            receive
                {wsc, Client, #{<<"type">> := <<"state">>} = J} ->
                    count(Client, End, F + 1, B + byte_size(jiffy:encode(J)));
                {wsc, Client, _} -> count(Client, End, F, B)
            after Left -> {F, B}
            end;
        _ -> {F, B}
    end.

live_table(#{samples := Samples, stats := Stats}, Secs, Dir) ->
    Rates = lists:sort([F || {F, _, _} <- Samples]),
    Mems = [M div 1024 || {_, _, M} <- Samples],
    Bytes = lists:sum([B || {_, B, _} <- Samples]) / max(1, lists:sum([F || {F, _, _} <- Samples])),
    Third = max(1, length(Mems) div 3),
    First = lists:sum(lists:sublist(Mems, Third)) / Third,
    Last = lists:sum(lists:nthtail(length(Mems) - Third, Mems)) / Third,
    Text = [io_lib:format("~n### The page at 1 kHz sensor input, ~w s~n~n", [Secs]),
            "| page updates/s min | p50 | max | mean state frame (bytes) | skipped (coalesced) | tap events dropped |\n",
            "|---:|---:|---:|---:|---:|---:|\n",
            io_lib:format("| ~w | ~w | ~w | ~w | ~w | ~w |~n",
                          [hd(Rates), pct(Rates, 0.5), lists:last(Rates), round(Bytes),
                           maps:get(skipped, Stats, 0), maps:get(tap_dropped, Stats, 0)]),
            io_lib:format("~n### Node memory meanwhile (KiB, one sample a second)~n~n"
                          "| first | min | max | last | mean of the first third | mean of the last third |~n"
                          "|---:|---:|---:|---:|---:|---:|~n| ~w | ~w | ~w | ~w | ~w | ~w |~n",
                          [hd(Mems), lists:min(Mems), lists:max(Mems), lists:last(Mems),
                           round(First), round(Last)])],
    out(Text, Dir, "live_page").

out(Text, Dir, File) ->
    io:put_chars(Text),
    ok = file:write_file(filename:join(Dir, File ++ ".md"), unicode:characters_to_binary(Text)).
