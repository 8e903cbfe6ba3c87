%% CPU per event (TOROCO_BENCH_ONLY=cpu): events per second per CPU-second
%% of this VM (and of the `pru_port' program where it takes part), for the
%% internal chain (closed loop, open loop, paced) and for the Torobot's own
%% event mix: its real devices and wiring (as `torobot_sim_robot' starts
%% them, the `pru_port' on its sim backend), the two IR channels sampled at
%% the PRU's rate (1 kHz, every sample crossing the threshold: the most IR
%% events the board can see) and the camera's two colours at 30 frames/s,
%% as datagrams. The VM's flags are the caller's (`scripts/bench' runs this
%% with the bench's flags and again without the schedulers' busy wait);
%% `main/1' takes the results directory and a label for the flags.
%%
%% The VM's CPU is user + system time of all its threads from /proc, as
%% for `pru_port' (waking and sleeping schedulers is system time, most of
%% the cost at robot rates; under qemu user mode, `make board-bench', it is
%% the qemu process's CPU, translation included);
%% TOROCO_BENCH_CPU_CLOCK=runtime counts `statistics(runtime)' instead,
%% user time only. With TOROCO_BENCH_CPU_CSV=File
%% each row is also appended to File, tagged with TOROCO_BENCH_CPU_RUN;
%% `compare/1' prints such files as one table.
-module(toroco_bench_cpu).
-export([main/1, compare/1]).

-define(IR_NEAR, 300).
-define(IR_FAR, 100).

main([Dir, Flags]) ->
    Quick = toroco_bench:setup(Dir),
    Secs = case Quick of true -> 5; false -> 10 end,
    io:format("~n### CPU per event, VM flags `~s`~n~n~ts~n~n", [Flags, vm_line()]),
    io:format("| load | events | events/s | CPU-s per s (VM + pru_port) | events per CPU-second | "
              "µs CPU per event | p50 µs |~n|---|---:|---:|---:|---:|---:|---:|~n"),
    toroco_bench:warm_up(),
    N = case Quick of true -> 20000; false -> 100000 end,
    chain_row("internal chain, closed loop", closed, N),
    chain_row("internal chain, open loop (window 1000)", {window, 1000}, N),
    chain_row("internal chain, paced 1 ms", {paced, 1}, Secs * 1000),
    chain_row("internal chain, paced 10 ms", {paced, 10}, Secs * 100),
    torobot_row(Secs, Dir),
    halt(0).

chain_row(Label, Mode, N) ->
    toroco_bench:chain(case Mode of
                           closed -> closed;
                           {window, _} -> {window, 100};
                           _ -> none
                       end, N),
    Cpu0 = cpu_ms(),
    #{wall_ns := Ns, lat := Lats} = toroco_bench:run(Mode, N, N * 20 + 60000),
    Cpu = cpu_ms() - Cpu0,
    P50 = case lists:sort(Lats) of
              [] -> none;
              S -> lists:nth(max(1, length(S) div 2), S) / 1000
          end,
    print(Label, N, Ns / 1.0e9, Cpu / 1000, P50).

print(Label, Events, WallS, CpuS, P50) ->
    csv(Label, Events, WallS, CpuS),
    io:format("| ~ts | ~b | ~b | ~.3f | ~b | ~.2f | ~ts |~n",
              [Label, Events, round(Events / WallS), CpuS / WallS, round(Events / max(1.0e-9, CpuS)),
               1.0e6 * CpuS / max(1, Events),
               case P50 of none -> "-"; _ -> io_lib:format("~.1f", [float(P50)]) end]).

%% The Torobot's robot side on its real devices and wiring, fed for `Secs'.
torobot_row(Secs, _Dir) ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
    {ok, CamPort} = torobot_sim_robot:start(#{wiring => "config/torobot.wiring",
                                              thresholds => #{threshold_high => 240,
                                                              threshold_low => 200},
                                              speed => 1}),
    ok = torobot_sim_robot:go(local),
    {ok, Sock} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    timer:sleep(500),
    Port = pru_port_pid(),
    process_flag(trap_exit, true),
    Cpu0 = cpu_ms(), PortCpu0 = os_cpu_ms(Port), W0 = erlang:monotonic_time(millisecond),
    Ir = spawn_link(fun() -> ir(W0, Secs * 1000, 0) end),
    Cam = spawn_link(fun() -> camera(Sock, CamPort, W0, Secs * 30, 0) end),
    %% Generous: under emulation the feeders fall behind when the VM is saturated.
    [receive {'EXIT', P, normal} -> ok after Secs * 20000 + 60000 -> error({stuck, P}) end
     || P <- [Ir, Cam]],
    W1 = erlang:monotonic_time(millisecond),
    Cpu = cpu_ms() - Cpu0, PortCpu = os_cpu_ms(Port) - PortCpu0,
    WallS = (W1 - W0) / 1000,
    IrEvents = 2 * Secs * 1000, CamEvents = 2 * Secs * 30,
    print("Torobot: IR 2 × 1 kHz + camera 2 × 30/s (VM only)", IrEvents + CamEvents, WallS,
          Cpu / 1000, none),
    print("Torobot: IR 2 × 1 kHz + camera 2 × 30/s (VM + pru_port)", IrEvents + CamEvents, WallS,
          (Cpu + PortCpu) / 1000, none),
    io:format("~nTorobot: ~b IR events (each a sim_adc call into pru_port, which the board's PRU "
              "does without the VM), ~b camera datagrams, ~.1f s; pru_port ~b ms CPU, VM ~b ms~n",
              [IrEvents, CamEvents, WallS, round(PortCpu), round(Cpu)]),
    ok = gen_udp:close(Sock),
    torobot_sim_robot:stop().

