%% The Foxglove bridge against the protocol's reference client
%% (@foxglove/ws-protocol's FoxgloveClient, in Node), on a node with fake
%% devices: s (a sensor, output dist) wired to a (an actuator, input d).
-module(toroco_live_foxglove_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [server_info_and_channels, values_in_order, channels_follow_wiring, connection_graph,
     publish_refused_when_off, publish_injects_when_on, misbehaving_client,
     client_that_never_reads, not_a_websocket, simulated_world, runtime_restart,
     tap_closed_with_every_event, {group, tls}].

%% The bridge's clients again with TLS on the port (wss://, Foxglove's
%% client trusting a test CA made at the group's start).
groups() ->
    [{tls, [], [server_info_and_channels, misbehaving_client, client_that_never_reads]}].

init_per_group(tls, Config) ->
    [{tls, tl_tls:make(?config(priv_dir, Config))} | Config].

end_per_group(tls, _Config) ->
    ok.

suite() -> [{timetrap, {seconds, 60}}].

%% Nothing on the default ports: each case starts on free ones.
init_per_suite(Config) ->
    [{env, tl_live:start(#{})} | Config].

end_per_suite(Config) ->
    tl_live:stop(?config(env, Config)).

init_per_testcase(Case, Config) ->
    tl_live:fake_robot(),
    ok = application:set_env(toroco_live, client_publish, Case =:= publish_injects_when_on),
    {Tls, Scheme} = case proplists:get_value(tls, Config) of
                        undefined -> {#{}, "ws://127.0.0.1"};
                        T -> {#{tls => tl_tls:tls(T)}, "wss://localhost"}
                    end,
    {ok, #{foxglove := Port}} = toroco_live:start(Tls#{http => 0, foxglove => 0}),
    Transcript = filename:join(?config(priv_dir, Config), atom_to_list(Case) ++ ".jsonl"),
    toroco_live_js:transcript(Transcript),
    [{port, Port}, {url, iolist_to_binary(io_lib:format("~s:~b/", [Scheme, Port]))} | Config].

%% The Node clients end with the case's process (their stdin closes).
end_per_testcase(_Case, _Config) ->
    toroco_live:stop(),
    application:set_env(toroco_live, client_publish, false),
    [toroco:remove_device(D) || D <- [s, a, b]],
    ok.

%%====================================================================
%% Cases
%%====================================================================

tap_closed_with_every_event() ->
    [{doc, "A bridge's tap closed at its shutdown (toroco_rec_tap:close/1) hands over every "
      "event emitted before, in order, to be passed on before the bridge closes."}].
tap_closed_with_every_event(_Config) ->
    {ok, Tap} = toroco_rec_tap:on(toroco_rec_tap:new(#{kinds => [emit], names => [s]})),
    [ok = toroco:inject({s, dist}, I) || I <- lists:seq(1, 200)],
    {Events, Closed} = toroco_rec_tap:close(Tap),
    false = toroco_rec_tap:subscribed(Closed),
    Values = [V || {emit, _, {s, dist}, send, V} <- Events],
    Values = lists:seq(1, 200).

server_info_and_channels() ->
    [{doc, "The client gets serverInfo (connectionGraph, no clientPublish by default) and "
      "the channels of SPEC 12, JSON with a valid JSON Schema each"}].
server_info_and_channels(Config) ->
    C = connect(Config),
    {ok, #{<<"info">> := Info}, _} = toroco_live_js:await(C, ev(<<"serverInfo">>), 10000),
    [<<"connectionGraph">>] = maps:get(<<"capabilities">>, Info),
    Topics = [<<"/toroco/out/s/dist">>, <<"/toroco/in/a/d">>, <<"/toroco/router/a/d">>,
              <<"/toroco/lifecycle">>],
    Channels = await_topics(C, Topics),
    [#{<<"encoding">> := <<"json">>, <<"schemaEncoding">> := <<"jsonschema">>,
       <<"schemaValid">> := true} = maps:get(T, Channels) || T <- Topics],
    #{<<"schemaName">> := <<"toroco.Output">>} = maps:get(<<"/toroco/out/s/dist">>, Channels),
    #{<<"schemaName">> := <<"toroco.Router">>} = maps:get(<<"/toroco/router/a/d">>, Channels),
    ok.

values_in_order() ->
    [{doc, "Values the fake sensor emits reach a subscribed client in order, with their "
      "terms and increasing nanosecond timestamps, on the output and the input's channels"}].
values_in_order(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>, <<"/toroco/in/a/d">>]),
    subscribe(C, <<"/toroco/out/s/dist">>),
    subscribe(C, <<"/toroco/in/a/d">>),
    N = 100,
    Values = [{I, <<"cm">>, [near, 1.5]} || I <- lists:seq(1, N)],
    [ok = toroco:inject({s, dist}, V) || V <- Values],
    All = messages(C, [<<"/toroco/out/s/dist">>, <<"/toroco/in/a/d">>], 2 * N),
    Out = [M || M = #{<<"topic">> := <<"/toroco/out/s/dist">>} <- All],
    Terms = [toroco_rec_json:term_text(V) || V <- Values],
    Terms = [T || #{<<"data">> := #{<<"term">> := T}} <- Out],
    [#{<<"data">> := #{<<"kind">> := <<"send">>, <<"value">> := [1, <<"cm">>, [<<"near">>, 1.5]]}} | _] = Out,
    Stamps = [binary_to_integer(S) || #{<<"timestamp">> := S} <- Out],
    Stamps = lists:sort(Stamps),
    In = [M || M = #{<<"topic">> := <<"/toroco/in/a/d">>} <- All],
    Terms = [T || #{<<"data">> := #{<<"term">> := T}} <- In],
    ok.

channels_follow_wiring() ->
    [{doc, "A device added and wired is advertised; removed, it is unadvertised"}].
channels_follow_wiring(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    ok = toroco:add_device(b, toroco_fake_sensor, #{outputs => [bump]}),
    await_topics(C, [<<"/toroco/out/b/bump">>]),
    ok = toroco:remove_device(b),
    {ok, _, _} = toroco_live_js:await(
                   C, fun(#{<<"ev">> := <<"unadvertise">>, <<"topics">> := Ts}) ->
                              lists:member(<<"/toroco/out/b/bump">>, Ts);
                         (_) -> false
                      end, 10000),
    ok.

connection_graph() ->
    [{doc, "connectionGraph: the sensor publishes its output's topic, the actuator subscribes it"}].
connection_graph(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    toroco_live_js:send(C, #{cmd => subscribeGraph}),
    {ok, #{<<"graph">> := G}, _} = toroco_live_js:await(C, ev(<<"graph">>), 10000),
    Pub = maps:from_list([{N, Ids} || #{<<"name">> := N, <<"publisherIds">> := Ids}
                                          <- maps:get(<<"publishedTopics">>, G)]),
    Sub = maps:from_list([{N, Ids} || #{<<"name">> := N, <<"subscriberIds">> := Ids}
                                          <- maps:get(<<"subscribedTopics">>, G)]),
    [<<"s">>] = maps:get(<<"/toroco/out/s/dist">>, Pub),
    [<<"a">>] = maps:get(<<"/toroco/out/s/dist">>, Sub),
    ok.

publish_refused_when_off() ->
    [{doc, "Without clientPublish in the node's configuration, a client's advertise and "
      "publish get status errors and nothing reaches the robot"}].
publish_refused_when_off(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    toroco_live_js:send(C, #{cmd => advertise, topic => <<"/toroco/out/s/dist">>}),
    {ok, #{<<"message">> := M}, _} = toroco_live_js:await(C, ev(<<"status">>), 10000),
    true = nomatch =/= string:find(M, "clientPublish is off"),
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/toroco/out/s/dist">>,
                             message => #{term => <<"{7, far}">>}}),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"status">>), 10000),
    [] = toroco_fake_actuator:history(a),
    ok.

publish_injects_when_on() ->
    [{doc, "With clientPublish on, a published {\"term\": ...} on an output or an input "
      "becomes toroco:inject/2 with the literal read, never evaluated"}].
publish_injects_when_on(Config) ->
    C = connect(Config),
    {ok, #{<<"info">> := Info}, _} = toroco_live_js:await(C, ev(<<"serverInfo">>), 10000),
    true = lists:member(<<"clientPublish">>, maps:get(<<"capabilities">>, Info)),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    toroco_live_js:send(C, #{cmd => advertise, topic => <<"/toroco/out/s/dist">>}),
    toroco_live_js:send(C, #{cmd => advertise, topic => <<"/toroco/in/a/d">>}),
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/toroco/out/s/dist">>,
                             message => #{term => <<"{7, far, <<\"x\">>}">>}}),
    ok = toroco_fake_actuator:await(a, fun(H) -> [V || {d, V, _} <- H] =:= [{7, far, <<"x">>}] end, 5000),
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/toroco/in/a/d">>,
                             message => #{term => <<"#{speed => 3}">>}}),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:member(#{speed => 3}, [V || {d, V, _} <- H]) end, 5000),
    %% An expression is not a literal: refused, not evaluated.
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/toroco/out/s/dist">>,
                             message => #{term => <<"erlang:halt()">>}}),
    {ok, #{<<"message">> := M}, _} = toroco_live_js:await(C, ev(<<"status">>), 10000),
    true = nomatch =/= string:find(M, "bad_term"),
    2 = length(toroco_fake_actuator:history(a)),
    ok.

misbehaving_client() ->
    [{doc, "Garbage frames, unknown ops, unknown channels and bad binary messages get status "
      "errors, a client that keeps at it is disconnected, and the robot is unaffected"}].
misbehaving_client(Config) ->
    C = connect_raw(Config, true),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"raw_open">>), 10000),
    Bad = [{raw_text, <<"garbage">>}, {raw_text, <<"{\"op\":\"explode\"}">>},
           {raw_text, <<"[1,2,3]">>},
           {raw_text, <<"{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":1,\"channelId\":99999}]}">>},
           {raw_text, <<"{\"op\":\"unsubscribe\",\"subscriptionIds\":[42]}">>},
           {raw_hex, <<"ff00">>}, {raw_hex, <<"0101000000">>}],
    [toroco_live_js:send(C, #{cmd => Cmd, text => B, hex => B}) || {Cmd, B} <- Bad],
    Statuses = statuses(C, length(Bad)),
    [2] = lists:usort([L || #{<<"level">> := L} <- Statuses]),
    %% The robot runs on meanwhile.
    ok = toroco:inject({s, dist}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    %% Keep at it and be disconnected.
    [toroco_live_js:send(C, #{cmd => raw_text, text => <<"nonsense">>}) || _ <- lists:seq(1, 30)],
    {ok, #{<<"code">> := 1008}, _} = toroco_live_js:await(C, ev(<<"raw_close">>), 10000),
    ok = toroco:inject({s, dist}, 2),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 2 end, 5000),
    ok.

client_that_never_reads() ->
    [{doc, "A client subscribed to everything that never reads stalls only itself: every "
      "value still reaches the actuator, and another client is still served"}].
client_that_never_reads(Config) ->
    Slow = connect_raw(Config, false),
    {ok, _, _} = toroco_live_js:await(Slow, ev(<<"raw_open">>), 10000),
    %% The channels came before it stopped reading: it subscribes to them all.
    {ok, _, _} = toroco_live_js:await(Slow, fun(#{<<"ev">> := <<"raw_text">>,
                                                  <<"msg">> := #{<<"op">> := <<"advertise">>}}) -> true;
                                               (_) -> false
                                            end, 10000),
    Before = subscriptions(),
    toroco_live_js:send(Slow, #{cmd => raw_subscribe_all}),
    {ok, #{<<"count">> := Count}, _} = toroco_live_js:await(Slow, ev(<<"raw_subscribed">>), 10000),
    true = Count > 0,
    ok = toroco_test_lib:wait_until(fun() -> subscriptions() >= Before + Count end, 10000,
                                    {subscribed, Count}),
    Big = binary:copy(<<"x">>, 2000),
    N = 5000,
    T0 = erlang:monotonic_time(millisecond),
    [ok = toroco:inject({s, dist}, {I, Big}) || I <- lists:seq(1, N)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 20000),
    Ms = erlang:monotonic_time(millisecond) - T0,
    ct:log("~b values of 2 kB through the robot in ~b ms with a client that never reads", [N, Ms]),
    Vs = [I || {d, {I, _}, _} <- toroco_fake_actuator:history(a)],
    Vs = lists:seq(1, N),
    %% Another client is still served.
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    subscribe(C, <<"/toroco/out/s/dist">>),
    ok = toroco:inject({s, dist}, last),
    [#{<<"data">> := #{<<"term">> := <<"last">>}}] = messages(C, [<<"/toroco/out/s/dist">>], 1),
    toroco_live_js:stop(Slow),
    ok.

not_a_websocket() ->
    [{doc, "A plain HTTP request on the bridge's port gets 400 and a line saying what the port is"}].
not_a_websocket(Config) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, ?config(port, Config), [binary, {active, false}]),
    ok = gen_tcp:send(S, <<"GET / HTTP/1.1\r\nHost: x\r\n\r\n">>),
    {ok, <<"HTTP/1.1 400", _/binary>> = R} = gen_tcp:recv(S, 0, 5000),
    true = nomatch =/= binary:match(R, <<"foxglove.websocket.v1">>),
    gen_tcp:close(S).

simulated_world() ->
    [{doc, "World snapshots appear as foxglove.FrameTransform and foxglove.SceneUpdate "
      "channels, so the 3D panel draws the robot in its arena"}].
simulated_world(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/lifecycle">>]),
    Snapshot = #{run => test, t_ms => 0, arena => {6.0, 4.0}, walls => [{{1.0, 1.0}, {1.0, 2.5}}],
                 objects => [{red, {4.5, 2.0}, 0.1}],
                 robots => [#{name => torobot, pose => {1.5, 2.0, 90.0}, radius => 0.1}]},
    %% As torobot_sim publishes each step.
    ok = toroco:publish_world(Snapshot),
    Chs = await_topics(C, [<<"/toroco/sim/pose">>, <<"/toroco/sim/scene">>]),
    #{<<"schemaName">> := <<"foxglove.FrameTransform">>} = maps:get(<<"/toroco/sim/pose">>, Chs),
    #{<<"schemaName">> := <<"foxglove.SceneUpdate">>} = maps:get(<<"/toroco/sim/scene">>, Chs),
    subscribe(C, <<"/toroco/sim/pose">>),
    subscribe(C, <<"/toroco/sim/scene">>),
    %% A ball more: the scene changed, so it comes again with the pose.
    ok = toroco:publish_world(
           Snapshot#{t_ms => 50, objects => [{blue, {3.0, 2.2}, 0.1} | maps:get(objects, Snapshot)]}),
    Ms = messages(C, [<<"/toroco/sim/pose">>, <<"/toroco/sim/scene">>], 2),
    [#{<<"data">> := #{<<"child_frame_id">> := <<"torobot">>,
                       <<"translation">> := #{<<"x">> := 1.5, <<"y">> := Y},
                       <<"rotation">> := #{<<"w">> := W}}}] =
        [M || M = #{<<"topic">> := <<"/toroco/sim/pose">>} <- Ms],
    true = Y == 2 andalso abs(W - math:cos(math:pi() / 4)) < 1.0e-9,
    [#{<<"data">> := #{<<"entities">> := [#{<<"frame_id">> := <<"arena">>, <<"cubes">> := Walls,
                                            <<"cylinders">> := [_, _]},
                                          #{<<"frame_id">> := <<"torobot">>, <<"frame_locked">> := true,
                                            <<"arrows">> := [_]}]}}] =
        [M || M = #{<<"topic">> := <<"/toroco/sim/scene">>} <- Ms],
    5 = length(Walls),
    ok.

runtime_restart() ->
    [{doc, "A connected client keeps getting values after the runtime restarts under the bridge"}].
runtime_restart(Config) ->
    C = connect(Config),
    await_topics(C, [<<"/toroco/out/s/dist">>]),
    subscribe(C, <<"/toroco/out/s/dist">>),
    ok = application:stop(toroco_hw),
    ok = application:stop(toroco),
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [dist]}),
    %% The same topic, re-advertised or kept, carries the new sensor's values.
    Got = fun Loop(N) when N > 0 ->
                  ok = toroco:inject({s, dist}, again),
                  case toroco_live_js:await(C, fun(#{<<"ev">> := <<"message">>, <<"data">> := #{<<"term">> := T}}) ->
                                                        T =:= <<"again">>;
                                                   (#{<<"ev">> := <<"advertise">>, <<"channels">> := Chs}) ->
                                                        [toroco_live_js:send(C, #{cmd => subscribe, topic => Tp})
                                                         || #{<<"topic">> := Tp = <<"/toroco/out/s/dist">>} <- Chs],
                                                        false;
                                                   (_) -> false
                                                end, 500) of
                      {ok, _, _} -> true;
                      {error, _} -> Loop(N - 1)
                  end;
              Loop(_) -> false
          end,
    true = Got(20),
    ok.

%%====================================================================
%% Helpers
%%====================================================================

%% Foxglove's driver, trusting the test CA in the group `tls'.
driver(Config) ->
    case proplists:get_value(tls, Config) of
        undefined -> toroco_live_js:start("fox_driver.js");
        #{ca := Ca} -> toroco_live_js:start("fox_driver.js", [{"NODE_EXTRA_CA_CERTS", Ca}])
    end.

connect(Config) ->
    C = driver(Config),
    toroco_live_js:send(C, #{cmd => connect, url => ?config(url, Config)}),
    C.

connect_raw(Config, Read) ->
    C = driver(Config),
    toroco_live_js:send(C, #{cmd => raw_connect, url => ?config(url, Config), read => Read}),
    C.

ev(Name) -> fun(#{<<"ev">> := E}) -> E =:= Name end.

%% Waits until every topic is advertised; returns topic => channel.
await_topics(C, Topics) ->
    await_topics(C, Topics, #{}).

await_topics(C, Topics, Acc) ->
    case Topics -- maps:keys(Acc) of
        [] -> Acc;
        _ ->
            {ok, #{<<"channels">> := Chs}, _} = toroco_live_js:await(C, ev(<<"advertise">>), 10000),
            await_topics(C, Topics, maps:merge(Acc, maps:from_list([{T, Ch} || Ch = #{<<"topic">> := T} <- Chs])))
    end.

%% Subscribed, and the subscription in the bridge before the case makes events.
subscribe(C, Topic) ->
    Before = subscriptions(),
    toroco_live_js:send(C, #{cmd => subscribe, topic => Topic}),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"subscribed">>), 10000),
    ok = toroco_test_lib:wait_until(fun() -> subscriptions() > Before end, 10000,
                                    {subscribed, Topic}).

subscriptions() ->
    maps:get(subscriptions, toroco_live_foxglove:stats(), 0).

%% The next N messages on any of Topics, in the order they came.
messages(C, Topics, N) ->
    messages(C, Topics, N, []).

messages(_C, _Topics, 0, Acc) -> lists:reverse(Acc);
messages(C, Topics, N, Acc) ->
    {ok, M, _} = toroco_live_js:await(C, fun(#{<<"ev">> := <<"message">>, <<"topic">> := T}) ->
                                                 lists:member(T, Topics);
                                            (_) -> false
                                         end, 10000),
    messages(C, Topics, N - 1, [M | Acc]).

statuses(_C, 0) -> [];
statuses(C, N) ->
    {ok, #{<<"msg">> := S}, _} =
        toroco_live_js:await(C, fun(#{<<"ev">> := <<"raw_text">>, <<"msg">> := #{<<"op">> := <<"status">>}}) -> true;
                                   (_) -> false
                                end, 10000),
    [S | statuses(C, N - 1)].
