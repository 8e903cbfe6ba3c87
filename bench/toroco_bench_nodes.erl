%% The cross-node benchmark (SPEC §13), next to its reference measured in
%% the same run on the same two nodes:
%% - closed loop: a source on this node (A) -> router and relay behavior on
%%   node B -> router and sink back on A, one event in flight, against a raw
%%   Erlang distribution ping-pong between a plain process on A and one on B;
%% - events per second through one remote wire (fake sensor on A, sink on B);
%% - the keep-alive traffic per idle remote latch (bytes/s on the A -> B
%%   connection with 100 idle latched remote sources, less the same without).
%% B is a peer started on loopback. Results: a table on stdout and
%% nodes.md in the results directory.
-module(toroco_bench_nodes).
-export([main/1]).

-define(LOOPS, 3000).
-define(WIRE_EVENTS, 20000).
-define(LATCHES, 100).

main([Dir]) ->
    _ = os:cmd("epmd -daemon"),
    {ok, _} = net_kernel:start([list_to_atom("bench_a" ++ os:getpid() ++ "@127.0.0.1"), longnames]),
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    {ok, Peer, B} = peer:start_link(#{name => list_to_atom("bench_b" ++ os:getpid()),
                                      host => "127.0.0.1", longnames => true,
                                      args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                               "+K", "true", "-pa" | Paths]}),
    {ok, _} = application:ensure_all_started(toroco_hw),
    {ok, _} = erpc:call(B, application, ensure_all_started, [toroco_hw]),
    Raw = raw_ping_pong(B, ?LOOPS),
    Local = closed_loop(node(), ?LOOPS, "local_"),
    Loop = closed_loop(B, ?LOOPS, "loop_"),
    Rate = wire_rate(B, ?WIRE_EVENTS),
    {Bytes, Msgs} = keepalive(B, ?LATCHES),
    Rows = [{"raw distribution ping-pong (A -> B -> A)", Raw},
            {"toroco closed loop, all on A (same processes, no distribution)", Local},
            {"toroco closed loop (A -> router, relay on B -> router, sink on A)", Loop}],
    Lines = ["| test | p50 µs | p99 µs | avg µs | × raw p50 |",
             "|---|---|---|---|---|"
             | [io_lib:format("| ~ts | ~.1f | ~.1f | ~.1f | ~.2f |",
                              [L, P50, P99, Avg, P50 / maps:get(p50, Raw)])
                || {L, #{p50 := P50, p99 := P99, avg := Avg}} <- Rows]]
        ++ ["",
            io_lib:format("events/s through one remote wire (A -> B): ~b", [Rate]),
            io_lib:format("keep-alive per idle remote latch: ~.1f bytes/s (~.1f messages/s, "
                          "remote_keepalive_ms ~b)",
                          [Bytes, Msgs, application:get_env(toroco, remote_keepalive_ms, 100)])],
    Text = ["## Several nodes (", atom_to_list(node()), " and ", atom_to_list(B), ")\n\n",
            lists:join("\n", Lines), "\n"],
    ok = io:setopts([{encoding, unicode}]),
    io:format("~n~ts", [Text]),
    ok = file:write_file(filename:join(Dir, "nodes.md"), unicode:characters_to_binary(Text)),
    peer:stop(Peer),
    halt(0).

%% A plain process on B that answers each ping.
raw_ping_pong(B, N) ->
    Echo = erpc:call(B, erlang, spawn, [fun Loop() -> receive {P, M} -> P ! M, Loop() end end]),
    [begin Echo ! {self(), warm}, receive warm -> ok end end || _ <- lists:seq(1, 100)],
    Lat = [begin
               T0 = erlang:monotonic_time(nanosecond),
               Echo ! {self(), I},
               receive I -> erlang:monotonic_time(nanosecond) - T0 end
           end || I <- lists:seq(1, N)],
    exit(Echo, kill),
    stats(Lat).

closed_loop(B, N, Prefix) ->
    [SrcN, SinkN, RelayN] = [list_to_atom(Prefix ++ X) || X <- ["src", "sink", "relay"]],
    ok = toroco:add_behavior(SrcN, toroco_bench_source, #{}),
    Src = whereis(toroco_names:process(SrcN)),
    ok = toroco:add_device(SinkN, toroco_bench_sink,
                           #{expect => N, mode => closed, source => Src, controller => self()}),
    ok = toroco:add_behavior(RelayN, toroco_bench_relay, #{node => B}),
    ok = toroco:set_inputs(RelayN, #{in => [{SrcN, out}]}),
    ok = toroco:set_inputs(SinkN, #{in => [{RelayN, out}]}),
    Src ! {run, closed, N},
    receive {sink_done, _, _, Lat} -> stats(lists:nthtail(100, Lat))
    after 60000 -> error(closed_loop_timeout)
    end.

%% At most ?WIRE_WINDOW events in flight, the sink on B acking every 100:
%% a congested connection swallows what is sent to it (toroco_wire:send/2,
%% as a cut wire would), so a burst of N could lose events and never end.
-define(WIRE_WINDOW, 1000).

wire_rate(B, N) ->
    ok = toroco:add_device(wire_src, toroco_fake_sensor, #{outputs => [out]}),
    ok = toroco:add_device(wire_sink, toroco_bench_sink,
                           #{expect => N, mode => {window, 100}, source => self(),
                             controller => self(), node => B}),
    ok = toroco:set_inputs(wire_sink, #{in => [{wire_src, out}]}),
    T0 = erlang:monotonic_time(microsecond),
    ok = wire_inject(1, N, 0),
    receive {sink_done, _, _, _} -> ok after 60000 -> error(wire_timeout) end,
    round(N / ((erlang:monotonic_time(microsecond) - T0) / 1.0e6)).

wire_inject(I, N, _Acked) when I > N ->
    ok;
wire_inject(I, N, Acked) when I - 1 - Acked < ?WIRE_WINDOW ->
    ok = toroco:inject({wire_src, out}, {0, I}),
    wire_inject(I + 1, N, Acked);
wire_inject(I, N, Acked) ->
    receive {acked, A} -> wire_inject(I, N, max(A, Acked))
    after 10000 -> error({wire_stalled, {sent, I - 1}, {acked, Acked}})
    end.

%% Bytes and messages per second per idle latched source with a consumer on
%% B, from the A -> B connection's counters.
keepalive(B, K) ->
    Base = sent_per_s(B, 2000),
    Ins = [list_to_atom("in" ++ integer_to_list(I)) || I <- lists:seq(1, K)],
    ok = toroco:add_device(idle_act, toroco_fake_actuator, #{inputs => Ins, node => B}),
    _ = [begin
             S = list_to_atom("idle" ++ integer_to_list(I)),
             ok = toroco:add_device(S, toroco_fake_sensor, #{outputs => [out]}),
             ok = toroco:inject({S, out}, I, #{latch => true}),
             ok = toroco:set_inputs(idle_act, #{In => [{S, out}]})
         end || {I, In} <- lists:zip(lists:seq(1, K), Ins)],
    timer:sleep(500),
    {Bytes, Msgs} = sent_per_s(B, 2000),
    {BaseBytes, BaseMsgs} = Base,
    {(Bytes - BaseBytes) / K, (Msgs - BaseMsgs) / K}.

sent_per_s(B, Ms) ->
    {ok, [{send_oct, O0}, {send_cnt, C0}]} = dist_stat(B),
    timer:sleep(Ms),
    {ok, [{send_oct, O1}, {send_cnt, C1}]} = dist_stat(B),
    {(O1 - O0) * 1000 / Ms, (C1 - C0) * 1000 / Ms}.

dist_stat(B) ->
    {B, Port} = lists:keyfind(B, 1, erlang:system_info(dist_ctrl)),
    inet:getstat(Port, [send_oct, send_cnt]).

stats(Ns) ->
    S = lists:sort(Ns),
    Us = fun(X) -> X / 1000 end,
    #{p50 => Us(pct(S, 0.50)), p99 => Us(pct(S, 0.99)), avg => Us(lists:sum(S) / length(S))}.

pct(Sorted, P) ->
    lists:nth(max(1, round(P * length(Sorted))), Sorted).
