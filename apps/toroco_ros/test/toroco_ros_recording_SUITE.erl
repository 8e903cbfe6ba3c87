%% The ROS 2 recording profile (SPEC §15, `toroco_ros_profile' through
%% `toroco_live:record/2'), read back as ROS 2 tooling reads it: @mcap/core,
%% @foxglove/rosmsg and @foxglove/rosmsg2-serialization.
-module(toroco_ros_recording_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [ros2_recording_of_simulated_run, ros2_recording_of_range, ros2_recording_replays,
     ros2_profile_goes_with_the_application].

suite() -> [{timetrap, {seconds, 90}}].

init_per_suite(Config) ->
    LogDir = filename:join(?config(priv_dir, Config), "log"),
    [{log_dir, LogDir}, {env, tl_live:start(#{log_dir => LogDir}, [toroco_ros])} | Config].

end_per_suite(Config) ->
    tl_live:stop(?config(env, Config)).

init_per_testcase(ros2_recording_of_range, Config) ->
    tl_live:fake_robot(),
    Config;
init_per_testcase(_Case, Config) ->
    Config.

end_per_testcase(_Case, _Config) ->
    _ = toroco_live:stop_recording(),
    _ = toroco_clock:realtime(),
    toroco_test_lib:clear().

ros2_profile_goes_with_the_application() ->
    [{doc, "The profile ros2 is there while toroco_ros runs, and refused once it stopped"}].
ros2_profile_goes_with_the_application(Config) ->
    Path = path(Config, "gone.mcap"),
    {ok, toroco_ros_profile} = toroco_rec_profile:find(ros2),
    ok = application:stop(toroco_ros),
    try
        {error, {bad_option, {profile, ros2}}} = toroco_live:record(Path, #{profile => ros2}),
        false = filelib:is_file(Path)
    after
        {ok, _} = application:ensure_all_started(toroco_ros)
    end.

ros2_recording_replays() ->
    [{doc, "A ros2-profile recording of a simulated run replays like the default one: the "
      "sensors' Strings re-emitted, the motors' deliveries matching the recording"}].
ros2_recording_replays(Config) ->
    World = short_world(),
    Path = path(Config, "sim_ros2_replay.mcap"),
    ok = toroco_live:record(Path, #{profile => ros2}),
    {ok, _} = torobot_sim:run(World, #{wiring => tl_live:wiring_file()}),
    ok = tl_live:settle_robot(),
    {ok, #{dropped := 0}} = toroco_live:stop_recording(),
    tl_live:replays_on_fakes(Path, tl_live:wiring_file()).

ros2_recording_of_simulated_run() ->
    [{doc, "A ros2-profile recording of a simulated run reads back as ROS 2 data: profile "
      "ros2, ros2msg schemas, cdr messages, every one decoded by the reference ROS 2 "
      "libraries to what the run emitted (Twist of the motors, Odometry of the world, "
      "String of the other outputs), counted as stop_recording/0 says"}].
ros2_recording_of_simulated_run(Config) ->
    World = short_world(),
    Path = path(Config, "sim_ros2.mcap"),
    ok = toroco_live:record(Path, #{profile => ros2}),
    {ok, Tap} = toroco:subscribe_events(#{kinds => [emit], buffer => 1000000}),
    {ok, Summary} = torobot_sim:run(World, #{wiring => tl_live:wiring_file()}),
    {ok, #{messages := M, dropped := 0, unencodable := 0}} = toroco_live:stop_recording(),
    Emitted = drain_tap(Tap),
    ok = toroco:unsubscribe_events(Tap),
    #{trajectories := Trails} = toroco_live_world:latest(),
    R = read_ros2(Path),
    ct:log("run ~p: ~b messages in ~b bytes, ~p", [Summary, M, filelib:file_size(Path),
                                                    maps:get(<<"perTopic">>, R)]),
    #{<<"profile">> := <<"ros2">>, <<"messages">> := M, <<"statistics">> := M,
      <<"perTopic">> := PerTopic, <<"decoded">> := Decoded, <<"channels">> := Channels} = R,
    [{<<"cdr">>, <<"ros2msg">>}] =
        lists:usort([{E, SE} || #{<<"encoding">> := E, <<"schemaEncoding">> := SE} <- Channels]),
    Types = maps:from_list([{T, S} || #{<<"topic">> := T, <<"schema">> := S} <- Channels]),
    #{<<"/toroco/motors/applied">> := <<"geometry_msgs/msg/Twist">>,
      <<"/odom">> := <<"nav_msgs/msg/Odometry">>,
      <<"/toroco/out/ir/left">> := <<"std_msgs/msg/String">>,
      <<"/toroco/in/motors/setvel">> := <<"std_msgs/msg/String">>,
      <<"/toroco/lifecycle">> := <<"std_msgs/msg/String">>} = Types,
    %% Every output's messages are what the run emitted, in order, at the
    %% emission's time: the typed ones and the String ones.
    Expected = lists:foldr(fun({T, Topic, Msg}, Acc) ->
                                   maps:update_with(Topic, fun(L) -> [{T, Msg} | L] end, [{T, Msg}], Acc)
                           end, #{}, [{T, Topic, Msg} || {emit, T, _, _, _} = E <- Emitted,
                                                       {Topic, _, Msg} <- toroco_ros_topics:of_event(E)]),
    OutTopics = [T || T <- maps:keys(PerTopic), T =/= <<"/odom">>,
                      nomatch =:= binary:match(T, [<<"/toroco/in/">>, <<"/toroco/router/">>,
                                                   <<"/toroco/lifecycle">>])],
    [] = OutTopics -- maps:keys(Expected),
    [] = maps:keys(Expected) -- OutTopics,
    [begin
         Want = maps:get(Topic, Expected),
         Got = [{binary_to_integer(T), Msg} || #{<<"t">> := T, <<"msg">> := Msg} <- maps:get(Topic, Decoded)],
         N = length(Want),
         N = length(Got),
         N = maps:get(Topic, PerTopic),
         [] = [{Topic, W, G} || {{Tw, W}, {Tg, G}} <- lists:zip(Want, Got), not (Tw =:= Tg andalso same(W, G))]
     end || Topic <- OutTopics],
    true = maps:get(<<"/toroco/motors/applied">>, PerTopic) > 0,
    %% The odometry is the world's pose: each one a point of the trajectory.
    Poses = [{X, Y} || #{<<"msg">> := #{<<"header">> := #{<<"frame_id">> := <<"odom">>},
                                       <<"child_frame_id">> := <<"base_link">>,
                                       <<"pose">> := #{<<"pose">> := #{<<"position">> := #{<<"x">> := X, <<"y">> := Y}}}}}
                           <- maps:get(<<"/odom">>, Decoded)],
    true = length(Poses) > 10,
    Points = lists:append([[{Px, Py} || {Px, Py, _} <- Trail] || Trail <- maps:values(Trails)]),
    [] = [P || P <- Poses, not lists:any(fun(Q) -> same(Q, P) end, Points)],
    %% The rest is §12's JSON in a String.
    [#{<<"msg">> := #{<<"data">> := Delivery}} | _] = maps:get(<<"/toroco/in/motors/setvel">>, Decoded),
    #{<<"term">> := _, <<"value">> := _} = jiffy:decode(Delivery, [return_maps]),
    ok.

ros2_recording_of_range() ->
    [{doc, "A range device's readings are recorded as sensor_msgs/msg/Range on /range/<output>, "
      "stamped with the emission's time, and a message its type does not take is left "
      "out and counted, not written"}].
ros2_recording_of_range(Config) ->
    ok = toroco:add_device(range, toroco_fake_sensor, #{outputs => [front]}),
    ok = toroco:add_device(b, toroco_fake_actuator, #{inputs => [d]}),
    ok = toroco:set_inputs(b, #{d => [{range, front}]}),
    Path = path(Config, "range.mcap"),
    ok = toroco_live:record(Path, #{profile => ros2, kinds => [emit], names => [range]}),
    {ok, Tap} = toroco:subscribe_events(#{kinds => [emit], names => [range]}),
    Values = [0.375, 1.25, 0.5],
    [ok = toroco:inject({range, front}, V) || V <- Values],
    ok = toroco_fake_actuator:await(b, fun(H) -> length(H) =:= 3 end, 5000),
    {ok, #{messages := 3, unencodable := 0}} = toroco_live:stop_recording(),
    Times = [T || {emit, T, _, _, _} <- drain_tap(Tap)],
    ok = toroco:unsubscribe_events(Tap),
    #{<<"ok">> := true, <<"profile">> := <<"ros2">>, <<"perTopic">> := PerTopic,
      <<"decoded">> := #{<<"/range/front">> := Got}, <<"channels">> := [Channel]} = read_ros2(Path),
    #{<<"/range/front">> := 3} = PerTopic,
    #{<<"schema">> := <<"sensor_msgs/msg/Range">>} = Channel,
    [{V, T} = {Range, binary_to_integer(LogT)} || {V, T, #{<<"t">> := LogT, <<"msg">> := #{<<"range">> := Range}}}
                                                     <- lists:zip3(Values, Times, Got)],
    [#{<<"header">> := #{<<"frame_id">> := <<"range_front">>, <<"stamp">> := #{<<"sec">> := Sec, <<"nanosec">> := Ns}},
       <<"radiation_type">> := 1} | _] = [Msg || #{<<"msg">> := Msg} <- Got],
    true = Sec * 1000000000 + Ns =:= hd(Times),
    ok.

drain_tap(Tap) ->
    receive {toroco_event, Tap, Event} -> [Event | drain_tap(Tap)]
    after 300 -> []
    end.

%% An Erlang message and what the reference decoder made of it (a float32
%% field as its float32).
same(M, D) when is_map(M), is_map(D) ->
    lists:all(fun({K, V}) -> same(V, maps:get(atom_to_binary(K), D, missing)) end, maps:to_list(M));
same(T, D) when is_tuple(T), is_tuple(D) -> same(tuple_to_list(T), tuple_to_list(D));
same(L, D) when is_list(L), is_list(D), length(L) =:= length(D) ->
    lists:all(fun({A, B}) -> same(A, B) end, lists:zip(L, D));
same(A, B) when is_number(A), is_number(B) -> A == B orelse as_float32(A) == B;
same(A, B) -> A =:= B.

%% A float32 field holds the nearest float32.
as_float32(A) ->
    <<F:32/float>> = <<A:32/float>>,
    F.

read_ros2(Path) ->
    #{<<"ok">> := true} = R = toroco_live_js:run("mcap_ros2_read.js", [Path]),
    R.

path(Config, Name) -> filename:join(?config(priv_dir, Config), Name).

short_world() -> tl_live:data("../../toroco_rec/test/toroco_rec_SUITE_data/short.world").
