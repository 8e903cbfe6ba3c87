%% The dashboard's and the bridge's ports against strangers
%% (`toroco_live_listener'): a flood of idle and half-open connections from
%% one address does not keep another address from the page, `/api/state'
%% or a Foxglove client; requests too slow and clients too idle are closed;
%% a full port sheds its longest-idle connection; every close is counted
%% in `/metrics'. The same again with TLS on the ports (group `tls'): the
%% served clients speak TLS, the flood's connections never finish a
%% handshake, and a handshake too slow is closed like a request too slow.
-module(toroco_live_listen_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

-define(FLOOD, 1000).
-define(OTHER, {127, 0, 0, 2}).

all() ->
    [flood_from_one_address, slow_request_and_idle_timeouts, full_port_sheds_longest_idle,
     silent_websocket_closed, {group, tls}].

groups() ->
    [{tls, [], [flood_from_one_address, slow_request_and_idle_timeouts,
                full_port_sheds_longest_idle, slow_tls_handshake_closed]}].

suite() -> [{timetrap, {seconds, 120}}].

init_per_suite(Config) ->
    {ok, _} = application:ensure_all_started(ssl),
    persistent_term:put({?MODULE, tls}, none),
    [{env, tl_live:start(#{})} | Config].

end_per_suite(Config) ->
    persistent_term:erase({?MODULE, tls}),
    tl_live:stop(?config(env, Config)).

%% The helpers below read whether the ports speak TLS (the group's
%% certificate, from a test CA) from here: they run in the flood's
%% processes too.
init_per_group(tls, Config) ->
    Tls = tl_tls:make(?config(priv_dir, Config)),
    persistent_term:put({?MODULE, tls}, Tls),
    [{tls, Tls} | Config].

end_per_group(tls, _Config) ->
    persistent_term:put({?MODULE, tls}, none).

%% toroco_live:start/1, with TLS in the group `tls'.
start(Opts) ->
    case persistent_term:get({?MODULE, tls}) of
        none -> toroco_live:start(Opts);
        Tls -> toroco_live:start(Opts#{tls => tl_tls:tls(Tls)})
    end.

end_per_testcase(_Case, _Config) ->
    application:unset_env(toroco_live, ws_ping_ms),
    toroco_live:stop().

%%====================================================================
%% Cases
%%====================================================================

silent_websocket_closed() ->
    [{doc, "A WebSocket client silent for ws_ping_ms gets a ping; one that never answers is "
      "closed (1001) after twice that, one that answers pongs stays"}].
silent_websocket_closed(_Config) ->
    Ping = 200,
    ok = application:set_env(toroco_live, ws_ping_ms, Ping),
    {ok, #{http := Http}} = toroco_live:start(#{http => 0, foxglove => off}),
    %% before the handshake: the server counts silence from its end of it,
    %% which a loaded machine may finish well before this process hears
    T0 = erlang:monotonic_time(millisecond),
    {ok, Silent, _} = toroco_live_test_client:raw_ws(Http, ""),
    {ok, Answering, _} = toroco_live_test_client:raw_ws(Http, ""),
    Answerer = spawn_link(fun() -> answer_pings(Answering, <<>>) end),
    ok = gen_tcp:controlling_process(Answering, Answerer),
    Ops = ws_ops(Silent, <<>>, []),
    {at, At} = lists:keyfind(at, 1, [O || O <- Ops, is_tuple(O)]),
    Closed = At - T0,
    ct:pal("silent client: frames ~w, closed after ~b ms (ping every ~b ms)", [Ops, Closed, Ping]),
    ?assert(lists:member(9, Ops)),
    ?assertMatch({8, 1001}, lists:keyfind(8, 1, [O || O <- Ops, is_tuple(O)])),
    %% in real time: between its bound and a generous margin for a loaded machine
    ?assert(Closed >= 2 * Ping andalso Closed < 20 * Ping),
    %% The answering client is still there after three pings: past the
    %% 2 x ping_ms at which a silent one is closed.
    Pongs = fun() -> Answerer ! {self(), pongs},
                     receive {pongs, N} -> N after 5000 -> ct:fail(answerer_gone) end
            end,
    toroco_test_lib:wait_until(fun() -> Pongs() >= 3 end, 20 * Ping, three_pongs),
    ?assert(is_process_alive(Answerer)),
    unlink(Answerer),
    exit(Answerer, kill),
    ok.

%% The opcodes of the frames a passive socket gets until it is closed
%% ({8, Code} for a close frame, after `{at, When}' it came).
ws_ops(S, Buf, Acc) ->
    case frame(Buf) of
        {8, <<Code:16, _/binary>>, Rest} ->
            ws_ops(S, Rest, [{8, Code}, {at, erlang:monotonic_time(millisecond)} | Acc]);
        {Op, _, Rest} -> ws_ops(S, Rest, [Op | Acc]);
        more ->
            case gen_tcp:recv(S, 0, 10000) of
                {ok, B} -> ws_ops(S, <<Buf/binary, B/binary>>, Acc);
                {error, _} -> lists:reverse(Acc)
            end
    end.

answer_pings(S, Buf) ->
    answer_pings(S, Buf, 0).

answer_pings(S, Buf, N) ->
    case frame(Buf) of
        {9, P, Rest} ->
            ok = gen_tcp:send(S, masked(10, P)),
            answer_pings(S, Rest, N + 1);
        {_, _, Rest} -> answer_pings(S, Rest, N);
        more ->
            case gen_tcp:recv(S, 0, 50) of
                {ok, B} -> answer_pings(S, <<Buf/binary, B/binary>>, N);
                {error, timeout} ->
                    receive {From, pongs} -> From ! {pongs, N}
                    after 0 -> ok
                    end,
                    answer_pings(S, Buf, N);
                {error, _} -> ok                 % the dashboard stopped
            end
    end.

frame(<<_:4, Op:4, 0:1, 126:7, Len:16, P:Len/binary, Rest/binary>>) -> {Op, P, Rest};
frame(<<_:4, Op:4, 0:1, 127:7, Len:64, P:Len/binary, Rest/binary>>) -> {Op, P, Rest};
frame(<<_:4, Op:4, 0:1, Len:7, P:Len/binary, Rest/binary>>) when Len < 126 -> {Op, P, Rest};
frame(_) -> more.

%% A client's frame: masked, short payloads only.
masked(Op, P) when byte_size(P) < 126 ->
    Key = crypto:strong_rand_bytes(4),
    <<1:1, 0:3, Op:4, 1:1, (byte_size(P)):7, Key/binary,
      (crypto:exor(P, binary:part(binary:copy(Key, byte_size(P) div 4 + 1), 0, byte_size(P))))/binary>>.

flood_from_one_address() ->
    [{doc, "With 1,000 idle or half-open connections held from 127.0.0.1 on each port, "
      "the page, /api/state and a Foxglove client from 127.0.0.2 are served within 2 s, "
      "the node's memory stays bounded and /metrics counts the refused"}].
flood_from_one_address(_Config) ->
    {ok, #{http := Http, foxglove := Fox}} = start(#{http => 0, foxglove => 0}),
    %% each flood socket is two descriptors in this VM (both ends), on
    %% each of the two ports: a lower `ulimit -n' gets a smaller flood
    Fds = fd_limit(),
    N = min(?FLOOD, (Fds - 1000) div 4),
    ct:pal("file descriptors: ~b allowed; ~b connections from 127.0.0.1 on each port", [Fds, N]),
    erlang:garbage_collect(),
    Before = erlang:memory(total),
    Flood = flood([Http, Fox], N),
    During = erlang:memory(total),
    {PageMs, {200, Page}} = timed(fun() -> http_get(Http, "/") end),
    {StateMs, {200, State}} = timed(fun() -> http_get(Http, "/api/state") end),
    {FoxMs, ServerInfo} = timed(fun() -> foxglove_hello(Fox) end),
    {200, Metrics} = http_get(Http, "/metrics"),
    After = erlang:memory(total),
    ct:pal("under the flood: page ~b ms (~b bytes), /api/state ~b ms, Foxglove serverInfo "
           "~b ms; memory ~.1f MB before, ~.1f MB with the flood, ~.1f MB after the requests",
           [PageMs, byte_size(Page), StateMs, FoxMs, mb(Before), mb(During), mb(After)]),
    ?assert(PageMs < 2000 andalso StateMs < 2000 andalso FoxMs < 2000),
    ?assertMatch(#{<<"inspect">> := #{<<"behaviors">> := _}}, jiffy:decode(State, [return_maps])),
    ?assertMatch(#{<<"op">> := <<"serverInfo">>}, ServerInfo),
    %% 2,000 sockets of the flood live in this same VM, their ports
    %% included: a generous bound, far below what 2,000 served
    %% connections (a process and buffers each) would cost
    ?assert(During - Before < 64 * 1024 * 1024),
    ?assert(After - Before < 64 * 1024 * 1024),
    Lines = metric_lines(Metrics),
    ct:pal("~s", [lists:join("\n", [L || L <- Lines, string:find(L, "connections") =/= nomatch])]),
    [#{connections := HttpConns, closed_by := HttpBy}, #{connections := FoxConns, closed_by := FoxBy}]
        = [toroco_live_listener:stats(L) || L <- [toroco_live_http, toroco_live_foxglove_listener]],
    ?assert(HttpConns =< 32 + 2 andalso FoxConns =< 32 + 1),
    %% every connection of the flood was given a slot or refused, the most refused
    [begin
         ?assert(Accepted + maps:get(too_many_from_peer, By) + maps:get(too_many_clients, By) >= N),
         ?assert(maps:get(too_many_from_peer, By) >= N div 2)
     end || #{accepted := Accepted, closed_by := By} <- [toroco_live_listener:stats(L)
                                                        || L <- [toroco_live_http,
                                                                 toroco_live_foxglove_listener]]],
    ?assertEqual(maps:get(too_many_from_peer, HttpBy),
                 metric_value(Lines, "dashboard", "too_many_from_peer")),
    ?assertEqual(maps:get(too_many_from_peer, FoxBy),
                 metric_value(Lines, "foxglove", "too_many_from_peer")),
    unflood(Flood),
    ok.

slow_request_and_idle_timeouts() ->
    [{doc, "Half a request is closed after request_timeout, a kept-alive client after "
      "idle_timeout, an unfinished WebSocket handshake too; each counted by reason"}].
slow_request_and_idle_timeouts(_Config) ->
    {ReqT, IdleT} = {300, 900},
    {ok, #{http := Http, foxglove := Fox}} =
        start(#{http => 0, foxglove => 0, request_timeout => ReqT, idle_timeout => IdleT}),
    T0 = erlang:monotonic_time(millisecond),
    Half = connect(Http, {127, 0, 0, 1}),
    ok = send(Half, <<"GET /api/sta">>),
    Handshake = connect(Fox, {127, 0, 0, 1}),
    ok = send(Handshake, <<"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n">>),
    Kept = connect(Http, {127, 0, 0, 1}),
    ok = send(Kept, <<"GET /api/state HTTP/1.1\r\nHost: x\r\n\r\n">>),
    {ok, <<"HTTP/1.1 200", _/binary>>} = recv(Kept, 0, 5000),
    Closed = fun(S) -> closed(S, T0) end,
    {THalf, TShake, TKept} = {Closed(Half), Closed(Handshake), Closed(Kept)},
    ct:pal("closed after ~b ms (half a request), ~b ms (half a handshake), ~b ms (kept alive); "
           "request_timeout ~b, idle_timeout ~b", [THalf, TShake, TKept, ReqT, IdleT]),
    ?assert(THalf >= ReqT andalso TShake >= ReqT andalso TKept >= IdleT),
    ?assert(TKept > THalf),
    #{closed_by := #{request_timeout := 1, idle_timeout := 1}} =
        toroco_live_listener:stats(toroco_live_http),
    #{closed_by := #{request_timeout := 1}} =
        toroco_live_listener:stats(toroco_live_foxglove_listener),
    {200, Metrics} = http_get(Http, "/metrics"),
    ?assertEqual(1, metric_value(metric_lines(Metrics), "dashboard", "idle_timeout")),
    [close(S) || S <- [Half, Handshake, Kept]],
    ok.

full_port_sheds_longest_idle() ->
    [{doc, "A full port closes its longest-idle connection (once min_age old) for a "
      "newcomer; one too young is kept and the newcomer refused"}].
full_port_sheds_longest_idle(_Config) ->
    %% older than the four connections' opening takes (TLS handshakes
    %% included, on a loaded machine)
    MinAge = 1000,
    {ok, #{http := Http}} = start(#{http => 0, foxglove => off, max_connections => 4,
                                    min_age => MinAge, request_timeout => 60000}),
    Idle = [connect(Http, {127, 0, 0, 1}) || _ <- lists:seq(1, 4)],
    toroco_test_lib:wait_until(
      fun() -> maps:get(connections, toroco_live_listener:stats(toroco_live_http)) =:= 4 end, 5000),
    %% too young to be shed: the newcomer is refused (at once, before
    %% any TLS handshake)
    Early = raw_connect(Http, ?OTHER),
    ?assertEqual({error, closed}, gen_tcp:recv(Early, 0, 5000)),
    %% the idle ones must be min_age old to be shed: a known wait
    toroco_test_lib:quiet(MinAge),
    {Ms, {200, _}} = timed(fun() -> http_get(Http, "/api/state") end),
    ct:pal("/api/state on a full port: ~b ms", [Ms]),
    %% one of the four (admitted in whatever order mochiweb's acceptors
    %% ran, so which one is the guard's to say) is closed, the others stay
    Shed = shed_one(Idle, 5000),
    [?assertEqual({error, timeout}, recv(S, 0, 0)) || S <- Idle -- [Shed]],
    #{closed_by := #{shed := 1, too_many_clients := 1}} =
        toroco_live_listener:stats(toroco_live_http),
    [close(S) || S <- [Early | Idle]],
    ok.

slow_tls_handshake_closed() ->
    [{doc, "Over TLS, a connection that never completes its handshake (silent, or half a "
      "ClientHello) is closed after request_timeout and counted so; one that speaks plain "
      "HTTP is closed at once (tls_handshake); a client from another address is served "
      "meanwhile"}].
slow_tls_handshake_closed(_Config) ->
    ReqT = 300,
    {ok, #{http := Http}} = start(#{http => 0, foxglove => off, request_timeout => ReqT}),
    T0 = erlang:monotonic_time(millisecond),
    Silent = raw_connect(Http, {127, 0, 0, 1}),
    HalfHello = raw_connect(Http, {127, 0, 0, 1}),
    %% a TLS record header announcing a ClientHello of 512 bytes, then 5 of them
    ok = gen_tcp:send(HalfHello, <<22, 3, 1, 2, 0, 1, 0, 1, 252, 3>>),
    Garbage = raw_connect(Http, {127, 0, 0, 1}),
    %% plain HTTP: not a TLS record
    ok = gen_tcp:send(Garbage, <<"GET / HTTP/1.1\r\nHost: x\r\n\r\n">>),
    {200, _} = http_get(Http, "/api/state"),
    %% the first to close first
    TGarbage = closed(Garbage, T0),
    {TSilent, THalf} = {closed(Silent, T0), closed(HalfHello, T0)},
    ct:pal("closed after ~b ms (silent), ~b ms (half a ClientHello), ~b ms (not TLS); "
           "request_timeout ~b", [TSilent, THalf, TGarbage, ReqT]),
    ?assert(TSilent >= ReqT andalso THalf >= ReqT),
    ?assert(TGarbage < TSilent),
    #{closed_by := #{request_timeout := 2, tls_handshake := 1}} =
        toroco_live_listener:stats(toroco_live_http),
    ok.

%%====================================================================
%% Helpers
%%====================================================================

%% The one socket of `Socks' the server closed (within Timeout ms).
shed_one(Socks, Timeout) ->
    %% a TLS client's socket learns of the close only while it reads
    Wait = fun(S) when is_port(S) -> 0; (_) -> 50 end,
    Step = fun(none) ->
                   case [S || S <- Socks, recv(S, 0, Wait(S)) =:= {error, closed}] of
                       [S] -> {done, S};
                       [] -> {more, none};
                       Many -> ct:fail({shed, length(Many)})
                   end
           end,
    toroco_test_lib:wait_fold(Step, none, Timeout, one_shed).

%% A process holding N connections to each port from 127.0.0.1, every
%% other one with half a request line sent; it answers once all are open
%% and closes them all when told (or when the case ends).
flood(Ports, N) ->
    Self = self(),
    Pid = spawn_link(fun() ->
                             Socks = [S || P <- Ports, I <- lists:seq(1, N), S <- open(P, I)],
                             Self ! {flooded, self(), length(Socks)},
                             receive stop -> [gen_tcp:close(S) || S <- Socks] end,
                             Self ! {unflooded, self()}
                     end),
    receive {flooded, Pid, Open} ->
            ct:pal("flood: ~b connections open", [Open]),
            ?assertEqual(N * length(Ports), Open)
    after 60000 -> ct:fail(flood_not_open)
    end,
    Pid.

open(Port, I) ->
    case gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}], 5000) of
        {ok, S} when I rem 2 =:= 0 -> _ = gen_tcp:send(S, <<"GET / HT">>), [S];
        {ok, S} -> [S];
        {error, _} -> []
    end.

unflood(Pid) ->
    Pid ! stop,
    receive {unflooded, Pid} -> ok after 30000 -> ct:fail(flood_not_closed) end.

%% A client's connection from `From': TLS in the group `tls' (its
%% handshake done, the server's certificate checked against the test CA).
connect(Port, From) ->
    S = raw_connect(Port, From),
    case persistent_term:get({?MODULE, tls}) of
        none -> S;
        #{ca := Ca} ->
            {ok, Ssl} = ssl:connect(S, [binary, {active, false}, {verify, verify_peer},
                                        {cacertfile, Ca}, {server_name_indication, "localhost"}],
                                    5000),
            Ssl
    end.

%% A TCP connection, whatever the port speaks.
raw_connect(Port, From) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}, {ip, From}], 5000),
    S.

send(S, Data) when is_port(S) -> gen_tcp:send(S, Data);
send(S, Data) -> ssl:send(S, Data).

recv(S, N, T) when is_port(S) -> gen_tcp:recv(S, N, T);
recv(S, N, T) -> ssl:recv(S, N, T).

close(S) when is_port(S) -> gen_tcp:close(S);
close(S) -> ssl:close(S).

%% When the server closed `S', in ms since `T0'.
closed(S, T0) ->
    case recv_all(S, 10000) of
        {closed, _} -> erlang:monotonic_time(millisecond) - T0;
        Other -> ct:fail({not_closed, Other})
    end.

recv_all(S, Timeout) ->
    recv_all(S, Timeout, <<>>).

recv_all(S, Timeout, Acc) ->
    case recv(S, 0, Timeout) of
        {ok, B} -> recv_all(S, Timeout, <<Acc/binary, B/binary>>);
        {error, closed} -> {closed, Acc};
        {error, Why} -> {Why, Acc}
    end.

%% One request from 127.0.0.2, `Connection: close': status and body.
http_get(Port, Path) ->
    S = connect(Port, ?OTHER),
    ok = send(S, ["GET ", Path, " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"]),
    {closed, Resp} = recv_all(S, 5000),
    close(S),
    [Head, Body] = binary:split(Resp, <<"\r\n\r\n">>),
    <<"HTTP/1.1 ", Status:3/binary, _/binary>> = Head,
    {binary_to_integer(Status), dechunk(Head, Body)}.

dechunk(Head, Body) ->
    case binary:match(string:lowercase(Head), <<"transfer-encoding: chunked">>) of
        nomatch -> Body;
        _ -> chunks(Body, <<>>)
    end.

chunks(Bin, Acc) ->
    [SizeHex, Rest] = binary:split(Bin, <<"\r\n">>),
    case binary_to_integer(SizeHex, 16) of
        0 -> Acc;
        Size -> <<Chunk:Size/binary, "\r\n", More/binary>> = Rest, chunks(More, <<Acc/binary, Chunk/binary>>)
    end.

%% A Foxglove client from 127.0.0.2: the handshake with the protocol's
%% subprotocol, then the first frame, which must be serverInfo.
foxglove_hello(Port) ->
    S = connect(Port, ?OTHER),
    Key = base64:encode(crypto:strong_rand_bytes(16)),
    ok = send(S, ["GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                          "Connection: Upgrade\r\nSec-WebSocket-Key: ", Key, "\r\n"
                          "Sec-WebSocket-Version: 13\r\n"
                          "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"]),
    {ok, Head, Rest} = read_head(S, <<>>),
    <<"HTTP/1.1 101", _/binary>> = Head,
    Json = text_frame(S, Rest),
    close(S),
    jiffy:decode(Json, [return_maps]).

read_head(S, Acc) ->
    case binary:split(Acc, <<"\r\n\r\n">>) of
        [Head, Rest] -> {ok, Head, Rest};
        [_] ->
            {ok, B} = recv(S, 0, 5000),
            read_head(S, <<Acc/binary, B/binary>>)
    end.

text_frame(S, <<_:4, 1:4, 0:1, 126:7, Len:16, P:Len/binary, _/binary>>) -> ok(S, P);
text_frame(S, <<_:4, 1:4, 0:1, 127:7, Len:64, P:Len/binary, _/binary>>) -> ok(S, P);
text_frame(S, <<_:4, 1:4, 0:1, Len:7, P:Len/binary, _/binary>>) when Len < 126 -> ok(S, P);
text_frame(S, Acc) ->
    {ok, B} = recv(S, 0, 5000),
    text_frame(S, <<Acc/binary, B/binary>>).

ok(_S, P) -> P.

timed(F) ->
    T0 = erlang:monotonic_time(millisecond),
    R = F(),
    {erlang:monotonic_time(millisecond) - T0, R}.

metric_lines(Text) ->
    string:split(binary_to_list(Text), "\n", all).

metric_value(Lines, Listener, Reason) ->
    Prefix = "toroco_live_connections_closed_total{listener=\"" ++ Listener ++ "\",reason=\""
        ++ Reason ++ "\"} ",
    case [list_to_integer(string:prefix(L, Prefix)) || L <- Lines, string:prefix(L, Prefix) =/= nomatch] of
        [V] -> V;
        [] -> ct:fail({no_metric, Listener, Reason})
    end.

fd_limit() ->
    case string:trim(os:cmd("ulimit -n")) of
        "unlimited" -> 1 bsl 20;
        Limit -> list_to_integer(Limit)
    end.

mb(Bytes) -> Bytes / 1048576.
