%% Raw references for the benchmark: what plain Erlang processes and a plain
%% gen_udp echo do on the same machine, in the same run, so the runtime's
%% figures can be read as multiples of the machine's own.
%%
%% chain/3 starts as many plain processes as the internal test's path has
%% (source → router → relay → router → sink: five), each forwarding what it
%% gets to the next, and drives them exactly as toroco_bench drives the
%% runtime: closed loop (the sink tells the source each arrival), paced
%% every N ms on absolute deadlines, or open loop with a window of events in
%% flight (the sink acks every 100). The sink reports to the controller as
%% toroco_bench_sink does: {sink_done, Pid, EndNs, Latencies}.
%%
%% udp_echo/0 is a process that sends back every datagram it gets on a
%% port of its own, to the port udp_bench listens on.
-module(toroco_bench_raw).
-export([chain/3, stop/1, udp_echo/1]).

%% Starts the chain; returns the source, which takes {run, Mode, N}.
chain(Mode, N, Controller) ->
    Sink = spawn(fun() -> sink(Mode, N, Controller) end),
    Last = lists:foldl(fun(_, Next) -> spawn(fun() -> forward(Next) end) end, Sink, [1, 2, 3]),
    Src = spawn(fun() -> source(Last) end),
    Sink ! {source, Src},
    {Src, [Src, Last, Sink]}.

stop({_Src, Pids}) ->
    _ = [exit(P, kill) || P <- Pids],
    ok.

forward(Next) ->
    receive
        {ev, _} = Ev -> Next ! Ev, forward(Next);
        stop -> ok
    end.

now_ns() -> erlang:monotonic_time(nanosecond).

source(First) ->
    receive
        {run, closed, N} -> closed(First, N, 1);
        {run, {paced, Ms}, N} ->
            T0 = erlang:monotonic_time(millisecond),
            First ! {ev, {now_ns(), 1}},
            paced(First, Ms, N, T0, 1);
        {run, {window, W}, N} -> window(First, W, N, 0, 0)
    end.

closed(First, N, Seq) ->
    First ! {ev, {now_ns(), Seq}},
    receive
        {arrived, Seq} when Seq < N -> closed(First, N, Seq + 1);
        {arrived, _} -> ok
    end.

paced(_First, _Ms, N, _T0, N) ->
    ok;
paced(First, Ms, N, T0, Sent) ->
    erlang:start_timer(T0 + Sent * Ms, self(), next, [{abs, true}]),
    receive {timeout, _, next} -> ok end,
    First ! {ev, {now_ns(), Sent + 1}},
    paced(First, Ms, N, T0, Sent + 1).

window(First, W, N, Sent, Acked) ->
    Upto = min(N, Acked + W),
    _ = [First ! {ev, {0, Seq}} || Seq <- lists:seq(Sent + 1, Upto)],
    case Upto >= N of
        true -> ok;
        false -> receive {acked, A} -> window(First, W, N, max(Sent, Upto), A) end
    end.

sink(Mode, Expect, Controller) ->
    receive {source, Src} -> sink(Mode, Expect, Controller, Src, 0, []) end.

sink(Mode, Expect, Controller, Src, N, Lat) ->
    receive
        {ev, Ev} ->
            case toroco_bench_sink:arrived(Ev, Mode, Expect, Src, Controller, N, Lat) of
                done -> ok;
                {N1, Lat1} -> sink(Mode, Expect, Controller, Src, N1, Lat1)
            end
    end.

%% A plain gen_udp echo on `InPort' back to 127.0.0.1:`OutPort'.
udp_echo({InPort, OutPort}) ->
    Parent = self(),
    Pid = spawn(fun() ->
                        {ok, S} = gen_udp:open(InPort, [binary, {active, true}, {ip, {127, 0, 0, 1}}]),
                        Parent ! {self(), open},
                        echo(S, OutPort)
                end),
    receive {Pid, open} -> Pid end.

echo(S, OutPort) ->
    receive
        {udp, S, _Ip, _Port, Data} ->
            ok = gen_udp:send(S, {127, 0, 0, 1}, OutPort, Data),
            echo(S, OutPort);
        stop ->
            gen_udp:close(S)
    end.
