%% What a bridge client costs the event path: the closed loop of
%% toroco_bench (source → relay → sink) with no client, with a Foxglove
%% client and with a rosbridge client, each subscribed to the relay's output
%% (`/toroco/out/relay/out', one message per event of the loop: far more
%% than 1 kHz) and reading every frame, taken in turn in the same run.
%% TOROCO_BENCH_QUICK=1 runs shorter tests; TOROCO_BENCH_ONLY=rosbridge
%% runs this section alone.
-module(toroco_ros_bench).
-export([main/1]).

-define(TOPIC, <<"/toroco/out/relay/out">>).

main([Dir]) ->
    Quick = toroco_bench:setup(Dir),
    {ok, _} = application:ensure_all_started(toroco_hw),
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_ros),
    {ok, #{foxglove := Fox, rosbridge := Ros}} =
        toroco_live:start(#{http => 0, foxglove => 0, rosbridge => 0}),
    N = case Quick of true -> 20000; false -> 100000 end,
    Rounds = case Quick of true -> 2; false -> 3 end,
    io:format("~n## A bridge client and the event path (Foxglove, rosbridge)~n~nOTP ~s, ~w "
              "schedulers; figures are only comparable within one run~n",
              [erlang:system_info(otp_release), erlang:system_info(schedulers_online)]),
    Rows = lists:append([[closed_loop(none, N), closed_loop({foxglove, Fox}, N),
                          closed_loop({rosbridge, Ros}, N)]
                         || _ <- lists:seq(1, Rounds)]),
    table(Rows, N, Dir),
    halt(0).

closed_loop(With, N) ->
    ok = toroco:add_behavior(src, toroco_bench_source, #{layer => 1}),
    ok = toroco:add_behavior(relay, toroco_bench_relay, #{layer => 0}),
    Src = whereis(toroco_names:process(src)),
    ok = toroco:add_device(sink, toroco_bench_sink,
                           #{expect => N, mode => closed, source => Src, controller => self()}),
    ok = toroco:set_inputs(relay, #{in => [{src, out}]}),
    ok = toroco:set_inputs(sink, #{in => [{relay, out}]}),
    Client = client(With),
    W0 = erlang:monotonic_time(nanosecond),
    Src ! {run, closed, N},
    Lats = receive {sink_done, _, _End, L} -> lists:sort(L) after N * 20 + 10000 -> [] end,
    Ns = erlang:monotonic_time(nanosecond) - W0,
    Frames = frames(Client),
    _ = [toroco:remove_behavior(B) || B <- [src, relay]],
    ok = toroco:remove_device(sink),
    #{with => With, lats => Lats, ns => Ns, frames => Frames}.

table(Rows, N, Dir) ->
    Us = fun(X) -> X / 1000 end,
    Name = fun(none) -> "no client"; ({foxglove, _}) -> "one Foxglove client";
              ({rosbridge, _}) -> "one rosbridge client" end,
    Line = fun(#{with := W, lats := L, ns := Ns, frames := F}) ->
                   io_lib:format("| ~s | ~.1f | ~.1f | ~.1f | ~w | ~w |~n",
                                 [Name(W), Us(pct(L, 0.5)), Us(pct(L, 0.99)),
                                  Us(lists:sum(L) / max(1, length(L))),
                                  round(length(L) / (Ns / 1.0e9)), F])
           end,
    Kind = fun(none) -> none; ({K, _}) -> K end,
    Avg = fun(K, F) -> Xs = [F(R) || R = #{with := W} <- Rows, Kind(W) =:= K],
                       lists:sum(Xs) / max(1, length(Xs)) end,
    P50 = fun(#{lats := L}) -> pct(L, 0.5) end,
    Rate = fun(#{lats := L, ns := Ns}) -> length(L) / (Ns / 1.0e9) end,
    Text = [io_lib:format("~n### Closed loop (~w events a run), the client subscribed to ~s~n~n",
                          [N, ?TOPIC]),
            "| client | p50 µs | p99 µs | avg µs | events/s | messages the client got |\n",
            "|---|---:|---:|---:|---:|---:|\n", [Line(R) || R <- Rows],
            io_lib:format("~nAgainst no client: p50 latency ×~.2f with Foxglove, ×~.2f with "
                          "rosbridge; throughput ×~.2f with Foxglove, ×~.2f with rosbridge~n",
                          [Avg(foxglove, P50) / max(1, Avg(none, P50)),
                           Avg(rosbridge, P50) / max(1, Avg(none, P50)),
                           Avg(foxglove, Rate) / max(1.0, Avg(none, Rate)),
                           Avg(rosbridge, Rate) / max(1.0, Avg(none, Rate))])],
    io:put_chars(Text),
    ok = file:write_file(filename:join(Dir, "live_bridges.md"), unicode:characters_to_binary(Text)).

pct([], _) -> 0;
pct(Sorted, P) -> lists:nth(max(1, round(P * length(Sorted))), Sorted).

%%====================================================================
%% A WebSocket client that subscribes and counts what it reads
%%====================================================================

client(none) -> none;
client({Kind, Port}) ->
    Owner = self(),
    Pid = spawn_link(fun() -> reader(Kind, Port, Owner) end),
    receive {subscribed, Pid} -> Pid after 10000 -> error({no_subscription, Kind}) end.

frames(none) -> 0;
frames(Pid) ->
    Pid ! {count, self()},
    receive {count, Pid, N} -> unlink(Pid), exit(Pid, kill), N after 5000 -> -1 end.

reader(Kind, Port, Owner) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}]),
    Proto = case Kind of foxglove -> ["Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n"]; rosbridge -> [] end,
    ok = gen_tcp:send(S, ["GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n",
                          "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n",
                          "Sec-WebSocket-Key: ", base64:encode(crypto:strong_rand_bytes(16)), "\r\n",
                          Proto, "\r\n"]),
    Rest = headers(S, <<>>),
    case Kind of
        rosbridge ->
            send(S, jiffy:encode(#{op => subscribe, topic => ?TOPIC})),
            timer:sleep(300),
            Owner ! {subscribed, self()},
            read(S, Rest, 0);
        foxglove ->
            {Id, Rest1} = channel(S, Rest),
            send(S, jiffy:encode(#{op => subscribe, subscriptions => [#{id => 1, channelId => Id}]})),
            timer:sleep(300),
            Owner ! {subscribed, self()},
            read(S, Rest1, 0)
    end.

headers(S, Acc) ->
    case binary:split(Acc, <<"\r\n\r\n">>) of
        [<<"HTTP/1.1 101", _/binary>>, Rest] -> Rest;
        [_] -> {ok, More} = gen_tcp:recv(S, 0, 5000), headers(S, <<Acc/binary, More/binary>>)
    end.

%% Until the advertise that has the topic: its channel id.
channel(S, Buf) ->
    case frame(Buf) of
        {ok, 1, Text, Rest} ->
            case jiffy:decode(Text, [return_maps]) of
                #{<<"op">> := <<"advertise">>, <<"channels">> := Chs} ->
                    case [Id || #{<<"topic">> := T, <<"id">> := Id} <- Chs, T =:= ?TOPIC] of
                        [Id | _] -> {Id, Rest};
                        [] -> channel(S, Rest)
                    end;
                _ -> channel(S, Rest)
            end;
        {ok, _, _, Rest} -> channel(S, Rest);
        more -> {ok, More} = gen_tcp:recv(S, 0, 10000), channel(S, <<Buf/binary, More/binary>>)
    end.

read(S, Buf, N) ->
    receive {count, From} -> From ! {count, self(), N}
    after 0 ->
            case frame(Buf) of
                {ok, _, _, Rest} -> read(S, Rest, N + 1);
                more ->
                    case gen_tcp:recv(S, 0, 50) of
                        {ok, More} -> read(S, <<Buf/binary, More/binary>>, N);
                        {error, timeout} -> read(S, Buf, N)
                    end
            end
    end.

%% A server frame (unmasked): {ok, Opcode, Payload, Rest} | more.
frame(<<_:4, Op:4, 0:1, 126:7, Len:16, P:Len/binary, Rest/binary>>) -> {ok, Op, P, Rest};
frame(<<_:4, Op:4, 0:1, 127:7, Len:64, P:Len/binary, Rest/binary>>) -> {ok, Op, P, Rest};
frame(<<_:4, Op:4, 0:1, Len:7, P:Len/binary, Rest/binary>>) when Len < 126 -> {ok, Op, P, Rest};
frame(_) -> more.

send(S, Text) ->
    Key = crypto:strong_rand_bytes(4),
    Len = byte_size(Text),
    Head = if Len < 126 -> <<1:1, 0:3, 1:4, 1:1, Len:7>>;
              true -> <<1:1, 0:3, 1:4, 1:1, 126:7, Len:16>>
           end,
    ok = gen_tcp:send(S, [Head, Key, mask(Text, Key)]).

mask(Bin, <<K:32>> = Key) ->
    Whole = byte_size(Bin) div 4 * 4,
    <<Body:Whole/binary, Tail/binary>> = Bin,
    Masked = << <<(W bxor K):32>> || <<W:32>> <= Body >>,
    <<Masked/binary, (mask_tail(Tail, Key))/binary>>.

mask_tail(Tail, Key) ->
    list_to_binary([B bxor binary:at(Key, I) || {I, B} <- lists:zip(lists:seq(0, byte_size(Tail) - 1),
                                                                    binary_to_list(Tail))]).