%% Both IR channels every millisecond on absolute deadlines, near and far
%% in turn, so every sample is an event.
ir(T0, N, N) -> _ = T0, ok;
ir(T0, N, K) ->
    Raw = case K rem 2 of 0 -> ?IR_NEAR; 1 -> ?IR_FAR end,
    ok = toroco_pru_sensors:sim_adc(ir, left, Raw),
    ok = toroco_pru_sensors:sim_adc(ir, right, Raw),
    wait_until(T0 + K + 1),
    ir(T0, N, K + 1).

%% Red and blue every 1/30 s: a blob moving across the frame.
camera(_Sock, _Port, _T0, N, N) -> ok;
camera(Sock, Port, T0, N, K) ->
    X = (K rem 200) - 100,
    [ok = gen_udp:send(Sock, {127, 0, 0, 1}, Port,
                       iolist_to_binary(io_lib:format("{\"color\": \"~s\", \"x\": ~b, \"y\": 0, \"area\": 400}",
                                                      [C, X])))
     || C <- ["red", "blue"]],
    wait_until(T0 + (K + 1) * 1000 div 30),
    camera(Sock, Port, T0, N, K + 1).

wait_until(At) ->
    erlang:start_timer(At, self(), tick, [{abs, true}]),
    receive {timeout, _, tick} -> ok end.

