%% Where the closed loop's time goes (TOROCO_BENCH_ONLY=profile): the
%% internal chain (source → router → relay → router → sink) run closed loop,
%% with per process reductions and messages per event (also with one tap
%% subscriber, its feeder and reader counted), the same figures for the raw
%% chain, each step of the path alone (with no observer and with a
%% subscriber) and, with TOROCO_BENCH_EPROF=1, each step's eprof breakdown
%% by function. A measuring tool: nothing here is a target.
-module(toroco_bench_profile).
-export([main/1]).

main([Dir]) ->
    _ = toroco_bench:setup(Dir),
    N = 20000,
    toroco_bench:warm_up(),
    io:format("~n### Closed loop, per event (~b events)~n~n", [N]),
    io:format("| chain | µs per event (wall) | reductions per event (VM) | "
              "per process: reductions per event |~n|---|---:|---:|---|~n"),
    [reference("raw", toroco_bench_raw, N) || _ <- [1, 2]],
    [reference("gen_statem", toroco_bench_statem, N) || _ <- [1, 2]],
    [runtime(N) || _ <- [1, 2]],
    [observed(N, Label, Opts) || {Label, Opts} <- [{"runtime, one subscriber", #{}},
                                                   {"runtime, one subscriber with room for 1",
                                                    #{buffer => 1}}]],
    flight(N),
    M = 1000,
    toroco_bench:chain(closed, M),
    Msgs = messages(procs(), fun() -> toroco_bench:run(closed, M, 60000) end, M),
    io:format("~nMessages received per event: ~s (total ~.1f)~n",
              [lists:join(", ", [io_lib:format("~s ~.1f", [K, float(C)]) || {K, C} <- Msgs]),
               float(lists:sum([C || {_, C} <- Msgs]))]),
    isolation(none),
    isolation(subscriber),
    halt(0).

%% The closed loop with a reader subscribed (Opts): the chain's processes
%% and the subscription's feeder and reader, what each does per event.
observed(N, Label, Opts) ->
    toroco_bench:chain(closed, N),
    {Reader, Ref} = reader(Opts),
    closed_loop(Label, [{feeder, toroco_tap:feeder(Ref)}, {reader, Reader}], N),
    Reader ! stop.

%% The closed loop with the flight recorder on (toroco_live's recorders,
%% no dashboard): the chain's processes, the recorder and its feeder.
flight(N) ->
    toroco_bench:chain(closed, N),
    toroco_bench_observers:live(),
    closed_loop("runtime, flight recorder",
                [{feeder, only_feeder(100)}, {flight, whereis(toroco_rec_flight)}], N),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    ok.

%% The feeder of the one subscription, once it is made (looked for every
%% 20 ms, `Tries' times).
only_feeder(0) ->
    error(no_subscription);
only_feeder(Tries) ->
    case toroco_tap:current() of
        [Sub] -> toroco_tap:feeder(element(1, Sub));
        [] -> timer:sleep(20), only_feeder(Tries - 1)
    end.

reader(Opts) ->
    Parent = self(),
    Reader = spawn(fun() ->
                           {ok, Ref} = toroco:subscribe_events(Opts),
                           Parent ! {self(), Ref},
                           read(Ref)
                   end),
    receive {Reader, Ref} -> {Reader, Ref} end.

read(Ref) ->
    receive
        {toroco_event, Ref, _} -> read(Ref);
        stop -> ok
    end.

%% Each step of the closed loop alone, in a tight loop in one process (no
%% message received, no scheduling; what a step sends piles up in suspended
%% processes): the source emitting, a router taking one event (shell, core,
%% its delivery), the relay taking one input and emitting, the sink taking
%% one input; then the gen_statem loop around each (a gen_statem draining a
%% full mailbox against a plain receive loop doing the same). What is left
%% of the closed loop is messaging and scheduling (the raw chain's figure).
isolation(Observer) ->
    M = 200000,
    toroco_bench:chain(closed, M + 1),
    Reader = case Observer of
                 none -> none;
                 subscriber -> element(1, reader(#{}))
             end,
    Src = pid(src), Relay = pid(relay), Sink = pid(sink),
    Router = whereis(toroco_names:router(relay, in)),
    RouterSink = whereis(toroco_names:router(sink, in)),
    All = [Src, Router, Relay, RouterSink, Sink],
    Got = [sys:get_state(P) || P <- All],
    [sys:suspend(P) || P <- All],
    %% what the steps send goes to processes that drop it, under the
    %% routers' names, as the receiver, as the source
    Drop = fun() -> spawn(fun Loop() -> receive _ -> Loop() end end) end,
    [begin unregister(Reg), register(Reg, Drop()) end
     || Reg <- [toroco_names:router(relay, in), toroco_names:router(sink, in)]],
    [{_, ESrc}, {ready, CRouter0}, {SRelay, ERelay}, _, {SSink, ESink0}] = Got,
    CRouter = setelement(4, CRouter0, setelement(5, element(4, CRouter0), Drop())),
    ESink = setelement(7, ESink0, (element(7, ESink0))#{source := Drop()}),
    io:format("~n### Each step alone, ~s (ns per call, ~b calls, one process)~n~n"
              "| step | ns |~n|---|---:|~n",
              [case Observer of
                   none -> "no observer";
                   subscriber -> "one tap subscriber taking every event"
               end, M]),
    Steps =
        [step("source: `{arrived, N}' in, the next emission out (engine + callback)",
              fun(K, E) -> data(toroco_behavior:handle_event(info, {arrived, K}, {closed, M + 1, 1, 0}, E), E) end,
              ESrc, M),
         step("router: one event in, one delivery out (shell + core)",
              fun(K, C) -> data(toroco_consumer:handle_event(info, {'$toroco', {src, out}, {send, {0, K}, default}},
                                                            ready, C), C) end,
              CRouter, M),
         step("relay: one input in, one emission out (engine + callback)",
              fun(K, E) -> data(toroco_behavior:handle_event(info, {'$toroco_in', in, {0, K}}, SRelay, E), E) end,
              ERelay, M),
         step("sink: one input in, `{arrived, N}' out (engine + callback)",
              fun(K, E) -> data(toroco_behavior:handle_event(info, {'$toroco_in', in, {0, K}}, SSink, E), E) end,
              ESink, M)],
    Loop = gen_statem_loop(M) - plain_loop(M),
    io:format("| gen_statem's loop around one event, per process (× 5 processes on the path) | ~.1f |~n",
              [float(Loop)]),
    io:format("| sum: the steps with the router twice, plus 5 gen_statem loops | ~.1f |~n",
              [float(lists:sum(Steps) + lists:nth(2, Steps) + 5 * Loop)]),
    %% the chain as it was: the routers under their names again, running
    [begin Stand = whereis(Reg), unregister(Reg), exit(Stand, kill), register(Reg, P) end
     || {Reg, P} <- [{toroco_names:router(relay, in), Router},
                     {toroco_names:router(sink, in), RouterSink}]],
    [sys:resume(P) || P <- All],
    _ = is_pid(Reader) andalso (Reader ! stop),
    ok.

data({keep_state, D}, _) -> D;
data({keep_state, D, _}, _) -> D;
data({next_state, _, D}, _) -> D;
data({next_state, _, D, _}, _) -> D;
data(keep_state_and_data, D) -> D;
data({keep_state_and_data, _}, D) -> D.

step(Label, F, Acc0, M) ->
    garbage_collect(),
    T0 = erlang:monotonic_time(nanosecond),
    _ = lists:foldl(F, Acc0, lists:seq(1, M)),
    Ns = (erlang:monotonic_time(nanosecond) - T0) / M,
    io:format("| ~ts | ~.1f |~n", [Label, float(Ns)]),
    [eprof_step(Label, F, Acc0) || os:getenv("TOROCO_BENCH_EPROF") =:= "1"],
    Ns.

%% With TOROCO_BENCH_EPROF=1: the step again, 20000 calls under eprof
%% (one process: what the step calls, by function).
eprof_step(Label, F, Acc0) ->
    {ok, _} = eprof:start(),
    {ok, _} = eprof:profile([], fun() -> lists:foldl(F, Acc0, lists:seq(1, 20000)) end),
    io:format("~n```~n~ts~n", [Label]),
    eprof:analyze(total, [{sort, time}]),
    io:format("```~n~n| step | ns |~n|---|---:|~n"),
    stopped = eprof:stop().

%% ns per message for a process draining M messages already in its mailbox
gen_statem_loop(M) ->
    drain(fun(Parent) -> {ok, P} = gen_statem:start(toroco_bench_drain, {Parent, M}, []), P end, M).

plain_loop(M) ->
    drain(fun(Parent) -> spawn(fun() -> plain_drain(Parent, M) end) end, M).

plain_drain(Parent, 0) -> Parent ! {drained, self()};
plain_drain(Parent, K) -> receive _ -> plain_drain(Parent, K - 1) end.

drain(Start, M) ->
    P = Start(self()),
    true = erlang:suspend_process(P),
    [P ! {'$toroco_in', in, K} || K <- lists:seq(1, M)],
    T0 = erlang:monotonic_time(nanosecond),
    true = erlang:resume_process(P),
    receive {drained, P} -> ok end,
    (erlang:monotonic_time(nanosecond) - T0) / M.

pid(Name) -> whereis(toroco_names:process(Name)).

runtime(N) ->
    toroco_bench:chain(closed, N),
    closed_loop("runtime", [], N).

%% The chain made, N events closed loop: what its processes and `Extra'
%% (an observer's) do per event. Each process has handled what was sent
%% to it before (a subscription) when the run starts.
closed_loop(Label, Extra, N) ->
    [sys:get_state(P) || {_, P} <- procs()],
    loop(Label, procs() ++ Extra, fun() -> toroco_bench:run(closed, N, N * 20 + 10000) end, N).

procs() ->
    [{src, pid(src)}, {router_relay, whereis(toroco_names:router(relay, in))},
     {relay, pid(relay)}, {router_sink, whereis(toroco_names:router(sink, in))},
     {sink, pid(sink)}].

%% A reference chain (toroco_bench_raw's or toroco_bench_statem's), N
%% events closed loop: what one of its forwarders does per event.
reference(Label, Mod, N) ->
    Chain = {Src, [Src, Fwd | _]} = Mod:chain(closed, N, self()),
    loop(Label, [{forwarder, Fwd}], fun() ->
                                            Src ! {run, closed, N},
                                            receive {sink_done, _, _, _} -> ok end
                                    end, N),
    Mod:stop(Chain).

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

