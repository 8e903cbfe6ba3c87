%% Where the closed loop's time goes (TOROCO_BENCH_ONLY=profile): the
%% internal chain (source → router → relay → router → sink) run closed loop,
%% with per process reductions and messages per event, the same figures for
%% the raw chain, and an eprof breakdown by function over the runtime's
%% processes. A measuring tool: nothing here is a target.
-module(toroco_bench_profile).
-export([main/1]).

main([_Dir]) ->
    ok = io:setopts([{encoding, unicode}]),
    logger:set_primary_config(level, error),
    N = 20000,
    toroco_bench:chain(closed, 2000),
    _ = toroco_bench:run(closed, 2000, 20000),
    io:format("~n### Closed loop, per event (~b events)~n~n", [N]),
    io:format("| chain | µs per event (wall) | reductions per event (VM) | "
              "per process: reductions per event |~n|---|---:|---:|---|~n"),
    [raw(N) || _ <- [1, 2]],
    [runtime(N) || _ <- [1, 2]],
    M = 1000,
    toroco_bench:chain(closed, M),
    Msgs = messages(procs(), fun() -> toroco_bench:run(closed, M, 60000) end, M),
    io:format("~nMessages received per event: ~s (total ~.1f)~n",
              [lists:join(", ", [io_lib:format("~s ~.1f", [K, float(C)]) || {K, C} <- Msgs]),
               float(lists:sum([C || {_, C} <- Msgs]))]),
    eprof(N),
    halt(0).

pid(Name) -> whereis(toroco_names:process(Name)).

runtime(N) ->
    toroco_bench:chain(closed, N),
    loop("runtime", procs(), fun() -> toroco_bench:run(closed, N, N * 20 + 10000) end, N).

procs() ->
    [{src, pid(src)}, {router_relay, whereis(toroco_names:router(relay, in))},
     {relay, pid(relay)}, {router_sink, whereis(toroco_names:router(sink, in))},
     {sink, pid(sink)}].

raw(N) ->
    Chain = {Src, [Src, Last, _Sink]} = toroco_bench_raw:chain(closed, N, self()),
    Procs = [{forwarder, Last}],
    loop("raw", Procs, fun() ->
                               Src ! {run, closed, N},
                               receive {sink_done, _, _, _} -> ok end
                       end, N),
    toroco_bench_raw:stop(Chain).

loop(Label, Procs, Run, N) ->
    R0 = [{K, counts(P)} || {K, P} <- Procs],
    {Red0, _} = erlang:statistics(reductions),
    W0 = erlang:monotonic_time(nanosecond),
    Run(),
    W1 = erlang:monotonic_time(nanosecond),
    {Red1, _} = erlang:statistics(reductions),
    R1 = [{K, counts(P)} || {K, P} <- Procs],
    Per = [{K, (Rd1 - Rd0) / N} || {{K, Rd0}, {K, Rd1}} <- lists:zip(R0, R1)],
    io:format("| ~s | ~.2f | ~.1f | ~s |~n",
              [Label, (W1 - W0) / 1000 / N, (Red1 - Red0) / N,
               lists:join(", ", [io_lib:format("~s ~.1f", [K, float(R)]) || {K, R} <- Per])]).

counts(P) ->
    {reductions, R} = erlang:process_info(P, reductions),
    R.

%% Messages each process receives per event, counted by tracing `receive'
%% over a short run (tracing slows the run: no times from it).
messages(Procs, Run, N) ->
    Self = self(),
    Tracer = spawn(fun() -> count_loop(Self, #{}) end),
    [erlang:trace(P, true, ['receive', {tracer, Tracer}]) || {_, P} <- Procs],
    Run(),
    [erlang:trace(P, false, ['receive']) || {_, P} <- Procs],
    Tracer ! {done, Self},
    Counts = receive {counts, C} -> C end,
    Names = maps:from_list([{P, K} || {K, P} <- Procs]),
    [{maps:get(P, Names), K / N} || {P, K} <- maps:to_list(Counts)].

count_loop(Parent, Acc) ->
    receive
        {trace, P, 'receive', _} -> count_loop(Parent, Acc#{P => maps:get(P, Acc, 0) + 1});
        {done, Parent} -> Parent ! {counts, Acc}
    end.

eprof(N) ->
    toroco_bench:chain(closed, N),
    Procs = [pid(src), whereis(toroco_names:router(relay, in)), pid(relay),
             whereis(toroco_names:router(sink, in)), pid(sink)],
    {ok, _} = eprof:start(),
    profiling = eprof:start_profiling(Procs),
    _ = toroco_bench:run(closed, N, N * 20 + 10000),
    profiling_stopped = eprof:stop_profiling(),
    io:format("~n### eprof, the five processes of the closed loop~n~n```~n"),
    eprof:analyze(total, [{sort, time}]),
    io:format("```~n"),
    stopped = eprof:stop().
