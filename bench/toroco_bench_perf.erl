%% Where the closed loop's CPU goes, seen from outside the VM
%% (TOROCO_BENCH_ONLY=perf): Linux `perf' samples the whole VM (its
%% schedulers, the JIT's code named through `+JPperf true', the emulator's
%% C functions, the kernel) while the internal chain runs closed loop, and
%% the same for the raw chain of five plain processes. Samples are grouped
%% by what they do and turned into µs of CPU per event with the run's own
%% CPU time, so the two chains can be read side by side: what the runtime
%% adds to messaging and scheduling, which eprof cannot see. A measuring
%% tool: nothing here is a target. Needs `perf' (Debian's linux-perf) and a
%% VM started with `+JPperf true' (scripts/bench does both).
-module(toroco_bench_perf).
-export([main/1, group/1]).

-define(SECONDS, 6).
-define(BATCH, 20000).

main([Dir]) ->
    _ = toroco_bench:setup(Dir),
    case os:find_executable("perf") of
        false ->
            io:format("~n(no `perf' here: install Debian's linux-perf for this section)~n"),
            halt(0);
        Perf ->
            toroco_bench:warm_up(),
            Raw = sample(Perf, Dir, "raw", fun raw_batch/0),
            Runtime = sample(Perf, Dir, "runtime", fun runtime_batch/0),
            table(Raw, Runtime),
            halt(0)
    end.

%% One batch of closed-loop events on each chain; returns how many ran.
runtime_batch() ->
    toroco_bench:chain(closed, ?BATCH),
    _ = toroco_bench:run(closed, ?BATCH, 60000),
    ?BATCH.

raw_batch() ->
    Chain = {Src, _} = toroco_bench_raw:chain(closed, ?BATCH, self()),
    _ = toroco_bench:measure(Src, closed, ?BATCH, 60000),
    toroco_bench_raw:stop(Chain),
    ?BATCH.

%% Runs batches while perf records this VM; returns µs of CPU per event
%% (the VM's user and system time over the events) and the samples' shares
%% by group.
sample(Perf, Dir, Label, Batch) ->
    Data = filename:join(Dir, "perf_" ++ Label ++ ".data"),
    Cmd = lists:flatten(io_lib:format("~s record -q -e cpu-clock -F 2999 -p ~s -o ~s -- sleep ~b 2>&1",
                                      [Perf, os:getpid(), Data, ?SECONDS])),
    Port = open_port({spawn, Cmd}, [exit_status, stderr_to_stdout]),
    Cpu0 = toroco_bench:cpu_ticks(),
    Events = batches(Port, Batch, 0),
    Cpu1 = toroco_bench:cpu_ticks(),
    UsPerEvent = (Cpu1 - Cpu0) / toroco_bench:ticks_per_sec() * 1.0e6 / max(1, Events),
    Report = os:cmd(Perf ++ " report -i " ++ Data ++
                        " --no-children --sort sym -g none --stdio 2>/dev/null"),
    {UsPerEvent, shares(Report)}.

batches(Port, Batch, N) ->
    receive
        {Port, {exit_status, _}} -> N;
        {Port, {data, _}} -> batches(Port, Batch, N)
    after 0 ->
            batches(Port, Batch, N + Batch())
    end.

%% Share of samples (per cent) by group, from `perf report --stdio'.
shares(Report) ->
    Lines = string:split(Report, "\n", all),
    Pairs = [{list_to_float(P), group(string:trim(Sym))}
             || L <- Lines,
                {match, [P, Sym]} <- [re:run(L, "^\\s+([0-9]+\\.[0-9]+)%\\s+\\[[^]]+\\]\\s+(.*)$",
                                             [{capture, all_but_first, list}])]],
    lists:foldl(fun({P, G}, Acc) -> maps:update_with(G, fun(X) -> X + P end, P, Acc) end,
                #{}, Pairs).

%% What a sampled symbol does. The JIT names Erlang functions `$Mod:F/A'.
-spec group(string()) -> string().
group("$toroco_bench" ++ _) -> "bench's own source and sink";
group("$gen_statem:" ++ _) -> "gen_statem's loop";
group("$toroco_" ++ Rest) -> "runtime: toroco_" ++ hd(string:split(Rest, ":"));
group("$global::" ++ _) -> "JIT shared helpers (BIF calls, receive, GC entry)";
group("$" ++ _) -> "other Erlang code";
group(Sym) ->
    Groups = [{"messages: send, copy, queue",
               ["copy_struct", "size_object", "send_message", "alloc_message", "message_ref",
                "proc_sig", "remove_message", "msg", "memmove", "memcpy", "loop_rec"]},
              {"registered names, read-write locks", ["whereis", "rwmutex"]},
              {"calls to a module in a variable (export lookup)",
               ["find_export_entry", "fixed_apply", "apply"]},
              {"clock reads", ["clock_gettime", "monotonic_time", "vdso", "get_time"]},
              {"scheduling and waking", ["schedule", "wait", "wake", "futex", "mutex", "pthread",
                                         "thr_", "task_switch", "spin", "poll", "check_balance"]},
              {"memory and GC", ["alloc", "garbage", "gc_", "sweep", "free"]},
              {"maps, tuples, comparisons", ["map", "setelement", "eq", "cmp", "tuple", "hash"]}],
    Match = [G || {G, Keys} <- Groups, lists:any(fun(K) -> string:find(Sym, K) =/= nomatch end, Keys)],
    case {Match, Sym} of
        {[G | _], _} -> G;
        {[], "0x" ++ _} -> "emulator, no symbol";
        {[], _} -> "emulator, other"
    end.

table({RawUs, RawShares}, {RtUs, RtShares}) ->
    Groups = lists:usort(maps:keys(RawShares) ++ maps:keys(RtShares)),
    Us = fun(Us0, Shares, G) -> Us0 * maps:get(G, Shares, 0.0) / 100 end,
    Rows = lists:reverse(lists:keysort(2, [{G, Us(RtUs, RtShares, G), Us(RawUs, RawShares, G)}
                                           || G <- Groups])),
    io:format("~n### Where the closed loop's CPU goes (perf, ~b s per chain)~n~n"
              "| group | runtime: µs CPU per event | share | raw chain: µs CPU per event | share |~n"
              "|---|---:|---:|---:|---:|~n", [?SECONDS]),
    [io:format("| ~ts | ~.2f | ~.1f % | ~.2f | ~.1f % |~n",
               [G, R, maps:get(G, RtShares, 0.0), W, maps:get(G, RawShares, 0.0)])
     || {G, R, W} <- Rows],
    io:format("| **all** | **~.2f** | | **~.2f** | |~n", [RtUs, RawUs]).
