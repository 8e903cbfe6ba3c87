%% The rosbridge v2 server (SPEC §15) against roslib 2.1.0 in Node
%% (test/js/ros_driver.js) and a raw WebSocket for what a misbehaving
%% client does. Most cases run on a fake robot: a `range' sensor (front),
%% `motors' (applied), the `ros' device wired to a fake actuator `cmd',
%% and the fake sensor `s' wired to the fake actuator `a'; the driving
%% cases run the teleop robot (config/robots/teleop.wiring) in its world.
-module(toroco_ros_server_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [topics_and_types, services_round_trip, publish_needs_the_token, subscribe_throttled, cbor_raw,
     fragments_out, bad_input, flood_disconnected, client_that_never_reads, not_a_websocket,
     start_options, server_goes_with_the_application, lockstep_stimulus, simulated_range_and_odometry, drive_the_teleop_robot,
     runtime_restart, {group, tls}].

%% The hostile clients again with TLS on the port (wss://, Node trusting a
%% test CA made at the group's start).
groups() ->
    [{tls, [], [publish_needs_the_token, bad_input, flood_disconnected, client_that_never_reads]}].

init_per_group(tls, Config) ->
    [{tls, tl_tls:make(?config(priv_dir, Config))} | Config].

end_per_group(tls, _Config) ->
    ok.

suite() -> [{timetrap, {seconds, 90}}].

-define(TWIST, <<"geometry_msgs/msg/Twist">>).

init_per_suite(Config) ->
    Env = tl_live:start(#{}, [toroco_ros]),
    %% Running already, each simulated run takes away only what it added.
    {ok, _} = application:ensure_all_started(torobot),
    [{env, Env} | Config].

end_per_suite(Config) ->
    application:stop(torobot),
    application:unset_env(toroco_ros, rosbridge_fragment_ms),
    application:unset_env(toroco_ros, rosbridge_max_message),
    tl_live:stop(?config(env, Config)).

init_per_testcase(Case, Config) ->
    Sim = lists:member(Case, [simulated_range_and_odometry, drive_the_teleop_robot]),
    Sim orelse fake_robot(),
    ok = application:set_env(toroco_ros, rosbridge_fragment_ms, 500),
    ok = application:set_env(toroco_ros, rosbridge_max_message, 65536),
    {Tls, Scheme} = case proplists:get_value(tls, Config) of
                        undefined -> {#{}, "ws://127.0.0.1"};
                        T -> {#{tls => tl_tls:tls(T)}, "wss://localhost"}
                    end,
    {ok, #{rosbridge := Port, token := Token}} =
        toroco_live:start(Tls#{http => 0, foxglove => off, rosbridge => 0}),
    Transcript = filename:join(?config(priv_dir, Config), atom_to_list(Case) ++ ".jsonl"),
    toroco_live_js:transcript(Transcript),
    Url = iolist_to_binary(io_lib:format("~s:~b/", [Scheme, Port])),
    [{port, Port}, {token, Token}, {url, Url},
     {token_url, <<Url/binary, "?token=", Token/binary>>} | Config].

end_per_testcase(_Case, _Config) ->
    %% A run a failed case left behind ends before the next case.
    case whereis(rosbridge_suite_sim) of
        undefined -> ok;
        Sim ->
            Ref = monitor(process, Sim),
            receive {'DOWN', Ref, process, Sim, _} -> ok after 30000 -> exit(Sim, kill) end
    end,
    toroco_live:stop(),
    [toroco:remove_device(D) || D <- [s, a, range, motors, ros, cmd]],
    ok.

fake_robot() ->
    tl_live:fake_robot(),
    ok = toroco:add_device(range, toroco_fake_sensor, #{outputs => [front]}),
    ok = toroco:add_device(motors, toroco_fake_sensor, #{outputs => [applied]}),
    ok = toroco:add_device(ros, toroco_ros_device, #{}),
    ok = toroco:add_device(cmd, toroco_fake_actuator, #{inputs => [v]}),
    ok = toroco:set_inputs(cmd, #{v => [{ros, cmd_vel}]}).

%%====================================================================
%% Cases
%%====================================================================

topics_and_types() ->
    [{doc, "roslib's getTopics lists the robot's topics with their ROS 2 types, getTopicType "
      "answers one, getServices lists the services; topics_and_raw_types gives definitions ROS 2 tooling parses"}].
topics_and_types(Config) ->
    C = connect(Config, url),
    toroco_live_js:send(C, #{cmd => getTopics}),
    {ok, #{<<"topics">> := Topics, <<"types">> := Types}, _} = await(C, <<"topics">>),
    Map = maps:from_list(lists:zip(Topics, Types)),
    ct:log("topics: ~p", [Map]),
    #{<<"/cmd_vel">> := ?TWIST, <<"/toroco/motors/applied">> := ?TWIST,
      <<"/range/front">> := <<"sensor_msgs/msg/Range">>,
      <<"/toroco/out/s/dist">> := <<"std_msgs/msg/String">>} = Map,
    false = maps:is_key(<<"/toroco/out/ros/cmd_vel">>, Map),
    toroco_live_js:send(C, #{cmd => getTopicType, topic => <<"range/front">>}),
    {ok, #{<<"type">> := <<"sensor_msgs/msg/Range">>}, _} = await(C, <<"topic_type">>),
    toroco_live_js:send(C, #{cmd => getServices}),
    {ok, #{<<"services">> := Services}, _} = await(C, <<"services">>),
    [<<"/rosapi/get_ros_version">>, <<"/rosapi/services">>, <<"/rosapi/topic_type">>,
     <<"/rosapi/topics">>, <<"/rosapi/topics_and_raw_types">>, <<"/toroco/inspect">>] =
        lists:sort(Services),
    %% What Foxglove's Rosbridge connection reads: each type's definition, which
    %% @foxglove/rosmsg parses with its dependencies.
    toroco_live_js:send(C, #{cmd => rawTypes}),
    {ok, #{<<"topics">> := Topics, <<"parsed">> := Parsed}, _} = await(C, <<"raw_types">>),
    Defs = maps:from_list(lists:zip(Topics, Parsed)),
    [#{<<"name">> := null, <<"fields">> := 2}, #{<<"name">> := <<"geometry_msgs/Vector3">>, <<"fields">> := 3}] =
        maps:get(<<"/cmd_vel">>, Defs),
    %% Range: 2 constants and 7 fields; Header; Time
    [#{<<"fields">> := 9}, #{<<"name">> := <<"std_msgs/Header">>}, #{<<"name">> := <<"builtin_interfaces/Time">>}] =
        maps:get(<<"/range/front">>, Defs),
    ok.

services_round_trip() ->
    [{doc, "/toroco/inspect answers toroco:inspect/0 and /1 as JSON; an unknown name or "
      "service fails with a reason"}].
services_round_trip(Config) ->
    C = connect(Config, url),
    toroco_live_js:send(C, #{cmd => call, service => <<"/toroco/inspect">>, args => #{}}),
    {ok, #{<<"ok">> := true, <<"values">> := #{<<"devices">> := Devices}}, _} = await(C, <<"service">>),
    true = lists:member(<<"ros">>, Devices) andalso lists:member(<<"s">>, Devices),
    toroco_live_js:send(C, #{cmd => call, service => <<"toroco/inspect">>, args => #{name => <<"a">>}}),
    {ok, #{<<"ok">> := true, <<"values">> := #{<<"name">> := <<"a">>, <<"inputs">> := #{<<"d">> := _}}}, _} =
        await(C, <<"service">>),
    toroco_live_js:send(C, #{cmd => call, service => <<"/toroco/inspect">>,
                             args => #{name => <<"no_such_thing_here">>}}),
    {ok, #{<<"ok">> := false, <<"values">> := Why}, _} = await(C, <<"service">>),
    true = nomatch =/= string:find(Why, "no behavior or device"),
    toroco_live_js:send(C, #{cmd => call, service => <<"/rosapi/nodes">>, args => #{}}),
    {ok, #{<<"ok">> := false, <<"values">> := Why2}, _} = await(C, <<"service">>),
    true = nomatch =/= string:find(Why2, "unknown service /rosapi/nodes"),
    ok.

publish_needs_the_token() ->
    [{doc, "Without the token a publish on /cmd_vel gets a status error saying why and "
      "nothing reaches the wiring; after the auth op (or with ?token=) the Twist arrives "
      "as {Left, Right} wheel velocities"}].
publish_needs_the_token(Config) ->
    C = connect(Config, url),
    Forward = #{linear => #{x => 0.1, y => 0, z => 0}, angular => #{x => 0, y => 0, z => 0}},
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/cmd_vel">>, type => ?TWIST, msg => Forward}),
    {ok, #{<<"level">> := <<"error">>, <<"msg">> := Msg}, _} = await(C, <<"status">>),
    ct:log("without the token: ~s", [Msg]),
    true = nomatch =/= string:find(Msg, "needs the dashboard's token"),
    %% Nothing went in: the device received nothing, the actuator got nothing.
    #{device := #{received := 0}} = toroco:inspect(ros),
    [] = toroco_fake_actuator:history(cmd),
    toroco_live_js:send(C, #{cmd => auth, token => ?config(token, Config)}),
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/cmd_vel">>, type => ?TWIST, msg => Forward}),
    ok = toroco_fake_actuator:await(cmd, fun(H) -> [V || {v, V, _} <- H] =:= [{40, 40}] end, 5000),
    %% With the token on the URL, publishing works from the start.
    C2 = connect(Config, token_url),
    Turn = #{linear => #{x => 0, y => 0, z => 0}, angular => #{x => 0, y => 0, z => 1.0}},
    toroco_live_js:send(C2, #{cmd => publish, topic => <<"cmd_vel">>, type => <<"geometry_msgs/Twist">>,
                              msg => Turn}),
    ok = toroco_fake_actuator:await(cmd, fun(H) -> lists:member({-40, 40}, [V || {v, V, _} <- H]) end, 5000),
    ok.

subscribe_throttled() ->
    [{doc, "Range and motor messages arrive typed; with throttle_rate a burst becomes at most "
      "one message per period, the newest last"}].
subscribe_throttled(Config) ->
    C = connect(Config, url),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/range/front">>,
                             type => <<"sensor_msgs/msg/Range">>}),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/toroco/motors/applied">>, type => ?TWIST}),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/toroco/out/s/dist">>,
                             type => <<"std_msgs/msg/String">>, throttle_rate => 300,
                             queue_length => 1}),
    await_subscribed(C, 3),
    ok = toroco:inject({range, front}, 0.42),
    ok = toroco:inject({motors, applied}, {100, 100}),
    {ok, #{<<"msg">> := Range}, _} = await_message(C, <<"/range/front">>),
    #{<<"range">> := 0.42, <<"radiation_type">> := 1, <<"max_range">> := 1.5,
      <<"min_range">> := _, <<"field_of_view">> := _, <<"variance">> := _,
      <<"header">> := #{<<"frame_id">> := <<"range_front">>,
                        <<"stamp">> := #{<<"sec">> := _, <<"nanosec">> := _}}} = Range,
    {ok, #{<<"msg">> := #{<<"linear">> := #{<<"x">> := 0.25}, <<"angular">> := #{<<"z">> := Z}}}, _} =
        await_message(C, <<"/toroco/motors/applied">>),
    true = Z == 0,
    T0 = erlang:monotonic_time(millisecond),
    [ok = toroco:inject({s, dist}, I) || I <- lists:seq(1, 50)],
    {ok, _, Seen} = toroco_live_js:await(
                      C, fun(#{<<"ev">> := <<"message">>, <<"msg">> := #{<<"data">> := D}}) ->
                                 #{<<"term">> := T} = jiffy:decode(D, [return_maps]),
                                 T =:= <<"50">>;
                            (_) -> false
                         end, 10000),
    Ms = erlang:monotonic_time(millisecond) - T0,
    Got = [M || #{<<"ev">> := <<"message">>, <<"topic">> := <<"/toroco/out/s/dist">>} = M <- Seen],
    ct:log("50 values in a burst, throttle 300 ms: ~b messages in ~b ms", [length(Got), Ms]),
    true = length(Got) =< 1 + Ms div 300 + 1,
    ok.

cbor_raw() ->
    [{doc, "A cbor-raw subscription (what Foxglove's Rosbridge connection asks for) carries "
      "each message as CDR bytes that @foxglove/rosmsg2-serialization reads back, with the "
      "definition from /rosapi/topics_and_raw_types, to the values the robot emitted"}].
cbor_raw(Config) ->
    C = connect(Config, url),
    %% As torobot_sim publishes a step.
    Snapshot = #{run => cbor_raw, t_ms => 0, arena => {4.0, 3.0}, walls => [], objects => [],
                 robots => [#{name => torobot, pose => {1.25, 0.5, 90.0}, radius => 0.12}]},
    ok = toroco:publish_world(Snapshot),
    await_topic(C, <<"/odom">>),
    [toroco_live_js:send(C, #{cmd => subscribe_raw, topic => T})
     || T <- [<<"/range/front">>, <<"/toroco/motors/applied">>, <<"/toroco/out/s/dist">>, <<"/odom">>]],
    await_subscribed(C, 4),
    ok = toroco:inject({range, front}, 0.37),
    ok = toroco:inject({motors, applied}, {20, 60}),
    ok = toroco:inject({s, dist}, {7, <<"cm">>}),
    Raw = fun(Topic) ->
                  {ok, #{<<"msg">> := M, <<"secs">> := Secs}, _} =
                      toroco_live_js:await(C, fun(#{<<"ev">> := <<"raw_message">>, <<"topic">> := T}) -> T =:= Topic;
                                                 (_) -> false
                                              end, 10000),
                  true = is_integer(Secs),
                  M
          end,
    #{<<"range">> := R, <<"radiation_type">> := 1, <<"variance">> := _,
      <<"header">> := #{<<"frame_id">> := <<"range_front">>, <<"stamp">> := #{<<"sec">> := _}}} =
        Raw(<<"/range/front">>),
    true = abs(R - 0.37) < 1.0e-6,    % float32
    G = toroco_ros_topics:geometry(),
    #{linear := #{x := Vx}, angular := #{z := Wz}} = toroco_ros_topics:wheels_to_twist({20, 60}, G),
    #{<<"linear">> := #{<<"x">> := X}, <<"angular">> := #{<<"z">> := Z}} = Raw(<<"/toroco/motors/applied">>),
    true = abs(X - Vx) < 1.0e-12 andalso abs(Z - Wz) < 1.0e-12,
    #{<<"data">> := Data} = Raw(<<"/toroco/out/s/dist">>),
    #{<<"term">> := <<"{7,<<\"cm\">>}">>} = jiffy:decode(Data, [return_maps]),
    ok = toroco:publish_world(Snapshot#{t_ms => 50}),
    #{<<"header">> := #{<<"frame_id">> := <<"odom">>}, <<"child_frame_id">> := <<"base_link">>,
      <<"pose">> := #{<<"pose">> := #{<<"position">> := #{<<"x">> := 1.25, <<"y">> := 0.5},
                                      <<"orientation">> := #{<<"w">> := Qw}},
                      <<"covariance">> := Cov},
      <<"twist">> := #{<<"covariance">> := [-1 | _] = Cov2}} = Raw(<<"/odom">>),
    true = abs(Qw - math:sqrt(0.5)) < 1.0e-12,
    {36, 36} = {length(Cov), length(Cov2)},
    ok.

fragments_out() ->
    [{doc, "A subscription with fragment_size gets long messages as fragment operations "
      "that join to the publish operation"}].
fragments_out(Config) ->
    C = connect_raw(Config, url, true),
    toroco_live_js:send(C, #{cmd => raw_json, json => #{op => subscribe, id => <<"f1">>,
                                                        topic => <<"/toroco/out/s/dist">>,
                                                        fragment_size => 40}}),
    await_subscriptions(1),
    ok = toroco:inject({s, dist}, <<"a value long enough to need several fragments: ééé"/utf8>>),
    Frags = raw_ops(C, <<"fragment">>, 1),
    [#{<<"total">> := Total}] = Frags,
    All = Frags ++ raw_ops(C, <<"fragment">>, Total - 1),
    Total = length(All),
    true = Total > 2,
    Whole = iolist_to_binary([D || #{<<"data">> := D} <- lists:sort(fun(X, Y) -> maps:get(<<"num">>, X) =< maps:get(<<"num">>, Y) end, All)]),
    #{<<"op">> := <<"publish">>, <<"topic">> := <<"/toroco/out/s/dist">>,
      <<"msg">> := #{<<"data">> := Data}} = jiffy:decode(Whole, [return_maps]),
    #{<<"value">> := <<"a value long enough to need several fragments: ééé"/utf8>>} =
        jiffy:decode(Data, [return_maps]),
    ok.

bad_input() ->
    [{doc, "Malformed JSON, an unknown op, a publish not fitting its type, unknown topics and "
      "services, a compression, a stray service_response and fragments that never complete "
      "each get a status error naming the fault; a message over the limit closes the "
      "connection with a status; the robot delivers throughout"}].
bad_input(Config) ->
    C = connect_raw(Config, token_url, true),
    Bad = [{<<"garbage">>, "not JSON"},
           {<<"{\"op\":\"explode\",\"id\":\"x1\"}">>, "unknown op explode"},
           {<<"{\"op\":\"publish\",\"topic\":\"/cmd_vel\",\"msg\":{\"linear\":{\"x\":\"fast\"}}}">>,
            "field linear.x does not fit"},
           {<<"{\"op\":\"publish\",\"topic\":\"/cmd_vel\",\"msg\":{\"speed\":1}}">>, "field speed"},
           {<<"{\"op\":\"publish\",\"topic\":\"/range/front\",\"msg\":{}}">>, "cannot publish on /range/front"},
           {<<"{\"op\":\"subscribe\",\"topic\":\"/nope\"}">>, "unknown topic /nope"},
           {<<"{\"op\":\"subscribe\",\"topic\":\"/range/front\",\"type\":\"std_msgs/msg/Int8\"}">>,
            "is of type sensor_msgs/msg/Range"},
           {<<"{\"op\":\"call_service\",\"service\":\"/nope\",\"id\":\"c1\"}">>, "unknown service /nope"},
           {<<"{\"op\":\"subscribe\",\"topic\":\"/range/front\",\"compression\":\"png\"}">>,
            "compression png is not supported: none (JSON), cbor or cbor-raw"},
           {<<"{\"op\":\"service_response\",\"id\":\"zz\",\"values\":{}}">>, "calls no client services"},
           {<<"{\"op\":\"set_level\",\"level\":\"loud\"}">>, "unknown level"},
           {<<"{\"op\":\"fragment\",\"id\":\"m1\",\"data\":\"{\\\"op\\\":\",\"num\":0,\"total\":2}">>,
            "never completed"}],
    [toroco_live_js:send(C, #{cmd => raw_text, text => T}) || {T, _} <- Bad],
    Statuses = [S || #{<<"level">> := <<"error">>, <<"msg">> := S} <- raw_ops(C, <<"status">>, length(Bad))],
    [begin
         ct:log("~s~n  -> ~s", [T, S]),
         true = nomatch =/= string:find(S, Want)
     end || {{T, Want}, S} <- lists:zip(Bad, Statuses)],
    %% A message in fragments that do complete is taken like a whole one.
    Sub = <<"{\"op\":\"subscribe\",\"id\":\"s9\",\"topic\":\"/toroco/out/s/dist\"}">>,
    <<P1:10/binary, P2/binary>> = Sub,
    [toroco_live_js:send(C, #{cmd => raw_json, json => #{op => fragment, id => <<"m2">>, data => P,
                                                        num => N, total => 2}})
     || {N, P} <- [{1, P2}, {0, P1}]],
    await_subscriptions(1),
    ok = toroco:inject({s, dist}, 1),
    [#{<<"topic">> := <<"/toroco/out/s/dist">>}] = raw_ops(C, <<"publish">>, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    %% Over the limit: answered, then closed (the rest cannot be read).
    toroco_live_js:send(C, #{cmd => raw_bytes, n => 70000}),
    [#{<<"msg">> := Over}] = raw_ops(C, <<"status">>, 1),
    ct:log("70000 bytes -> ~s", [Over]),
    true = nomatch =/= string:find(Over, "over the limit of 65536 bytes"),
    {ok, #{<<"code">> := 1009}, _} = toroco_live_js:await(C, ev(<<"raw_close">>), 10000),
    ok = toroco:inject({s, dist}, 2),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 2 end, 5000),
    #{device := #{received := 0}} = toroco:inspect(ros),
    ok.

flood_disconnected() ->
    [{doc, "A subscribe/unsubscribe flood is cut at its rate with status errors, the client "
      "that keeps at it is disconnected, /metrics counts it, and the robot delivers throughout"}].
flood_disconnected(Config) ->
    C = connect_raw(Config, url, true),
    [toroco_live_js:send(C, #{cmd => raw_json,
                              json => #{op => Op, id => integer_to_binary(I), topic => <<"/range/front">>}})
     || I <- lists:seq(1, 200), Op <- [subscribe, unsubscribe]],
    {ok, _, Seen} = toroco_live_js:await(C, ev(<<"raw_close">>), 20000),
    [#{<<"code">> := 1008} | _] = lists:reverse(Seen),
    Errors = [S || #{<<"ev">> := <<"raw_text">>, <<"msg">> := #{<<"op">> := <<"status">>, <<"msg">> := S}} <- Seen],
    ct:log("~b status errors, the first: ~s~nthe last: ~s", [length(Errors), hd(Errors), lists:last(Errors)]),
    true = nomatch =/= string:find(hd(Errors), "too many subscribe and unsubscribe operations"),
    true = nomatch =/= string:find(lists:last(Errors), "too many faults: disconnected"),
    ok = toroco:inject({s, dist}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    Metrics = metrics(),
    true = nomatch =/= string:find(Metrics, "toroco_live_rosbridge_total{counter=\"disconnected\"} 1"),
    {match, [Faults]} = re:run(Metrics, "toroco_live_rosbridge_total\\{counter=\"faults\"\\} ([0-9]+)",
                               [{capture, all_but_first, list}]),
    true = list_to_integer(Faults) >= 21,
    ok.

client_that_never_reads() ->
    [{doc, "A client subscribed to a busy topic that never reads stalls only itself: every "
      "value still reaches the actuator, what it missed is counted, another client is served"}].
client_that_never_reads(Config) ->
    Slow = connect_raw(Config, url, false),
    toroco_live_js:send(Slow, #{cmd => raw_json, json => #{op => subscribe, topic => <<"/toroco/out/s/dist">>}}),
    await_subscriptions(1),
    Big = binary:copy(<<"x">>, 8000),
    N = 5000,
    T0 = erlang:monotonic_time(millisecond),
    [ok = toroco:inject({s, dist}, {I, Big}) || I <- lists:seq(1, N)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 20000),
    Ms = erlang:monotonic_time(millisecond) - T0,
    Vs = [I || {d, {I, _}, _} <- toroco_fake_actuator:history(a)],
    Vs = lists:seq(1, N),
    Missed = fun() -> S = toroco_ros_server:stats(),
                      maps:get(dropped, S, 0) + maps:get(tap_dropped, S, 0)
             end,
    ok = toroco_test_lib:wait_until(fun() -> Missed() > 0 end, 10000, nothing_missed),
    Dropped = Missed(),
    ct:log("~b values of 8 kB through the robot in ~b ms with a client that never reads; "
           "~b messages not sent to it", [N, Ms, Dropped]),
    true = Dropped > 0,
    C = connect(Config, url),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/toroco/out/s/dist">>}),
    await_subscribed(C, 1),
    %% The client that never reads may be gone by now: a send blocked for the
    %% send timeout (5 s) ends its connection. Every client still there,
    %% the new one among them, has its subscription.
    toroco_test_lib:wait_until(
      fun() -> case toroco_ros_server:stats() of
                   #{clients := K, subscriptions := K} -> K >= 1;
                   _ -> false
               end
      end, 10000, every_client_subscribed),
    ct:log("clients left: ~b", [maps:get(clients, toroco_ros_server:stats())]),
    ok = toroco:inject({s, dist}, last),
    {ok, #{<<"msg">> := #{<<"data">> := D}}, _} = await_message(C, <<"/toroco/out/s/dist">>),
    #{<<"term">> := <<"last">>} = jiffy:decode(D, [return_maps]),
    toroco_live_js:stop(Slow),
    ok.

not_a_websocket() ->
    [{doc, "A plain HTTP request on the server's port gets 400 and a line saying what the port is"}].
not_a_websocket(Config) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, ?config(port, Config), [binary, {active, false}]),
    ok = gen_tcp:send(S, <<"GET / HTTP/1.1\r\nHost: x\r\n\r\n">>),
    {ok, <<"HTTP/1.1 400", _/binary>> = R} = gen_tcp:recv(S, 0, 5000),
    true = nomatch =/= binary:match(R, <<"rosbridge v2">>),
    gen_tcp:close(S).

start_options() ->
    [{doc, "toroco_live:info/0 shows the rosbridge port; a bad rosbridge option or a port "
      "already taken is refused naming it; start/1 leaves it off by default"}].
start_options(Config) ->
    Port = ?config(port, Config),
    #{rosbridge := Port} = toroco_live:info(),
    toroco_live:stop(),
    {error, {bad_option, {rosbridge, fast}}} = toroco_live:start(#{http => 0, rosbridge => fast}),
    {ok, #{rosbridge := off}} = toroco_live:start(#{http => 0, foxglove => off}),
    off = toroco_ros_server:port(),
    toroco_live:stop(),
    %% A port already taken: refused naming the server, nothing left running.
    {ok, L} = gen_tcp:listen(0, [{ip, {127, 0, 0, 1}}]),
    {ok, Taken} = inet:port(L),
    {error, {rosbridge, {listen, eaddrinuse}}} =
        toroco_live:start(#{http => 0, foxglove => off, rosbridge => Taken}),
    not_running = toroco_live:info(),
    gen_tcp:close(L),
    ok.

server_goes_with_the_application() ->
    [{doc, "The server is a static child of toroco_ros_sup: stopping toroco_ros leaves the "
      "dashboard running and rosbridge off (client mode not_started); starting it again "
      "listens on the option's port at once; toroco_live:stop/0 leaves the child without a "
      "process"}].
server_goes_with_the_application(_Config) ->
    ok = application:stop(toroco_ros),
    try
        #{rosbridge := off, http := Http} = toroco_live:info(),
        true = is_integer(Http),
        error = toroco_live_extensions:find(bridge, rosbridge),
        {error, not_started} = toroco_live:rosbridge_connect("ws://127.0.0.1:1/", #{}),
        [] = toroco_live:rosbridge_clients()
    after
        {ok, _} = application:ensure_all_started(toroco_ros)
    end,
    #{rosbridge := Port} = toroco_live:info(),
    true = is_integer(Port),
    [{toroco_ros_client_sup, _, supervisor, _}, {toroco_ros_server, Pid, worker, _}] =
        lists:sort(supervisor:which_children(toroco_ros_sup)),
    true = is_pid(Pid),
    toroco_live:stop(),
    [{toroco_ros_server, undefined, worker, _}] =
        [C || C = {toroco_ros_server, _, _, _} <- supervisor:which_children(toroco_ros_sup)],
    off = toroco_ros:port(),
    ok.

lockstep_stimulus() ->
    [{doc, "In lockstep a Twist handed to a tick as the ros device's stimulus reaches the "
      "wiring as {Left, Right} at that tick, in the trace; a live publish is taken too"}].
lockstep_stimulus(_Config) ->
    ok = toroco_clock:lockstep(#{trace => true}),
    try
        Twist = #{<<"linear">> => #{<<"x">> => 0.125}},
        {ok, Lines} = toroco_clock:tick(100, [toroco_ros_device:stimulus(ros, Twist)]),
        [{v, {50, 50}, _}] = toroco_fake_actuator:history(cmd),
        Trace = iolist_to_binary(Lines),
        ct:log("~s", [Trace]),
        true = nomatch =/= binary:match(Trace, <<"cmd_vel">>),
        %% A live publish arrives when it arrives, and is taken.
        ok = toroco_ros_device:publish(ros, cmd_vel, #{angular => #{z => 1.0}}),
        ok = toroco_clock:settle(),
        {ok, _} = toroco_clock:tick(200, []),
        [{v, {50, 50}, _}, {v, {-40, 40}, _}] = toroco_fake_actuator:history(cmd)
    after
        toroco_clock:realtime()
    end,
    ok.

simulated_range_and_odometry() ->
    [{doc, "While the teleop robot's world runs, a subscription gets sensor_msgs/msg/Range "
      "from its range sensors and nav_msgs/msg/Odometry of its pose, every field there"}].
simulated_range_and_odometry(Config) ->
    %% Long enough for a loaded machine to start roslib, subscribe and drive
    %% before the world ends.
    run_world(Config, 20),
    C = connect(Config, token_url),
    await_topic(C, <<"/odom">>),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/odom">>, type => <<"nav_msgs/msg/Odometry">>}),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/range/rear">>, type => <<"sensor_msgs/msg/Range">>}),
    await_subscribed(C, 2),
    {ok, #{<<"msg">> := Odom}, _} = await_message(C, <<"/odom">>),
    %% A range sensor emits when its reading changes: moving on changes the rear one's.
    toroco_live_js:send(C, #{cmd => drive, topic => <<"/cmd_vel">>, type => ?TWIST,
                             msg => #{linear => #{x => 0.1}}, hz => 10, ms => 1000}),
    {ok, #{<<"msg">> := Range}, _} = await_message(C, <<"/range/rear">>),
    ct:log("odom: ~p~nrange: ~p", [Odom, Range]),
    #{<<"header">> := #{<<"frame_id">> := <<"odom">>}, <<"child_frame_id">> := <<"base_link">>,
      <<"pose">> := #{<<"pose">> := #{<<"position">> := #{<<"x">> := X, <<"y">> := Y},
                                      <<"orientation">> := #{<<"w">> := _}},
                      <<"covariance">> := Cov},
      <<"twist">> := #{<<"twist">> := #{<<"linear">> := _}, <<"covariance">> := Cov2}} = Odom,
    true = abs(X - 1.0) < 0.01 andalso abs(Y - 1.5) < 0.01,
    {36, 36} = {length(Cov), length(Cov2)},
    %% The rear sensor looks back along -x at the wall from about x = 1.
    #{<<"range">> := R, <<"max_range">> := 1.5, <<"header">> := #{<<"frame_id">> := <<"range_rear">>}} = Range,
    true = R > 0 andalso R =< 1.5,
    sim_done().

drive_the_teleop_robot() ->
    [{doc, "A roslib client publishing Twist on /cmd_vel at 10 Hz drives the teleop robot in "
      "its world: forward moves it along +x, turning changes its heading, and it stops "
      "within 500 ms of the last command"}].
drive_the_teleop_robot(Config) ->
    run_world(Config, 25),
    C = connect(Config, token_url),
    await_topic(C, <<"/odom">>),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/odom">>, type => <<"nav_msgs/msg/Odometry">>}),
    {ok, #{<<"msg">> := Odom0}, _} = await_message(C, <<"/odom">>),
    {X0, Y0, H0} = pose(Odom0),
    drive(C, #{linear => #{x => 0.2}}, 2000),
    {X1, Y1, H1} = latest_pose(C),
    ct:log("forward 2 s at 0.2 m/s: ~p -> ~p",
           [{X0, Y0, H0}, {X1, Y1, H1}]),
    true = X1 - X0 > 0.25 andalso abs(Y1 - Y0) < 0.05 andalso abs(H1 - H0) < 5,
    LastMs = drive(C, #{angular => #{z => 1.0}}, 1500),
    %% Until the robot has stood still for a second.
    {StopMs, {X2, Y2, H2}} = stopped(C, 1000),
    ct:log("turn 1.5 s at 1 rad/s: heading ~p -> ~p, at ~p; stopped ~b ms "
           "after the last command", [H1, H2, {X2, Y2}, StopMs - LastMs]),
    true = abs(H2 - H1) > 45,
    true = abs(X2 - X1) < 0.05,
    true = StopMs - LastMs =< 500,
    sim_done().

runtime_restart() ->
    [{doc, "A subscribed client keeps getting the robot's messages after the runtime restarts "
      "under the server (the server takes the tap again)"}].
runtime_restart(Config) ->
    C = connect(Config, url),
    toroco_live_js:send(C, #{cmd => subscribe, topic => <<"/range/front">>,
                             type => <<"sensor_msgs/msg/Range">>}),
    await_subscribed(C, 1),
    ok = toroco:inject({range, front}, 0.5),
    {ok, _, _} = await_message(C, <<"/range/front">>),
    ok = application:stop(toroco_hw),
    ok = application:stop(toroco),
    {ok, _} = application:ensure_all_started(toroco_hw),
    fake_robot(),
    %% Until the server has the tap again, a value reaches nobody.
    Again = fun() ->
                    ok = toroco:inject({range, front}, 0.25),
                    case toroco_live_js:await(C, fun(#{<<"ev">> := <<"message">>,
                                                       <<"msg">> := #{<<"range">> := R}}) -> R == 0.25;
                                                    (_) -> false
                                                 end, 300) of
                        {ok, _, _} -> true;
                        {error, _} -> false
                    end
            end,
    ok = toroco_test_lib:wait_until(Again, 15000, no_message_after_restart).

%%====================================================================
%% Shared by the cases
%%====================================================================

%% roslib's driver, trusting the test CA in the group `tls'.
driver(Config) ->
    case proplists:get_value(tls, Config) of
        undefined -> toroco_live_js:start("ros_driver.js");
        #{ca := Ca} -> toroco_live_js:start("ros_driver.js", [{"NODE_EXTRA_CA_CERTS", Ca}])
    end.

connect(Config, Which) ->
    C = driver(Config),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"ready">>), 10000),
    toroco_live_js:send(C, #{cmd => connect, url => ?config(Which, Config)}),
    {ok, _, _} = await(C, <<"open">>),
    C.

connect_raw(Config, Which, Read) ->
    C = driver(Config),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"ready">>), 10000),
    toroco_live_js:send(C, #{cmd => raw_connect, url => ?config(Which, Config), read => Read}),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"raw_open">>), 10000),
    C.

ev(Name) -> fun(#{<<"ev">> := E}) -> E =:= Name end.

await(C, Name) -> toroco_live_js:await(C, ev(Name), 10000).

%% N subscriptions made by the client, and at least N in the server, so
%% that the case's events find them there.
await_subscribed(C, N) ->
    [{ok, _, _} = await(C, <<"subscribed">>) || _ <- lists:seq(1, N)],
    await_subscriptions(N).

%% The server holds at least N subscriptions (of any client to any topic).
await_subscriptions(N) ->
    toroco_test_lib:wait_until(
      fun() -> maps:get(subscriptions, toroco_ros_server:stats(), 0) >= N end,
      10000, {subscriptions, N}).

await_message(C, Topic) ->
    toroco_live_js:await(C, fun(#{<<"ev">> := <<"message">>, <<"topic">> := T}) -> T =:= Topic;
                               (_) -> false
                            end, 10000).

%% The next N raw operations `Op' the server sent, in order.
raw_ops(_C, _Op, 0) -> [];
raw_ops(C, Op, N) ->
    {ok, #{<<"msg">> := M}, _} =
        toroco_live_js:await(C, fun(#{<<"ev">> := <<"raw_text">>, <<"msg">> := #{<<"op">> := O}}) -> O =:= Op;
                                   (_) -> false
                                end, 10000),
    [M | raw_ops(C, Op, N - 1)].

%% Until getTopics lists Topic (the world's first snapshot came).
await_topic(C, Topic) ->
    Listed = fun() ->
                     toroco_live_js:send(C, #{cmd => getTopics}),
                     {ok, #{<<"topics">> := Ts}, _} = await(C, <<"topics">>),
                     lists:member(Topic, Ts)
             end,
    case toroco_test_lib:poll(Listed, 10000, 200) of
        ok -> ok;
        timeout -> ct:fail({never_listed, Topic})
    end.

%% The teleop robot in its world, for DurationS simulated seconds, in real time.
run_world(Config, DurationS) ->
    Root = root(),
    World = filename:join(?config(priv_dir, Config), "teleop.world"),
    {ok, Text} = file:read_file(filename:join(Root, "config/worlds/teleop.world")),
    ok = file:write_file(World, re:replace(Text, "\\{duration_s, *[0-9]+\\}",
                                           io_lib:format("{duration_s, ~b}", [DurationS]))),
    Wiring = filename:join(Root, "config/robots/teleop.wiring"),
    Self = self(),
    Pid = spawn(fun() -> Self ! {sim_done, torobot_sim:run(World, #{wiring => Wiring})} end),
    register(rosbridge_suite_sim, Pid),
    ok.

%% The run is over (its devices gone) before the next case.
sim_done() ->
    receive {sim_done, R} -> {ok, _} = R, ok
    after 40000 -> ct:fail(sim_not_done)
    end.

root() ->
    toroco_test_lib:root().

%% Publishes Msg on /cmd_vel at 10 Hz for Ms; the wall-clock ms of the last.
drive(C, Msg, Ms) ->
    toroco_live_js:send(C, #{cmd => drive, topic => <<"/cmd_vel">>, type => ?TWIST, msg => Msg,
                             hz => 10, ms => Ms}),
    {ok, #{<<"n">> := N, <<"last_ms">> := Last}, _} = toroco_live_js:await(C, ev(<<"drove">>), Ms + 10000),
    true = N >= Ms div 100 - 1,
    Last.

pose(#{<<"pose">> := #{<<"pose">> := #{<<"position">> := #{<<"x">> := X, <<"y">> := Y},
                                       <<"orientation">> := #{<<"z">> := Z, <<"w">> := W}}}}) ->
    {X, Y, 2 * math:atan2(Z, W) * 180 / math:pi()}.

stamp_ms(#{<<"header">> := #{<<"stamp">> := #{<<"sec">> := S, <<"nanosec">> := N}}}) ->
    S * 1000 + N div 1000000.

%% The pose of the next /odom message.
latest_pose(C) ->
    {ok, #{<<"msg">> := M}, _} = await_message(C, <<"/odom">>),
    pose(M).

%% Reads /odom until the pose has not changed for HoldMs: the stamp (ms)
%% from which it stood still, and the pose.
stopped(C, HoldMs) ->
    {ok, #{<<"msg">> := M}, _} = await_message(C, <<"/odom">>),
    stopped(C, HoldMs, stamp_ms(M), pose(M)).

stopped(C, HoldMs, Since, Pose) ->
    {ok, #{<<"msg">> := M}, _} = await_message(C, <<"/odom">>),
    P = pose(M),
    T = stamp_ms(M),
    case same(P, Pose) of
        true when T - Since >= HoldMs -> {Since, Pose};
        true -> stopped(C, HoldMs, Since, Pose);
        false -> stopped(C, HoldMs, T, P)
    end.

same({X1, Y1, H1}, {X2, Y2, H2}) ->
    abs(X1 - X2) < 1.0e-4 andalso abs(Y1 - Y2) < 1.0e-4 andalso abs(H1 - H2) < 0.01.

metrics() ->
    {Mod, S} = case toroco_live:info() of
                   #{http := Http, tls := true} ->
                       {ok, _} = application:ensure_all_started(ssl),
                       {ok, T} = ssl:connect({127, 0, 0, 1}, Http, [binary, {active, false},
                                                                   {verify, verify_none}]),
                       {ssl, T};
                   #{http := Http} ->
                       {ok, T} = gen_tcp:connect({127, 0, 0, 1}, Http, [binary, {active, false}]),
                       {gen_tcp, T}
               end,
    ok = Mod:send(S, <<"GET /metrics HTTP/1.0\r\n\r\n">>),
    Body = recv_all(Mod, S, []),
    Mod:close(S),
    Body.

recv_all(Mod, S, Acc) ->
    case Mod:recv(S, 0, 5000) of
        {ok, B} -> recv_all(Mod, S, [Acc, B]);
        {error, closed} -> binary_to_list(iolist_to_binary(Acc))
    end.
