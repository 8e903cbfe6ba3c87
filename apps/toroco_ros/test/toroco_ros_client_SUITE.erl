%% Client mode (SPEC §15): the robot dials a rosbridge v2 server. There is
%% no ROS graph here: the server is a scripted rosbridge peer in this
%% suite (an Erlang WebSocket server that checks the client's ops and
%% publishes on /cmd_vel), and this project's own server on a second node
%% (OTP's `peer', on loopback, not connected to this one: two robots),
%% used by roslib in Node.
-module(toroco_ros_client_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [advertises_publishes_and_drives, odometry_of_the_world, refused_topic_not_published,
     reconnects_with_backoff,
     disconnect_ends_it,
     bad_handshakes_retried, bad_url_and_options_refused, stalled_server_costs_the_robot_nothing,
     own_server_on_another_node, app_env_dials, wss_checked_by_ca_or_fingerprint,
     wss_refuses_a_certificate_that_does_not_match].

suite() -> [{timetrap, {seconds, 90}}].

init_per_suite(Config) ->
    [{env, tl_live:start(#{}, [toroco_ros])} | Config].

end_per_suite(Config) ->
    tl_live:stop(?config(env, Config)).

init_per_testcase(_Case, Config) ->
    tl_live:fake_robot(),
    %% the inbound topic /cmd_vel: the `ros' device's output, wired to motors
    ok = toroco:add_device(ros, toroco_ros_device, #{}),
    ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [setvel]}),
    ok = toroco:set_inputs(motors, #{setvel => [{ros, cmd_vel}]}),
    Config.

end_per_testcase(_Case, _Config) ->
    [ok = toroco_live:rosbridge_disconnect(P) || P <- toroco_ros_client_sup:clients()],
    ok = toroco_live:stop(),
    toroco_test_lib:clear().

%%====================================================================
%% Cases
%%====================================================================

advertises_publishes_and_drives() ->
    [{doc, "Connected, the client advertises the robot's topics with their ROS 2 types, "
      "subscribes to /cmd_vel, publishes the robot's messages, and a Twist the server "
      "publishes on /cmd_vel drives the motors through the wheel geometry; a Twist that "
      "does not fit is refused and counted; all of it in /api/state and /metrics"}].
advertises_publishes_and_drives(_Config) ->
    {L, Port} = listen(),
    {ok, Pid} = toroco_live:rosbridge_connect(url(Port, "/rb?token=t0ken-123"), #{}),
    {S, Request, P0} = accept(L),
    %% the query goes with the upgrade, for a server that wants a token
    {match, _} = re:run(Request, "^GET /rb\\?token=t0ken-123 HTTP/1.1\r\n"),
    {_, Seen, P1} = recv_op(S, P0, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    #{<<"topic">> := <<"/cmd_vel">>, <<"type">> := <<"geometry_msgs/msg/Twist">>} = lists:last(Seen),
    Advertised = [{T, Ty} || #{<<"op">> := <<"advertise">>, <<"topic">> := T, <<"type">> := Ty} <- Seen],
    ct:log("ops: ~p", [Seen]),
    true = lists:member({<<"/toroco/out/s/dist">>, <<"std_msgs/msg/String">>}, Advertised),
    false = lists:keymember(<<"/cmd_vel">>, 1, Advertised),
    %% the robot's messages, published there
    ok = toroco:inject({s, dist}, {near, 7}),
    {#{<<"msg">> := #{<<"data">> := Data}}, _, P2} =
        recv_op(S, P1, fun(#{<<"op">> := <<"publish">>, <<"topic">> := <<"/toroco/out/s/dist">>}) -> true;
                          (_) -> false end),
    #{<<"term">> := <<"{near,7}">>} = jiffy:decode(Data, [return_maps]),
    %% a Twist from there drives the robot here
    Twist = #{linear => #{x => 0.125, y => 0, z => 0}, angular => #{x => 0, y => 0, z => 0.5}},
    {ok, Wheels} = toroco_ros_topics:twist_to_wheels(Twist, toroco_ros_topics:geometry()),
    send_op(S, #{op => publish, topic => <<"/cmd_vel">>, msg => Twist}),
    ok = toroco_fake_actuator:await(motors, fun(H) -> lists:keymember(Wheels, 2, H) end, 5000),
    %% one that does not fit, and one on a topic not subscribed: nothing moves
    send_op(S, #{op => publish, topic => <<"/cmd_vel">>, msg => #{linear => <<"fast">>}}),
    send_op(S, #{op => publish, topic => <<"/elsewhere">>, msg => Twist}),
    send_op(S, #{op => status, level => error, msg => <<"just saying">>}),
    ok = until(fun() -> [#{refused := R}] = toroco_live:rosbridge_clients(), R =:= 1 end, 5000),
    [{setvel, Wheels, _}] = toroco_fake_actuator:history(motors),
    [#{url := Url, state := connected, attempts := 0, connects := 1, received := 2, refused := 1,
       sent := Sent, dropped := 0}] = toroco_live:rosbridge_clients(),
    true = Sent >= 1,
    %% shown without its query (the token)
    Url = iolist_to_binary(url(Port, "/rb")),
    #{<<"rosbridge_clients">> := [#{<<"state">> := <<"connected">>, <<"url">> := Url,
                                    <<"received">> := 2, <<"attempts">> := 0}]} =
        jiffy:decode(jiffy:encode(toroco_live_state:api()), [return_maps]),
    Metrics = iolist_to_binary(toroco_live_metrics:text()),
    {match, _} = re:run(Metrics, "toroco_live_rosclient_connected\\{url=\"" ++ binary_to_list(Url) ++ "\"\\} 1"),
    {match, _} = re:run(Metrics, "toroco_live_rosclient_received_total\\{url=\"[^\"]+\"\\} 2"),
    {match, _} = re:run(Metrics, "toroco_live_rosclient_refused_total\\{url=\"[^\"]+\"\\} 1"),
    nomatch = re:run(Metrics, "t0ken-123"),
    true = is_process_alive(Pid),
    _ = P2,
    gen_tcp:close(S),
    gen_tcp:close(L).

odometry_of_the_world() ->
    [{doc, "While a simulated world runs, /odom is advertised as nav_msgs/msg/Odometry and "
      "each snapshot's pose is published there"}].
odometry_of_the_world(_Config) ->
    {L, Port} = listen(),
    {ok, _} = toroco_live:rosbridge_connect(url(Port, "/"), #{}),
    {S, _, P0} = accept(L),
    {_, _, P1} = recv_op(S, P0, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    Robot = #{name => r1, pose => {0.5, 0.75, 90.0}, radius => 0.1, winner => none, ir => [],
              camera => #{fov_deg => 60, range => 1.0}},
    ok = toroco:publish_world(#{run => odom_test, t_ms => 0, arena => {2.0, 2.0}, walls => [],
                                objects => [], robots => [Robot]}),
    {#{<<"topic">> := <<"/odom">>, <<"type">> := <<"nav_msgs/msg/Odometry">>}, _, P2} =
        recv_op(S, P1, fun(#{<<"op">> := <<"advertise">>, <<"topic">> := T}) -> T =:= <<"/odom">>;
                          (_) -> false end),
    {#{<<"msg">> := Odom}, _, _} =
        recv_op(S, P2, fun(#{<<"op">> := <<"publish">>, <<"topic">> := T}) -> T =:= <<"/odom">>;
                          (_) -> false end),
    #{<<"header">> := #{<<"frame_id">> := <<"odom">>}, <<"child_frame_id">> := <<"base_link">>,
      <<"pose">> := #{<<"pose">> := #{<<"position">> := #{<<"x">> := 0.5, <<"y">> := 0.75},
                                      <<"orientation">> := #{<<"z">> := Z, <<"w">> := W}}}} = Odom,
    true = abs(Z - math:sin(math:pi() / 4)) < 1.0e-9 andalso abs(W - math:cos(math:pi() / 4)) < 1.0e-9,
    gen_tcp:close(S),
    gen_tcp:close(L).

refused_topic_not_published() ->
    [{doc, "A topic the server refuses (a status error for its advertise's id) is not "
      "published on for the rest of the connection, and is counted; the others are"}].
refused_topic_not_published(_Config) ->
    ok = toroco:add_device(t, toroco_fake_sensor, #{outputs => [v]}),
    {L, Port} = listen(),
    {ok, _} = toroco_live:rosbridge_connect(url(Port, "/"), #{}),
    {S, _, P0} = accept(L),
    {#{<<"id">> := Id}, _, P1} =
        recv_op(S, P0, fun(#{<<"op">> := <<"advertise">>, <<"topic">> := T}) -> T =:= <<"/toroco/out/s/dist">>;
                          (_) -> false end),
    send_op(S, #{op => status, level => error, id => Id, msg => <<"cannot publish on /toroco/out/s/dist">>}),
    ok = until(fun() -> [#{refused_topics := R}] = toroco_live:rosbridge_clients(),
                         R =:= [<<"/toroco/out/s/dist">>] end, 5000),
    %% s before t: the client handles the robot's events in order
    ok = toroco:inject({s, dist}, 1),
    ok = toroco:inject({t, v}, 2),
    {_, Seen, _} = recv_op(S, P1, fun(#{<<"op">> := <<"publish">>, <<"topic">> := T}) -> T =:= <<"/toroco/out/t/v">>;
                                     (_) -> false end),
    [] = [Op || #{<<"op">> := <<"publish">>, <<"topic">> := <<"/toroco/out/s/dist">>} = Op <- Seen],
    gen_tcp:close(S),
    gen_tcp:close(L).

reconnects_with_backoff() ->
    [{doc, "When the server closes the connection the client dials again and advertises "
      "again; while nobody listens it keeps trying with a growing, bounded backoff, and "
      "connects as soon as the server is back"}].
reconnects_with_backoff(_Config) ->
    {L, Port} = listen(),
    {ok, _} = toroco_live:rosbridge_connect(url(Port, "/"), #{backoff_min => 20, backoff_max => 200}),
    {S1, _, P1} = accept(L),
    {_, _, _} = recv_op(S1, P1, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    ok = gen_tcp:close(S1),
    %% dialled again, and the topics advertised again
    {S2, _, P2} = accept(L),
    {_, _, _} = recv_op(S2, P2, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    ok = until(fun() -> [#{connects := C}] = toroco_live:rosbridge_clients(), C =:= 2 end, 5000),
    %% nobody listens: attempts pile up, refused
    ok = gen_tcp:close(L),
    ok = gen_tcp:close(S2),
    Start = erlang:monotonic_time(millisecond),
    ok = until(fun() -> [#{attempts := A}] = toroco_live:rosbridge_clients(), A >= 6 end, 10000),
    Elapsed = erlang:monotonic_time(millisecond) - Start,
    [#{state := State, last_error := {connect, econnrefused}}] = toroco_live:rosbridge_clients(),
    true = lists:member(State, [connecting, waiting]),
    %% 6 attempts with a backoff from 20 ms doubling to 200 ms, each wait at
    %% least half its ceiling: 10 + 20 + 40 + 80 + 100 ms at the least
    ct:log("6 failed attempts in ~b ms", [Elapsed]),
    true = Elapsed >= 250,
    %% back: connected within a backoff or so
    {ok, L2} = gen_tcp:listen(Port, [binary, {active, false}, {reuseaddr, true}]),
    {S3, _, P3} = accept(L2),
    {_, _, _} = recv_op(S3, P3, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    ok = until(fun() -> [#{state => connected, attempts => 0, connects => 3}] =:=
                            [maps:with([state, attempts, connects], I) || I <- toroco_live:rosbridge_clients()]
               end, 5000),
    gen_tcp:close(S3),
    gen_tcp:close(L2).

disconnect_ends_it() ->
    [{doc, "rosbridge_disconnect/1 closes the connection with a close frame and the client "
      "dials no more; the supervisor does not bring it back"}].
disconnect_ends_it(_Config) ->
    {L, Port} = listen(),
    {ok, Pid} = toroco_live:rosbridge_connect(url(Port, "/"), #{backoff_min => 20}),
    {S, _, P} = accept(L),
    {_, _, P1} = recv_op(S, P, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    ok = toroco_live:rosbridge_disconnect(Pid),
    {close, 1000, _} = recv_close(S, P1),
    false = is_process_alive(Pid),
    [] = toroco_live:rosbridge_clients(),
    {error, timeout} = gen_tcp:accept(L, 300),
    {error, not_found} = toroco_live:rosbridge_disconnect(Pid),
    gen_tcp:close(S),
    gen_tcp:close(L).

bad_handshakes_retried() ->
    [{doc, "A server that answers the upgrade with 200, or with a wrong Sec-WebSocket-Accept, "
      "is not taken for connected: each is an attempt with its reason, and the client "
      "dials again"}].
bad_handshakes_retried(_Config) ->
    {L, Port} = listen(),
    {ok, _} = toroco_live:rosbridge_connect(url(Port, "/"), #{backoff_min => 20, backoff_max => 50}),
    {ok, S1} = gen_tcp:accept(L, 5000),
    {ok, _} = read_request(S1, <<>>),
    ok = gen_tcp:send(S1, <<"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n">>),
    ok = until(fun() -> [#{last_error := E}] = toroco_live:rosbridge_clients(), E =:= {http_status, 200} end, 5000),
    {ok, S2} = gen_tcp:accept(L, 5000),
    {ok, _} = read_request(S2, <<>>),
    ok = gen_tcp:send(S2, <<"HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n"
                            "Connection: Upgrade\r\nSec-WebSocket-Accept: bm90IHRoZSBhbnN3ZXI=\r\n\r\n">>),
    ok = until(fun() -> [#{last_error := E}] = toroco_live:rosbridge_clients(),
                         E =:= {bad_accept, <<"bm90IHRoZSBhbnN3ZXI=">>} end, 5000),
    [#{state := State, connects := 0}] = toroco_live:rosbridge_clients(),
    true = State =/= connected,
    %% and then a good one
    {S3, _, P3} = accept(L),
    {_, _, _} = recv_op(S3, P3, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    [gen_tcp:close(S) || S <- [S1, S2, S3]],
    gen_tcp:close(L).

wss_checked_by_ca_or_fingerprint() ->
    [{doc, "Over wss:// the client connects to this project's server (TLS, a test CA's "
      "certificate) checked against the CA file, by name or by address, and to a self-signed "
      "one by its pinned fingerprint (as scripts/tls-cert prints it)"}].
wss_checked_by_ca_or_fingerprint(Config) ->
    Tls = tl_tls:make(?config(priv_dir, Config)),
    {ok, #{rosbridge := Port, token := Token}} =
        toroco_live:start(#{http => 0, foxglove => off, rosbridge => 0, tls => tl_tls:tls(Tls)}),
    Url = fun(Host) -> iolist_to_binary(io_lib:format("wss://~s:~b/?token=~s", [Host, Port, Token])) end,
    Ca = #{cacertfile => maps:get(ca, Tls)},
    {ok, ByName} = toroco_live:rosbridge_connect(Url("localhost"), Ca),
    {ok, ByAddress} = toroco_live:rosbridge_connect(Url("127.0.0.1"), Ca),
    await_state([ByName, ByAddress], connected),
    %% the server took both as its clients
    2 = maps:get(connections, toroco_ros_server:stats()),
    [ok = toroco_live:rosbridge_disconnect(P) || P <- [ByName, ByAddress]],
    ok = toroco_live:stop(),
    %% self-signed, pinned
    {ok, #{rosbridge := Port2}} =
        toroco_live:start(#{http => 0, foxglove => off, rosbridge => 0, tls => tl_tls:stranger_tls(Tls)}),
    {ok, Pinned} = toroco_live:rosbridge_connect(
                     iolist_to_binary(io_lib:format("wss://127.0.0.1:~b/", [Port2])),
                     #{fingerprint => maps:get(stranger_fingerprint, Tls)}),
    await_state([Pinned], connected),
    ok = toroco_live:rosbridge_disconnect(Pinned),
    ok = toroco_live:stop().

wss_refuses_a_certificate_that_does_not_match() ->
    [{doc, "A server whose certificate the CA file does not vouch for, or whose fingerprint "
      "is not the pinned one, is refused before a byte is sent: {tls, Why} in last_error, "
      "never connected, dialled again with backoff"}].
wss_refuses_a_certificate_that_does_not_match(Config) ->
    Tls = tl_tls:make(?config(priv_dir, Config)),
    {ok, #{rosbridge := Port}} =
        toroco_live:start(#{http => 0, foxglove => off, rosbridge => 0,
                            tls => tl_tls:stranger_tls(Tls)}),
    Url = iolist_to_binary(io_lib:format("wss://localhost:~b/", [Port])),
    {ok, Ca} = toroco_live:rosbridge_connect(Url, #{cacertfile => maps:get(ca, Tls),
                                                    backoff_min => 50, backoff_max => 200}),
    {ok, Pin} = toroco_live:rosbridge_connect(Url, #{fingerprint => maps:get(fingerprint, Tls),
                                                     backoff_min => 50, backoff_max => 200}),
    toroco_test_lib:wait_until(
      fun() -> lists:all(fun(#{attempts := A}) -> A >= 3 end, toroco_live:rosbridge_clients()) end,
      15000),
    Infos = toroco_live:rosbridge_clients(),
    ct:pal("refused: ~p", [[E || #{last_error := E} <- Infos]]),
    2 = length([I || I = #{connects := 0, state := S, last_error := {tls, _}} <- Infos,
                     S =/= connected]),
    [{tls, {fingerprint_mismatch, _}}] =
        [E || #{last_error := E = {tls, {fingerprint_mismatch, _}}} <- Infos],
    %% the server saw no WebSocket client: nothing was sent past the handshake
    0 = maps:get(connections, toroco_ros_server:stats(), 0),
    [ok = toroco_live:rosbridge_disconnect(P) || P <- [Ca, Pin]],
    ok = toroco_live:stop().

await_state(Pids, State) ->
    toroco_test_lib:wait_until(
      fun() ->
              Now = [S || P <- Pids, #{state := S} <- [toroco_ros_client:info(P)]],
              Now =:= [State || _ <- Pids]
      end, 15000).

bad_url_and_options_refused() ->
    [{doc, "A URL that is not ws://, and options out of range, are refused naming them, and "
      "no client is started"}].
bad_url_and_options_refused(_Config) ->
    %% wss:// only with the server's certificate checked
    {error, {unverified_wss, _}} = toroco_live:rosbridge_connect("wss://h:9090/", #{}),
    {error, {tls_options_without_wss, _}} =
        toroco_live:rosbridge_connect("ws://h:9090/", #{fingerprint => binary:copy(<<"ab">>, 32)}),
    {error, {bad_option, {fingerprint, <<"AB:CD">>}}} =
        toroco_live:rosbridge_connect("wss://h:9090/", #{fingerprint => <<"AB:CD">>}),
    {error, {bad_option, {cacertfile, "/no/such/ca.pem"}}} =
        toroco_live:rosbridge_connect("wss://h:9090/", #{cacertfile => "/no/such/ca.pem"}),
    {error, {unsupported_scheme, <<"ftp">>}} = toroco_live:rosbridge_connect("ftp://h:9090/", #{}),
    {error, {unsupported_scheme, <<"http">>}} = toroco_live:rosbridge_connect(<<"http://h/">>, #{}),
    {error, {bad_url, _}} = toroco_live:rosbridge_connect("not a url", #{}),
    {error, {bad_url, 42}} = toroco_live:rosbridge_connect(42, #{}),
    {error, {bad_option, {max_queue, 0}}} = toroco_live:rosbridge_connect("ws://h:1/", #{max_queue => 0}),
    {error, {bad_option, {colour, red}}} = toroco_live:rosbridge_connect("ws://h:1/", #{colour => red}),
    {error, {bad_option, nope}} = toroco_live:rosbridge_connect("ws://h:1/", nope),
    [] = toroco_live:rosbridge_clients(),
    ok.

stalled_server_costs_the_robot_nothing() ->
    [{doc, "A server that stops reading fills the client's bounded queue: the robot's events "
      "past it are dropped and counted, the robot delivers every value meanwhile, and once "
      "the socket stays full the connection is given up and dialled again"}].
stalled_server_costs_the_robot_nothing(_Config) ->
    {L, Port} = listen(),
    {ok, _} = toroco_live:rosbridge_connect(url(Port, "/"), #{max_queue => 50, backoff_min => 20}),
    {S, _, P} = accept(L),
    {_, _, _} = recv_op(S, P, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
    %% From now on the server reads nothing; the robot's values go on until
    %% the client has given the connection up and dialled again.
    Big = binary:copy(<<"x">>, 2000),
    T0 = erlang:monotonic_time(millisecond),
    {N, S2} = flood(L, Big, 0, T0 + 60000),
    Ms = erlang:monotonic_time(millisecond) - T0,
    ok = until(fun() -> [#{dropped := D}] = toroco_live:rosbridge_clients(), D > 0 end, 10000),
    [#{dropped := Dropped, sent := Sent, connects := Connects}] = toroco_live:rosbridge_clients(),
    ct:log("~b values of 2 kB delivered in ~b ms while the server read nothing: ~b sent, "
           "~b dropped, ~b connections", [N, Ms, Sent, Dropped, Connects]),
    [gen_tcp:close(X) || X <- [S, S2]],
    gen_tcp:close(L).

%% Values into the robot, a batch at a time, until the client dials again.
flood(L, Big, N, Until) ->
    erlang:monotonic_time(millisecond) < Until orelse ct:fail({not_dialled_again, N}),
    [ok = toroco:inject({s, dist}, {I, Big}) || I <- lists:seq(N + 1, N + 500)],
    %% each batch delivered whole
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 500 end, 20000),
    toroco_fake_actuator:clear(a),
    case gen_tcp:accept(L, 50) of
        {ok, S2} -> {N + 500, S2};
        {error, timeout} -> flood(L, Big, N + 500, Until)
    end.

own_server_on_another_node() ->
    [{doc, "Against this project's rosbridge server on another node: the robot's topics "
      "appear there (roslib's getTopics lists them with their types, and a subscription "
      "there gets the robot's messages), and Twists roslib publishes there on /cmd_vel at "
      "10 Hz drive the robot here"}].
own_server_on_another_node(_Config) ->
    Token = <<"peer-node-token-42">>,
    {Peer, RosPort} = start_server_node(Token),
    try
        Url = "ws://127.0.0.1:" ++ integer_to_list(RosPort) ++ "/?token=" ++ binary_to_list(Token),
        {ok, _} = toroco_live:rosbridge_connect(Url, #{}),
        ok = until(fun() -> [#{state := connected}] = toroco_live:rosbridge_clients(), true end, 10000),
        %% the robot here keeps emitting while roslib looks there
        Injector = toroco_test_lib:paced(fun(I) -> ok = toroco:inject({s, dist}, {tick, I}) end,
                                         infinity, 50),
        Twist = #{linear => #{x => 0.1, y => 0.0, z => 0.0}, angular => #{x => 0.0, y => 0.0, z => -0.4}},
        {ok, Wheels} = toroco_ros_topics:twist_to_wheels(Twist, toroco_ros_topics:geometry()),
        R = toroco_live_js:run("roslib_peer.js", [url_there(RosPort, Token), "/toroco/out/s/dist",
                                                  binary_to_list(jiffy:encode(Twist)), "10"]),
        ok = toroco_test_lib:stop_paced(Injector),
        ct:log("roslib there: ~p", [R]),
        #{<<"ok">> := true, <<"topics">> := Topics, <<"types">> := Types,
          <<"message">> := #{<<"data">> := Data}, <<"published">> := 10} = R,
        Listed = maps:from_list(lists:zip(Topics, Types)),
        #{<<"/toroco/out/s/dist">> := <<"std_msgs/msg/String">>,
          <<"/cmd_vel">> := <<"geometry_msgs/msg/Twist">>} = Listed,
        #{<<"kind">> := <<"send">>, <<"term">> := _} = jiffy:decode(Data, [return_maps]),
        %% the Twists from there, here: each one the same wheels
        ok = toroco_fake_actuator:await(motors, fun(H) -> length(H) >= 10 end, 10000),
        [Wheels] = lists:usort([W || {setvel, W, _} <- toroco_fake_actuator:history(motors)]),
        [#{received := 10, refused := 0, refused_topics := []}] = toroco_live:rosbridge_clients()
    after
        peer:stop(Peer)
    end.

app_env_dials() ->
    [{doc, "The app env rosbridge_connect ({Url, Opts}, or a list) dials when toroco_ros "
      "starts, under toroco_ros_client_sup; a URL it cannot use (wss) does not keep "
      "the application from starting"}].
app_env_dials(_Config) ->
    {L, Port} = listen(),
    ok = application:stop(toroco_ros),
    ok = application:set_env(toroco_ros, rosbridge_connect,
                             [{url(Port, "/"), #{backoff_min => 20}}, "wss://nowhere/"]),
    try
        ok = application:start(toroco_ros),
        {S, _, P} = accept(L),
        {_, _, _} = recv_op(S, P, fun(#{<<"op">> := <<"subscribe">>}) -> true; (_) -> false end),
        [Pid] = toroco_ros_client_sup:clients(),
        [{_, Pid, worker, _}] = supervisor:which_children(toroco_ros_client_sup),
        {_, Sup, supervisor, _} = lists:keyfind(toroco_ros_client_sup, 1,
                                                supervisor:which_children(toroco_ros_sup)),
        Sup = whereis(toroco_ros_client_sup),
        gen_tcp:close(S)
    after
        application:unset_env(toroco_ros, rosbridge_connect),
        ok = application:stop(toroco_ros),
        ok = application:start(toroco_ros),
        gen_tcp:close(L)
    end.

url_there(Port, Token) ->
    "ws://127.0.0.1:" ++ integer_to_list(Port) ++ "/?token=" ++ binary_to_list(Token).

%% A second node, not connected to this one (its own robot), running the
%% rosbridge server with a ros device of its own: its handle and port.
start_server_node(Token) ->
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    {ok, Peer, _} = peer:start_link(#{connection => standard_io, args => ["-pa" | Paths]}),
    ok = peer:call(Peer, application, load, [toroco_live]),
    ok = peer:call(Peer, application, set_env, [toroco_live, enabled, false]),
    {ok, _} = peer:call(Peer, application, ensure_all_started, [toroco_ros], 30000),
    {ok, #{rosbridge := Port}} =
        peer:call(Peer, toroco_live, start, [#{http => 0, foxglove => off, rosbridge => 0, token => Token}]),
    ok = peer:call(Peer, toroco, add_device, [ros, toroco_ros_device, #{}]),
    {Peer, Port}.

%%====================================================================
%% The scripted rosbridge peer
%%====================================================================

url(Port, Path) -> "ws://127.0.0.1:" ++ integer_to_list(Port) ++ Path.

listen() ->
    {ok, L} = gen_tcp:listen(0, [binary, {active, false}, {reuseaddr, true}]),
    {ok, Port} = inet:port(L),
    {L, Port}.

%% Accepts a client and answers its upgrade: the socket, the request, and
%% the peer's decoder of the client's (masked) frames.
accept(L) ->
    {ok, S} = gen_tcp:accept(L, 10000),
    {ok, Request} = read_request(S, <<>>),
    {match, [Key]} = re:run(Request, "Sec-WebSocket-Key: *([^\r]+)\r\n", [{capture, all_but_first, binary}, caseless]),
    {match, _} = re:run(Request, "Sec-WebSocket-Version: 13\r\n", [caseless]),
    ok = gen_tcp:send(S, [<<"HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n"
                            "Connection: Upgrade\r\nSec-WebSocket-Accept: ">>,
                          toroco_live_ws_frame:accept_key(Key), <<"\r\n\r\n">>]),
    {S, Request, {toroco_live_ws_frame:decoder(1 bsl 24), []}}.

read_request(S, Acc) ->
    case binary:match(Acc, <<"\r\n\r\n">>) of
        nomatch ->
            case gen_tcp:recv(S, 0, 5000) of
                {ok, B} -> read_request(S, <<Acc/binary, B/binary>>);
                Err -> Err
            end;
        _ -> {ok, Acc}
    end.

%% The client's ops until one for which Pred holds: {Op, AllSeen, Peer}.
recv_op(S, Peer, Pred) ->
    recv_op(S, Peer, Pred, erlang:monotonic_time(millisecond) + 10000, []).

recv_op(S, {D, [M | Ms]}, Pred, Until, Seen) ->
    case M of
        {text, Json} ->
            Op = jiffy:decode(Json, [return_maps]),
            case Pred(Op) of
                true -> {Op, lists:reverse([Op | Seen]), {D, Ms}};
                false -> recv_op(S, {D, Ms}, Pred, Until, [Op | Seen])
            end;
        _ -> recv_op(S, {D, Ms}, Pred, Until, Seen)
    end;
recv_op(S, {D, []}, Pred, Until, Seen) ->
    Left = Until - erlang:monotonic_time(millisecond),
    Left > 0 orelse ct:fail({no_op, lists:reverse(Seen)}),
    case gen_tcp:recv(S, 0, Left) of
        {ok, B} ->
            {ok, Ms, D1} = toroco_live_ws_frame:decode(B, D),
            recv_op(S, {D1, Ms}, Pred, Until, Seen);
        {error, Why} -> ct:fail({recv, Why, lists:reverse(Seen)})
    end.

recv_close(S, {D, Ms}) ->
    case [C || {close, _, _} = C <- Ms] of
        [C | _] -> C;
        [] ->
            {ok, B} = gen_tcp:recv(S, 0, 5000),
            {ok, Ms1, D1} = toroco_live_ws_frame:decode(B, D),
            recv_close(S, {D1, Ms1})
    end.

send_op(S, Op) ->
    ok = gen_tcp:send(S, toroco_live_ws_frame:frame(text, jiffy:encode(Op))).

%% Pred may fail to match while the client is not listed yet.
until(Pred, Ms) ->
    toroco_test_lib:wait_until(fun() -> (catch Pred()) =:= true end, Ms, client_state).