%% This VM's CPU time (all threads), ms: user + system time of its threads,
%% or with TOROCO_BENCH_CPU_CLOCK=runtime user time (`statistics(runtime)').
cpu_ms() ->
    case proc_clock() of
        true ->
            tasks_ms(os:getpid());
        false ->
            {Ms, _} = erlang:statistics(runtime),
            Ms
    end.

proc_clock() ->
    os:getenv("TOROCO_BENCH_CPU_CLOCK") =/= "runtime".

%% The pru_port program of this VM: a child of its erl_child_setup.
pru_port_pid() ->
    Me = os:getpid(),
    Rows = [string:lexemes(L, " ") || L <- string:split(os:cmd("ps -e -o pid=,ppid=,comm="), "\n", all)],
    Setup = [P || [P, Pp, "erl_child_setup"] <- Rows, Pp =:= Me],
    case [P || [P, Pp, "pru_port"] <- Rows, lists:member(Pp, Setup)] of
        [P | _] -> P;
        [] -> none
    end.

%% User + system time of a process (a pid), ms.
os_cpu_ms(none) -> 0;
os_cpu_ms(Pid) ->
    case proc_clock() of
        true -> tasks_ms(Pid);
        false -> stat_ms("/proc/" ++ Pid ++ "/stat")
    end.

%% The time on a CPU of all threads of a process, ms, summed over
%% /proc/PID/task/*/schedstat (ns; /stat's times count 10 ms ticks, too coarse
%% for a row of 100 ms), or over their /stat where there is no schedstat.
%% The threads' files, not the process's: qemu user mode answers a
%% program's reads of its own /proc/PID/stat itself (with no times), not
%% those of its threads. No thread ends during a row.
tasks_ms(Pid) ->
    Task = "/proc/" ++ Pid ++ "/task",
    case file:list_dir(Task) of
        {ok, Tids} -> lists:sum([task_ms(filename:join(Task, T)) || T <- Tids]);
        {error, _} -> 0
    end.

task_ms(Dir) ->
    case file:read_file(Dir ++ "/schedstat") of
        {ok, B} ->
            [Ns | _] = string:lexemes(binary_to_list(B), " \n"),
            list_to_integer(Ns) / 1.0e6;
        {error, _} ->
            stat_ms(Dir ++ "/stat")
    end.

stat_ms(File) ->
    toroco_bench:stat_ticks(File) * 1000 div toroco_bench:ticks_per_sec().

%% Which VM this is: architecture, emulator flavor (jit or emu), word size,
%% schedulers.
vm_line() ->
    io_lib:format("VM: OTP ~s, ~s, flavor ~s, ~b-bit, ~b scheduler(s), CPU clock ~s",
                  [erlang:system_info(otp_release), erlang:system_info(system_architecture),
                   erlang:system_info(emu_flavor), 8 * erlang:system_info(wordsize),
                   erlang:system_info(schedulers_online),
                   case proc_clock() of
                       true -> "user + system (/proc/PID/task/*/schedstat)";
                       false -> "user (statistics(runtime))"
                   end]).

csv(Label, Events, WallS, CpuS) ->
    case os:getenv("TOROCO_BENCH_CPU_CSV") of
        false -> ok;
        File ->
            Run = os:getenv("TOROCO_BENCH_CPU_RUN", "run"),
            Line = io_lib:format("~ts;~ts;~b;~.6f;~.6f~n", [Run, Label, Events, WallS, CpuS]),
            ok = file:write_file(File, unicode:characters_to_binary(Line), [append])
    end.

%% compare([File | Prefixes]): the rows of File (written through
%% TOROCO_BENCH_CPU_CSV) as one table, load by load, runs in the order they
%% ran. Each run's CPU per event is divided by the first run's (the native
%% one to compare with) and by that of the first run whose tag starts with
%% each of Prefixes.
compare([File | Prefixes]) ->
    ok = io:setopts([{encoding, unicode}]),
    {ok, Bin} = file:read_file(File),
    Rows = [list_to_tuple(string:split(L, ";", all))
            || L <- string:lexemes(unicode:characters_to_list(Bin), "\n")],
    Loads = in_order([Load || {_, Load, _, _, _} <- Rows]),
    Runs = in_order([Run || {Run, _, _, _, _} <- Rows]),
    Bases = in_order([hd(Runs) | [R || P <- Prefixes, R <- [hd([X || X <- Runs, lists:prefix(P, X)] ++ [none])],
                                       R =/= none]]),
    Find = fun(Run, Load) ->
                   case [{list_to_integer(E), list_to_float(W), list_to_float(C)}
                         || {R, L, E, W, C} <- Rows, R =:= Run, L =:= Load] of
                       [{E, W, C} | _] -> {E, W, C};
                       [] -> none
                   end
           end,
    io:format("| load | run | events/s | CPU-s per s | events per CPU-second | µs CPU per event |~ts~n"
              "|---|---|---:|---:|---:|---:|~ts~n",
              [[[" ÷ ", B, " |"] || B <- Bases], [[" ---: |"] || _ <- Bases]]),
    _ = [case Find(Run, Load) of
             none -> ok;
             {E, W, C} ->
                 Ratios = [case Find(B, Load) of
                               {E0, _, C0} when C0 > 0, E > 0 ->
                                   io_lib:format(" ~.1f |", [(C / E) / (C0 / E0)]);
                               _ -> " - |"
                           end || B <- Bases],
                 io:format("| ~ts | ~ts | ~b | ~.3f | ~b | ~.1f |~ts~n",
                           [Load, Run, round(E / W), C / W, round(E / max(1.0e-9, C)),
                            1.0e6 * C / max(1, E), Ratios])
         end || Load <- Loads, Run <- Runs],
    halt(0).

in_order(L) ->
    lists:foldl(fun(X, Acc) -> case lists:member(X, Acc) of true -> Acc; false -> Acc ++ [X] end end,
                [], L).
