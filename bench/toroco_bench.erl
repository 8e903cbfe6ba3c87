%% The benchmark: the thesis' internal and external tests (tables 5.2 and 5.3)
%% on this runtime, then throughput and scaling. Prints Markdown tables, writes
%% CSV files and a latency CDF (SVG) per test under the results directory.
%%
%% Run with `make bench' (or `scripts/bench'). `main/1' takes the results
%% directory; env `TOROCO_BENCH_QUICK=1' runs shorter tests.
-module(toroco_bench).
-export([main/1]).
%% The chain and its tables, for the recording section (toroco_bench_live).
-export([setup/1, warm_up/0, chain/2, run/3, measure/4, row/4, table/4]).
%% CPU time, for the sections that count it (toroco_bench_cpu, toroco_bench_perf).
-export([cpu_ticks/0, stat_ticks/1, ticks_per_sec/0]).

-define(N, 10000).

%% What every section of the benchmark does first: its results directory,
%% UTF-8 output, only errors logged. `true' for a quick run
%% (TOROCO_BENCH_QUICK=1).
-spec setup(file:filename()) -> boolean().
setup(Dir) ->
    ok = filelib:ensure_path(Dir),
    ok = io:setopts([{encoding, unicode}]),
    logger:set_primary_config(level, error),
    os:getenv("TOROCO_BENCH_QUICK") =:= "1".

%% `main([Dir])' runs the sections `tap', `raw' and `scaling'; `main([Dir,
%% Sections])' the ones named (comma-separated) of: `tap' (the observer
%% tap's cost), `raw' (the thesis' internal and external tests against
%% their raw references, and open-loop throughput), `internal' (the
%% internal test alone, closed and 10 ms), `scaling' (sources per input,
%% fan-out, behaviors alive), `memory' (memory per idle behavior, by part).
main([Dir]) ->
    main([Dir, "tap,raw,scaling"]);
main([Dir, Sections]) ->
    Quick = setup(Dir),
    N = case Quick of true -> 2000; false -> ?N end,
    io:format("~ts~n~nMachine: ~ts~nOTP ~s, ~w schedulers~n~n",
              [<<"# Torocó benchmark"/utf8>>, machine(), erlang:system_info(otp_release),
               erlang:system_info(schedulers_online)]),
    warm_up(),
    [section(list_to_atom(S), Quick, N, Dir) || S <- string:lexemes(Sections, ",")],
    io:format("~nCSV files and latency CDFs (SVG) in ~s~n", [Dir]),
    halt(0).

section(memory, Quick, _N, _Dir) ->
    %% Idle behaviors are measured hibernated: a second of idleness is
    %% enough for that, and the settling waits for it (5 s by default).
    ok = application:set_env(toroco, hibernate_after_ms, 1000),
    put(settle_tries, case Quick of true -> 3; false -> 10 end),
    %% At 10 the VM's noise swamps the figure: a quick run shows 1,000 only.
    memory_table(case Quick of true -> [1000]; false -> [10, 1000, 10000] end);
section(internal, _Quick, N, Dir) ->
    table("Internal test", [internal(I, N, Dir) || I <- [closed, 10]], Dir, "internal");
section(tap, _Quick, N, Dir) ->
    Tap = [tap_row(Sub, N, Dir) || Sub <- [none, one, none, one]],
    table("Observer tap: the closed loop with no subscriber and with one subscriber reading every event "
          "(alternated, twice)", Tap, Dir, "tap");
section(raw, Quick, N, Dir) ->
    raw(Quick, N, Dir);
section(scaling, Quick, N, Dir) ->
    Sources = [sources_per_input(K, N, Dir) || K <- [1, 4, 16, 64]],
    table("Sources per input (the others holding latches below the measured source)", Sources, Dir, "sources"),
    Fanout = [fan_out(F, N div 2, Dir) || F <- [1, 8, 64]],
    table("Fan-out: one output wired to F receivers", Fanout, Dir, "fanout"),
    Alive = [alive(B, N, Dir) || B <- case Quick of true -> [10, 1000]; false -> [10, 1000, 10000] end],
    table("Behaviors alive (each idle behavior has one wired input, so one router)", Alive, Dir, "alive"),
    io:format("~n| behaviors alive | memory per idle behavior with its router (bytes) |~n|---:|---:|~n"),
    [io:format("| ~w | ~w |~n", [B, M]) || #{label := B, mem_per := M} <- Alive];
section(Other, _Quick, _N, _Dir) ->
    io:format(standard_error, "toroco_bench: no section ~s~n", [Other]),
    halt(2).

%% The internal and external tests against their references, alternated
%% before and after.
raw(Quick, N, Dir) ->
    Intervals = [closed, 1, 2, 5, 10],
    TputN = case Quick of true -> 100000; false -> 500000 end,
    %% A quick run paces fewer events: at 10 ms, 2,000 take 20 s a row.
    NOf = fun(closed) -> N; (_) when Quick -> 500; (_) -> N end,
    ExtN = case Quick of true -> 500; false -> N end,
    %% The raw references run before and after the runtime's tests; the
    %% "× raw" columns divide by the mean of the two.
    RawBefore = [raw_internal(toroco_bench_raw, I, NOf(I), Dir) || I <- Intervals],
    RawTputBefore = raw_throughput(toroco_bench_raw, 1000, TputN),
    StmBefore = [raw_internal(toroco_bench_statem, I, NOf(I), Dir) || I <- Intervals],
    StmTputBefore = raw_throughput(toroco_bench_statem, 1000, TputN),
    RawExtBefore = external(raw, ExtN, Dir),
    Internal = [internal(I, NOf(I), Dir) || I <- Intervals],
    Tput = [throughput(W, TputN) || W <- [1000]],
    External = external(toroco, ExtN, Dir),
    RawAfter = [raw_internal(toroco_bench_raw, I, NOf(I), Dir) || I <- Intervals],
    RawTputAfter = raw_throughput(toroco_bench_raw, 1000, TputN),
    StmAfter = [raw_internal(toroco_bench_statem, I, NOf(I), Dir) || I <- Intervals],
    StmTputAfter = raw_throughput(toroco_bench_statem, 1000, TputN),
    RawExtAfter = external(raw, ExtN, Dir),
    Raw = mean_rows(RawBefore, RawAfter),
    Stm = mean_rows(StmBefore, StmAfter),
    RawExt = mean_rows(RawExtBefore, RawExtAfter),
    Events = integer_to_list(N) ++ " events" ++ case Quick of
                                                    true -> " (paced rows 500)";
                                                    false -> ""
                                                end,
    table("Raw reference: five plain processes, source → … → sink, " ++ Events
          ++ " (mean of a run before and a run after the runtime's)", Raw, Dir, "raw_internal"),
    table("Structural reference: five plain gen_statems, source → … → sink, " ++ Events
          ++ " (mean of a run before and a run after the runtime's)", Stm, Dir, "statem_internal",
          [{"raw", Raw}]),
    table("Internal test: behavior → router → behavior → router → actuator, " ++ Events,
          Internal, Dir, "internal", [{"raw", Raw}, {"gen_statem", Stm}]),
    RawTput = mean_rate(RawTputBefore, RawTputAfter),
    StmTput = mean_rate(StmTputBefore, StmTputAfter),
    tput_table("Throughput, open loop with a bounded window", Tput, Dir, "throughput",
               [{"raw", RawTput}, {"gen_statem", StmTput}]),
    rounds(case Quick of true -> 5; false -> 9 end, N),
    RawExt =/= [] andalso table("Raw reference: UDP sender → plain gen_udp echo → UDP receiver "
                                "(mean of a run before and a run after)", RawExt, Dir, "raw_external"),
    External =/= [] andalso table("External test: UDP sender → udp_link → behavior → udp_link → UDP receiver", External, Dir, "external", [{"raw", RawExt}]).

machine() ->
    Cpu = case file:read_file("/proc/cpuinfo") of
              {ok, B} ->
                  case re:run(B, "model name\\s*:\\s*(.*)", [{capture, all_but_first, list}]) of
                      {match, [M]} -> M;
                      _ -> "unknown CPU"
                  end;
              _ -> "unknown CPU"
          end,
    io_lib:format("~s, ~w cores", [Cpu, erlang:system_info(logical_processors_available)]).

%%====================================================================
%% Networks
%%====================================================================

restart() ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok.

pid(Name) -> whereis(toroco_names:process(Name)).

%% source (layer 1) → relay (layer 0) → sink
chain(Mode, N) ->
    restart(),
    ok = toroco:add_behavior(src, toroco_bench_source, #{layer => 1}),
    ok = toroco:add_behavior(relay, toroco_bench_relay, #{layer => 0}),
    ok = toroco:add_device(sink, toroco_bench_sink,
                           #{expect => N, mode => Mode, source => pid(src), controller => self()}),
    ok = toroco:set_inputs(relay, #{in => [{src, out}]}),
    ok = toroco:set_inputs(sink, #{in => [{relay, out}]}).

run(Mode, N, Timeout) ->
    measure(pid(src), Mode, N, Timeout).

measure(Src, Mode, N, Timeout) ->
    Cpu0 = cpu_ticks(), W0 = erlang:monotonic_time(nanosecond),
    Src ! {run, Mode, N},
    receive
        {sink_done, _, End, Lats} ->
            Cpu1 = cpu_ticks(),
            #{lat => Lats, wall_ns => End - W0, n => N,
              cpu => 100 * (Cpu1 - Cpu0) / ticks_per_sec() / ((End - W0) / 1.0e9)}
    after Timeout ->
            #{lat => [], wall_ns => Timeout * 1000000, n => N, cpu => 0.0, lost => N}
    end.

warm_up() ->
    chain(closed, 2000),
    _ = run(closed, 2000, 10000),
    ok.

internal(Interval, N, Dir) ->
    Mode = case Interval of closed -> closed; Ms -> {paced, Ms} end,
    chain(case Mode of closed -> closed; _ -> none end, N),
    R = run(Mode, N, N * 20 + 10000),
    row(label(Interval), R, Dir, "internal_" ++ label(Interval)).

%% The closed loop with `one' subscriber of the observer tap taking every
%% event of every kind, or `none'.
tap_row(Sub, N, Dir) ->
    chain(closed, N),
    Reader = case Sub of
                 one -> tap_reader();
                 none -> none
             end,
    R = run(closed, N, N * 20 + 10000),
    Events = case Reader of
                 none -> 0;
                 _ -> Reader ! {stop, self()}, receive {Reader, Count} -> Count end
             end,
    Label = case Sub of
                none -> "no subscriber";
                one -> lists:flatten(io_lib:format("one subscriber (~b events)", [Events]))
            end,
    row(Label, R, Dir, "tap_" ++ atom_to_list(Sub)).

tap_reader() ->
    Parent = self(),
    Pid = spawn(fun() ->
                        {ok, Ref} = toroco:subscribe_events(#{}),
                        Parent ! {self(), subscribed},
                        tap_read(Ref, 0)
                end),
    receive {Pid, subscribed} -> Pid end.

tap_read(Ref, Count) ->
    receive
        {toroco_event, Ref, _} -> tap_read(Ref, Count + 1);
        {stop, From} -> From ! {self(), Count}
    end.

%% The same loads on a reference chain: toroco_bench_raw's plain processes
%% or toroco_bench_statem's plain gen_statems.
raw_internal(Ref, Interval, N, Dir) ->
    Mode = case Interval of closed -> closed; Ms -> {paced, Ms} end,
    Chain = {Src, _} = Ref:chain(case Mode of closed -> closed; _ -> none end, N, self()),
    R = measure(Src, Mode, N, N * 20 + 10000),
    Ref:stop(Chain),
    row(label(Interval), R, Dir, atom_to_list(Ref) ++ "_" ++ label(Interval)).

%% The closed loop of the three chains in rounds, one right after the
%% other: the machine runs every chain at one of two speeds about twice
%% apart, and changes from one moment to the next (on one scheduler as on
%% two: doc/benchmarks.md). A ratio of rows taken at different moments can
%% mix the two; a round's three rows are most often at the same one. Each
%% round's ratios, and their median.
rounds(K, N) ->
    Rs = [begin
              Raw = closed_p50(toroco_bench_raw, N),
              Stm = closed_p50(toroco_bench_statem, N),
              chain(closed, N),
              Rt = p50_of(run(closed, N, N * 20 + 10000)),
              {Raw, Stm, Rt}
          end || _ <- lists:seq(1, K)],
    Median = fun(L) -> lists:nth((length(L) + 1) div 2, lists:sort(L)) end,
    io:format("~n### Closed loop in rounds: the three chains one after the other, ~b events "
              "each, ~b rounds~n~n| round | raw p50 µs | gen_statem p50 µs | runtime p50 µs | "
              "gen_statem × raw | runtime × raw | runtime × gen_statem |~n"
              "|---:|---:|---:|---:|---:|---:|---:|~n", [N, K]),
    [io:format("| ~b | ~.1f | ~.1f | ~.1f | ~.2f | ~.2f | ~.2f |~n",
               [I, Raw, Stm, Rt, Stm / Raw, Rt / Raw, Rt / Stm])
     || {I, {Raw, Stm, Rt}} <- lists:zip(lists:seq(1, K), Rs)],
    io:format("| median | ~.1f | ~.1f | ~.1f | ~.2f | ~.2f | ~.2f |~n",
              [Median([R || {R, _, _} <- Rs]), Median([S || {_, S, _} <- Rs]),
               Median([T || {_, _, T} <- Rs]), Median([S / R || {R, S, _} <- Rs]),
               Median([T / R || {R, _, T} <- Rs]), Median([T / S || {_, S, T} <- Rs])]).

closed_p50(Ref, N) ->
    Chain = {Src, _} = Ref:chain(closed, N, self()),
    R = measure(Src, closed, N, N * 20 + 10000),
    Ref:stop(Chain),
    p50_of(R).

p50_of(#{lat := []}) -> 0.0;
p50_of(#{lat := Lats}) -> pct(lists:sort(Lats), 0.50) / 1000.

raw_throughput(Ref, W, N) ->
    Chain = {Src, _} = Ref:chain({window, 100}, N, self()),
    #{wall_ns := Ns} = measure(Src, {window, W}, N, 120000),
    Ref:stop(Chain),
    round(N / (Ns / 1.0e9)).

mean_rows(As, Bs) ->
    [A#{p50 => (P50a + P50b) / 2, p99 => (P99a + P99b) / 2, avg => (Avga + Avgb) / 2,
        min => min(Mina, Minb), max => max(Maxa, Maxb), rate => (Ra + Rb) div 2}
     || {A = #{p50 := P50a, p99 := P99a, avg := Avga, min := Mina, max := Maxa, rate := Ra},
         #{p50 := P50b, p99 := P99b, avg := Avgb, min := Minb, max := Maxb, rate := Rb}}
            <- lists:zip(As, Bs)].

mean_rate(A, B) -> (A + B) div 2.

throughput(W, N) ->
    chain({window, 100}, N),
    R = #{wall_ns := Ns} = run({window, W}, N, 120000),
    Rate = round(N / (Ns / 1.0e9)),
    #{label => W, n => N, rate => Rate, cpu => maps:get(cpu, R), lost => maps:get(lost, R, 0),
      mailbox_max => 0}.

sources_per_input(K, N, Dir) ->
    chain(closed, N),
    Others = [list_to_atom("hold" ++ integer_to_list(I)) || I <- lists:seq(2, K)],
    [ok = toroco:add_behavior(O, toroco_bench_relay, #{layer => 0}) || O <- Others],
    %% The measured source holds 1 s on each event (its router moves the timer
    %% every time); the others hold latches below it.
    ok = toroco:set_inputs(relay, #{in => [{src, out, #{hold => 1000}} | [{O, out} || O <- Others]]}),
    [ok = toroco:inject({O, out}, ignore, #{latch => true}) || O <- Others],
    R = run(closed, N, N * 20 + 10000),
    row(K, R, Dir, "sources_" ++ integer_to_list(K)).

fan_out(F, N, Dir) ->
    restart(),
    ok = toroco:add_behavior(src, toroco_bench_source, #{layer => 1}),
    Sinks = [list_to_atom("sink" ++ integer_to_list(I)) || I <- lists:seq(1, F)],
    [begin
         ok = toroco:add_device(S, toroco_bench_sink,
                                #{expect => N, mode => closed,
                                  source => pid(src), controller => self()}),
         ok = toroco:set_inputs(S, #{in => [{src, out}]})
     end || S <- Sinks],
    Cpu0 = cpu_ticks(), W0 = erlang:monotonic_time(nanosecond),
    pid(src) ! {run, {closed, F}, N},
    Results = [receive {sink_done, _, End, L} -> {End, L} after 60000 -> {W0, []} end || _ <- Sinks],
    End = lists:max([E || {E, _} <- Results]),
    Cpu1 = cpu_ticks(),
    Lats = lists:append([L || {_, L} <- Results]),
    R = #{lat => Lats, wall_ns => End - W0, n => N * F,
          cpu => 100 * (Cpu1 - Cpu0) / ticks_per_sec() / ((End - W0) / 1.0e9)},
    row(F, R, Dir, "fanout_" ++ integer_to_list(F)).

alive(B, N, Dir) ->
    chain(closed, N),
    ok = toroco:add_device(idle_src, toroco_fake_sensor, #{outputs => [v]}),
    settle_memory(),
    M0 = erlang:memory(total),
    Names = [list_to_atom("idle" ++ integer_to_list(I)) || I <- lists:seq(1, B)],
    Terms = [{behavior, Nm, toroco_bench_relay, #{layer => 0}} || Nm <- Names]
        ++ [{inputs, Nm, #{in => [{idle_src, v}]}} || Nm <- Names],
    ok = toroco_wiring:call({load, Terms}),
    settle_memory(),
    M1 = erlang:memory(total),
    R = run(closed, N, N * 20 + 60000),
    Row = row(B, R, Dir, "alive_" ++ integer_to_list(B)),
    Row#{mem_per => (M1 - M0) div B}.

%% Memory per idle behavior with its router, and where it goes: the new
%% behavior and router processes, what the processes that were there before
%% grew by (supervisors, the wiring server, the source's subscribers), ETS,
%% atoms, and the rest of the system. No latency is measured here.
memory_table(Counts) ->
    io:format("~n| behaviors alive | bytes per idle behavior with its router | behavior process | "
              "router and other new processes | older processes' growth | ETS | atoms | rest | processes |~n"
              "|---:|---:|---:|---:|---:|---:|---:|---:|---:|~n"),
    %% A first round, not shown: what starting the runtime leaves behind is
    %% freed during it, which would swamp the 10-behavior row.
    _ = memory_row(10, false),
    [memory_row(B, true) || B <- Counts],
    ok.

memory_row(B, Show) ->
    chain(closed, 10),
    ok = toroco:add_device(idle_src, toroco_fake_sensor, #{outputs => [v]}),
    settle_steady(erlang:memory(total), settle_tries()),
    Before = maps:from_list([{P, proc_mem(P)} || P <- processes()]),
    M0 = maps:from_list(erlang:memory()),
    Mine0 = proc_mem(self()),
    Names = [list_to_atom("idle" ++ integer_to_list(I)) || I <- lists:seq(1, B)],
    Terms = [{behavior, Nm, toroco_bench_relay, #{layer => 0}} || Nm <- Names]
        ++ [{inputs, Nm, #{in => [{idle_src, v}]}} || Nm <- Names],
    ok = toroco_wiring:call({load, Terms}),
    settle_steady(erlang:memory(total), settle_tries()),
    M1 = maps:from_list(erlang:memory()),
    %% This process holds the names: not the runtime's memory.
    Mine = proc_mem(self()) - Mine0,
    Behaviors = [whereis(toroco_names:process(Nm)) || Nm <- Names],
    BehaviorSet = maps:from_keys(Behaviors, true),
    {New, Grown} = lists:foldl(
                     fun(P, {NewAcc, GrownAcc}) ->
                             case {maps:find(P, Before), maps:is_key(P, BehaviorSet)} of
                                 {error, false} -> {NewAcc + proc_mem(P), GrownAcc};
                                 {error, true} -> {NewAcc, GrownAcc};
                                 {{ok, Was}, _} -> {NewAcc, GrownAcc + proc_mem(P) - Was}
                             end
                     end, {0, 0}, processes() -- [self()]),
    Beh = lists:sum([proc_mem(P) || P <- Behaviors]),
    D = fun(K) -> maps:get(K, M1) - maps:get(K, M0) end,
    Total = D(total) - Mine,
    Rest = Total - Beh - New - Grown - D(ets) - D(atom_used),
    Per = fun(X) -> round(X / B) end,
    Show andalso io:format("| ~w | ~w | ~w | ~w | ~w | ~w | ~w | ~w | ~w |~n",
              [B, Per(Total), Per(Beh), Per(New), Per(Grown), Per(D(ets)), Per(D(atom_used)),
               Per(Rest), erlang:system_info(process_count)]).

settle_tries() ->
    case get(settle_tries) of
        undefined -> 10;
        N -> N
    end.

%% Settles until the VM's total stays within 1 KB from one settling to the
%% next (what the previous round left is freed by then), at most N times.
settle_steady(_, 0) ->
    ok;
settle_steady(Was, N) ->
    settle_memory(),
    case erlang:memory(total) of
        Now when abs(Now - Was) < 1024 -> ok;
        Now -> settle_steady(Now, N - 1)
    end.

proc_mem(P) ->
    case erlang:process_info(P, memory) of
        {memory, M} -> M;
        undefined -> 0
    end.

%% Idle processes hibernate after hibernate_after_ms (5 s): measure after that.
settle_memory() ->
    timer:sleep(application:get_env(toroco, hibernate_after_ms, 5000) + 500),
    _ = [garbage_collect(P) || P <- processes()],
    ok.

%%====================================================================
%% External test
%%====================================================================

%% Needs the UDP link device and the C sender/receiver (bench/udp_bench.c,
%% built by scripts/bench). Skipped with a message if either is missing.
external(What, N, Dir) ->
    Prog = filename:join(filename:dirname(Dir), "udp_bench"),
    case {code:which(toroco_udp_link), filelib:is_regular(Prog)} of
        {non_existing, _} -> io:format("~n(external test skipped: no toroco_udp_link)~n"), [];
        {_, false} -> io:format("~n(external test skipped: no ~s)~n", [Prog]), [];
        _ -> [external_run(What, Prog, I, N, Dir) || I <- [10, 5, 2, 1, 0.1]]
    end.

%% `toroco': udp_link → relay behavior → udp_link; `raw': a plain gen_udp echo.
external_run(What, Prog, IntervalMs, N, Dir) ->
    {ok, InSock} = gen_udp:open(0), {ok, InPort} = inet:port(InSock), ok = gen_udp:close(InSock),
    {ok, OutSock} = gen_udp:open(0), {ok, OutPort} = inet:port(OutSock), ok = gen_udp:close(OutSock),
    Stop = case What of
               toroco ->
                   restart(),
                   ok = toroco:add_device(udp_in, toroco_udp_link, #{port => InPort, outputs => [event]}),
                   ok = toroco:add_behavior(relay, toroco_bench_relay, #{layer => 0}),
                   ok = toroco:add_device(udp_out, toroco_udp_link,
                                          #{port => 0, inputs => [in], peers => [{{127, 0, 0, 1}, OutPort}]}),
                   ok = toroco:set_inputs(relay, #{in => [{udp_in, event}]}),
                   ok = toroco:set_inputs(udp_out, #{in => [{relay, out}]}),
                   fun() -> ok end;
               raw ->
                   Echo = toroco_bench_raw:udp_echo({InPort, OutPort}),
                   fun() -> Echo ! stop end
           end,
    Cmd = lists:flatten(io_lib:format("~s ~w ~w ~w ~w", [Prog, InPort, OutPort, IntervalMs, N])),
    Cpu0 = cpu_ticks(), W0 = erlang:monotonic_time(nanosecond),
    Out = os:cmd(Cmd),
    Cpu1 = cpu_ticks(), W1 = erlang:monotonic_time(nanosecond),
    Stop(),
    {Lats, Lost} = parse_udp_bench(Out),
    R = #{lat => Lats, wall_ns => W1 - W0, n => N, lost => Lost,
          cpu => 100 * (Cpu1 - Cpu0) / ticks_per_sec() / ((W1 - W0) / 1.0e9)},
    row(IntervalMs, R, Dir, atom_to_list(What) ++ "_external_" ++ lists:flatten(io_lib:format("~w", [IntervalMs]))).

parse_udp_bench(Out) ->
    Lines = string:split(string:trim(Out), "\n", all),
    Lats = [list_to_integer(L) || "lat " ++ L <- Lines],
    Lost = case [list_to_integer(L) || "lost " ++ L <- Lines] of [X] -> X; _ -> length(Lats) end,
    {Lats, Lost}.

%%====================================================================
%% Figures
%%====================================================================

label(closed) -> "closed loop";
label(Ms) -> io_lib:format("~w ms", [Ms]).

row(Label, R = #{lat := Lats, wall_ns := Ns, n := N, cpu := Cpu}, Dir, File) ->
    S = lists:sort(Lats),
    Us = fun(X) -> X / 1000 end,
    Row = case S of
              [] -> #{label => Label, min => 0, avg => 0, max => 0, p50 => 0, p99 => 0};
              _ -> #{label => Label, min => Us(hd(S)), max => Us(lists:last(S)),
                     avg => Us(lists:sum(S) / length(S)), p50 => Us(pct(S, 0.50)),
                     p99 => Us(pct(S, 0.99))}
          end,
    write_csv(filename:join(Dir, File ++ ".csv"), S),
    write_cdf(filename:join(Dir, File ++ ".svg"), File, S),
    Row#{interval_us => Us(Ns / max(1, N)), rate => round(N / (Ns / 1.0e9)), cpu => Cpu,
         lost => maps:get(lost, R, N - length(Lats)) * min(1, length(Lats))}.

pct(Sorted, P) -> lists:nth(max(1, round(P * length(Sorted))), Sorted).

table(Title, Rows, Dir, File) ->
    table(Title, Rows, Dir, File, none).

%% With references (`[{Name, Rows}]', rows of the same labels from a
%% reference chain), a column per reference "× Name p50": this row's p50
%% over the reference's p50.
table(Title, Rows, Dir, File, none) ->
    table(Title, Rows, Dir, File, []);
table(Title, Rows, Dir, File, Refs) ->
    Header = ["| test | max µs | avg µs | min µs | p50 µs | p99 µs | mean interval µs | events/s | CPU % | lost |",
              [[" × ", Name, " p50 |"] || {Name, _} <- Refs]],
    Ratio = fun(L, P50) ->
                    [case [R || #{label := RL, p50 := R} <- Ref, RL =:= L] of
                         [R | _] when R > 0 -> io_lib:format(" ~.2f |", [P50 / R]);
                         _ -> " - |"
                     end || {_, Ref} <- Refs]
            end,
    Lines = [[io_lib:format("| ~ts | ~.1f | ~.1f | ~.1f | ~.1f | ~.1f | ~.1f | ~w | ~w | ~w |",
                            [to_s(L), float(Max), float(Avg), float(Min), float(P50), float(P99),
                             float(Iv), Rate, round(Cpu), Lost]), Ratio(L, P50)]
             || #{label := L, max := Max, avg := Avg, min := Min, p50 := P50, p99 := P99,
                  interval_us := Iv, rate := Rate, cpu := Cpu, lost := Lost} <- Rows],
    Text = ["\n### ", Title, "\n\n", Header, "\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            ["---:|" || _ <- Refs], "\n",
            lists:join("\n", Lines), "\n"],
    io:put_chars(Text),
    ok = file:write_file(filename:join(Dir, File ++ ".md"), unicode:characters_to_binary(Text)).

%% With a column pair per reference (`[{Name, Rate}]'): its events/s and
%% this row's rate over it.
tput_table(Title, Rows, Dir, File, Refs) ->
    Text = ["\n### ", Title, "\n\n| window | events | events/s | CPU % | lost |",
            [[" ", Name, " events/s | × ", Name, " |"] || {Name, _} <- Refs], "\n"
            "|---:|---:|---:|---:|---:|", ["---:|---:|" || _ <- Refs], "\n",
            [[io_lib:format("| ~w | ~w | ~w | ~w | ~w |", [W, N, Rate, round(Cpu), Lost]),
              [io_lib:format(" ~w | ~.2f |", [RefRate, Rate / max(1, RefRate)])
               || {_, RefRate} <- Refs], "\n"]
             || #{label := W, n := N, rate := Rate, cpu := Cpu, lost := Lost} <- Rows]],
    io:put_chars(Text),
    ok = file:write_file(filename:join(Dir, File ++ ".md"), unicode:characters_to_binary(Text)).

to_s(L) when is_integer(L) -> integer_to_list(L);
to_s(L) when is_float(L) -> float_to_list(L, [{decimals, 1}, compact]);
to_s(L) -> L.

write_csv(File, Sorted) ->
    ok = file:write_file(File, ["latency_ns\n", [[integer_to_list(round(X)), "\n"] || X <- Sorted]]).

%% Latency CDF on a log scale from 1 µs to 100 ms.
write_cdf(File, Title, Sorted) ->
    W = 480, H = 300, M = 40,
    Len = max(1, length(Sorted)),
    X = fun(Ns) -> M + (W - 2 * M) * (math:log10(max(1000, Ns) / 1000) / 5) end,
    Y = fun(P) -> H - M - (H - 2 * M) * P end,
    Step = max(1, Len div 400),
    Pts = [io_lib:format("~.1f,~.1f ", [float(X(V)), float(Y(I / Len))])
           || {I, V} <- lists:zip(lists:seq(1, length(Sorted)), Sorted), I rem Step =:= 0],
    Ticks = [io_lib:format("<text x='~.1f' y='~w' font-size='10' text-anchor='middle'>~s</text>",
                           [float(X(Ns)), H - M + 14, T])
             || {Ns, T} <- [{1000, "1µs"}, {10000, "10µs"}, {100000, "100µs"}, {1000000, "1ms"},
                            {10000000, "10ms"}, {100000000, "100ms"}]],
    Svg = [io_lib:format("<svg xmlns='http://www.w3.org/2000/svg' width='~w' height='~w'>", [W, H]),
           "<rect width='100%' height='100%' fill='white'/>",
           io_lib:format("<text x='~w' y='20' font-size='12'>~s latency CDF</text>", [M, Title]),
           io_lib:format("<line x1='~w' y1='~w' x2='~w' y2='~w' stroke='black'/>", [M, H - M, W - M, H - M]),
           io_lib:format("<line x1='~w' y1='~w' x2='~w' y2='~w' stroke='black'/>", [M, M, M, H - M]),
           Ticks,
           "<polyline fill='none' stroke='steelblue' stroke-width='1.5' points='", Pts, "'/></svg>\n"],
    ok = file:write_file(File, unicode:characters_to_binary(Svg)).

%%====================================================================
%% CPU of this VM
%%====================================================================

%% This VM's user + system time, in clock ticks.
cpu_ticks() ->
    stat_ticks("/proc/self/stat").

%% User + system time in a /proc `stat' file (a process's or a thread's),
%% in clock ticks; 0 if it cannot be read.
-spec stat_ticks(file:filename()) -> non_neg_integer().
stat_ticks(File) ->
    case file:read_file(File) of
        {ok, B} ->
            [_, Rest] = binary:split(B, <<") ">>),
            F = string:lexemes(binary_to_list(Rest), " "),
            list_to_integer(lists:nth(12, F)) + list_to_integer(lists:nth(13, F));
        {error, _} ->
            0
    end.

ticks_per_sec() ->
    case string:trim(os:cmd("getconf CLK_TCK")) of
        "" -> 100;
        T -> list_to_integer(T)
    end.
