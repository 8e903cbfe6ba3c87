%% The ROS 2 message types (toroco_ros_msgs), pure code, checked with the
%% reference ROS 2 libraries in Node (@foxglove/rosmsg,
%% @foxglove/rosmsg2-serialization).
-module(toroco_ros_msgs_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [ros_definitions_parse, ros_cdr_as_reference, ros_cdr_errors].

ros_definitions_parse() ->
    [{doc, "Every type's ros2msg definition parses with @foxglove/rosmsg (ros2) into the type "
      "and each of its dependencies once, after 80 '=' and a 'MSG: pkg/Type' line"}].
ros_definitions_parse(_Config) ->
    ok = toroco_live_js:ensure_installed(),
    Types = toroco_ros_msgs:types(),
    #{<<"cases">> := Results} = check_ros(ros_cases(<<>>)),
    Parsed = maps:from_list([{T, P} || #{<<"type">> := T, <<"parsed">> := P} <- Results]),
    [] = Types -- maps:keys(Parsed),
    [<<>>, <<"std_msgs/Header">>, <<"builtin_interfaces/Time">>,
     <<"geometry_msgs/PoseWithCovariance">>, <<"geometry_msgs/Pose">>, <<"geometry_msgs/Point">>,
     <<"geometry_msgs/Quaternion">>, <<"geometry_msgs/TwistWithCovariance">>,
     <<"geometry_msgs/Twist">>, <<"geometry_msgs/Vector3">>] =
        maps:get(<<"nav_msgs/msg/Odometry">>, Parsed),
    [<<>>, <<"std_msgs/Header">>, <<"builtin_interfaces/Time">>] =
        maps:get(<<"sensor_msgs/msg/Range">>, Parsed),
    {ok, Def} = toroco_ros_msgs:definition(<<"geometry_msgs/msg/Twist">>),
    [<<"geometry_msgs/Vector3 linear">>, <<"geometry_msgs/Vector3 angular">>, Sep,
     <<"MSG: geometry_msgs/Vector3">> | _] = binary:split(Def, <<"\n">>, [global]),
    Sep = binary:copy(<<"=">>, 80),
    ok.

ros_cdr_as_reference() ->
    [{doc, "Every type's CDR bytes decode with @foxglove/rosmsg2-serialization's MessageReader "
      "to the values encoded and equal its MessageWriter's bytes, for strings of every "
      "length modulo 8 before the aligned fields"}].
ros_cdr_as_reference(_Config) ->
    ok = toroco_live_js:ensure_installed(),
    %% MessageWriter 3.1 counts a string's UTF-16 units, not its bytes: a
    %% text beyond ASCII is checked by decoding only.
    Utf8 = #{type => <<"std_msgs/msg/String">>, writer => false,
             definition => <<"string data\n">>, msg => #{data => <<"{\"é☃\":1}"/utf8>>},
             cdr => base64:encode(element(2, toroco_ros_msgs:cdr(<<"std_msgs/msg/String">>,
                                                                      #{data => <<"{\"é☃\":1}"/utf8>>})))},
    Cases = [Utf8 | lists:append([ros_cases(binary:copy(<<"f">>, N)) || N <- lists:seq(0, 8)])],
    #{<<"cases">> := Results} = check_ros(Cases),
    N = length(Cases),
    N = length(Results),
    [] = [R || R <- Results, maps:is_key(<<"error">>, R)],
    [] = [{T, L} || #{<<"type">> := T, <<"same_bytes">> := Same, <<"length">> := L} <- Results,
                    Same =/= true, Same =/= null],
    [] = [{T, Msg, Decoded} || {#{type := T, msg := Msg}, #{<<"decoded">> := Decoded}}
                                   <- lists:zip(Cases, Results), not same(Msg, Decoded)],
    ct:log("~b messages of ~b types, bytes: ~p", [length(Results), length(toroco_ros_msgs:types()),
                                                 lists:usort([{T, L} || #{<<"type">> := T, <<"length">> := L} <- Results])]),
    ok.

ros_cdr_errors() ->
    [{doc, "An unknown type, a missing field (named by its path), a value its field cannot "
      "hold and a string with a NUL are errors naming the culprit; a String reads back, "
      "and bytes that are not one are an error"}].
ros_cdr_errors(_Config) ->
    {error, {unknown_type, <<"nav_msgs/msg/Path">>}} = toroco_ros_msgs:cdr(<<"nav_msgs/msg/Path">>, #{}),
    {error, {unknown_type, x}} = toroco_ros_msgs:definition(x),
    Twist = ros_sample(<<"geometry_msgs/msg/Twist">>, <<>>),
    {error, {missing_field, <<"geometry_msgs/msg/Vector3">>, [angular, z]}} =
        toroco_ros_msgs:cdr(<<"geometry_msgs/msg/Twist">>,
                                 Twist#{angular := maps:remove(z, maps:get(angular, Twist))}),
    {error, {bad_value, [linear, x], <<"fast">>}} =
        toroco_ros_msgs:cdr(<<"geometry_msgs/msg/Twist">>,
                                 Twist#{linear := #{x => <<"fast">>, y => 0, z => 0}}),
    Range = ros_sample(<<"sensor_msgs/msg/Range">>, <<"ir">>),
    {error, {bad_value, [radiation_type], 256}} =
        toroco_ros_msgs:cdr(<<"sensor_msgs/msg/Range">>, Range#{radiation_type := 256}),
    {error, {bad_value, [header, frame_id], <<"a", 0>>}} =
        toroco_ros_msgs:cdr(<<"sensor_msgs/msg/Range">>,
                                 Range#{header := #{stamp => #{sec => 0, nanosec => 0},
                                                    frame_id => <<"a", 0>>}}),
    {error, {bad_value, [covariance], [1.0]}} =
        toroco_ros_msgs:cdr(<<"geometry_msgs/msg/PoseWithCovariance">>,
                                 (ros_sample(<<"geometry_msgs/msg/PoseWithCovariance">>, <<>>))#{covariance := [1.0]}),
    {error, {bad_value, [], not_a_map}} = toroco_ros_msgs:cdr(<<"std_msgs/msg/String">>, not_a_map),
    %% extra keys are not the encoder's business
    {ok, _} = toroco_ros_msgs:cdr(<<"std_msgs/msg/String">>, #{data => <<"x">>, other => 1}),
    %% a String read back, and bytes that are not one
    [{ok, D} = toroco_ros_msgs:string_data(element(2, toroco_ros_msgs:cdr(<<"std_msgs/msg/String">>, #{data => D})))
     || D <- [<<>>, <<"{}">>, <<"{\"é\":1}"/utf8>>, binary:copy(<<"x">>, 1000)]],
    [error = toroco_ros_msgs:string_data(B)
     || B <- [<<>>, <<0, 1, 0, 0>>, <<0, 1, 0, 0, 5:32/little, "ab">>, <<0, 1, 0, 0, 0:32>>,
              <<0, 1, 0, 0, 3:32/little, "abc">>, crypto:strong_rand_bytes(3)]],
    ok.

%% One case per type, `Frame' as every string.
ros_cases(Frame) ->
    [#{type => T, definition => element(2, toroco_ros_msgs:definition(T)),
       cdr => base64:encode(element(2, toroco_ros_msgs:cdr(T, M))), msg => M}
     || T <- toroco_ros_msgs:types(), M <- [ros_sample(T, Frame)]].

%% A message of each type; float32 fields hold values a float32 holds exactly.
ros_sample(<<"builtin_interfaces/msg/Time">>, _) -> #{sec => 1764115200, nanosec => 999999999};
ros_sample(<<"std_msgs/msg/Header">>, F) ->
    #{stamp => ros_sample(<<"builtin_interfaces/msg/Time">>, F), frame_id => F};
ros_sample(<<"std_msgs/msg/String">>, F) -> #{data => <<F/binary, "{\"a\":1}">>};
ros_sample(<<"geometry_msgs/msg/Vector3">>, _) -> #{x => math:pi(), y => -1.0e-300, z => 7};
ros_sample(<<"geometry_msgs/msg/Point">>, _) -> #{x => 1.25, y => -2.5, z => 0};
ros_sample(<<"geometry_msgs/msg/Quaternion">>, _) -> #{x => 0, y => 0, z => 0.3826834323650898, w => 0.9238795325112867};
ros_sample(<<"geometry_msgs/msg/Pose">>, F) ->
    #{position => ros_sample(<<"geometry_msgs/msg/Point">>, F),
      orientation => ros_sample(<<"geometry_msgs/msg/Quaternion">>, F)};
ros_sample(<<"geometry_msgs/msg/Twist">>, F) ->
    #{linear => ros_sample(<<"geometry_msgs/msg/Vector3">>, F),
      angular => #{x => 0.0, y => 0.0, z => -0.5}};
ros_sample(<<"geometry_msgs/msg/PoseWithCovariance">>, F) ->
    #{pose => ros_sample(<<"geometry_msgs/msg/Pose">>, F), covariance => [I / 8 || I <- lists:seq(1, 36)]};
ros_sample(<<"geometry_msgs/msg/TwistWithCovariance">>, F) ->
    #{twist => ros_sample(<<"geometry_msgs/msg/Twist">>, F), covariance => [-1.0 | lists:duplicate(35, 0.0)]};
ros_sample(<<"nav_msgs/msg/Odometry">>, F) ->
    #{header => ros_sample(<<"std_msgs/msg/Header">>, F), child_frame_id => <<F/binary, "base_link">>,
      pose => ros_sample(<<"geometry_msgs/msg/PoseWithCovariance">>, F),
      twist => ros_sample(<<"geometry_msgs/msg/TwistWithCovariance">>, F)};
ros_sample(<<"sensor_msgs/msg/Range">>, F) ->
    #{header => ros_sample(<<"std_msgs/msg/Header">>, F), radiation_type => 1, field_of_view => 0.046875,
      min_range => 0.015625, max_range => 1.5, range => 0.375, variance => 0}.

check_ros(Cases) ->
    File = filename:join(filename:basedir(user_cache, "toroco_live_test"),
                         "ros_cases_" ++ os:getpid() ++ ".json"),
    ok = filelib:ensure_dir(File),
    ok = file:write_file(File, jiffy:encode(Cases)),
    try
        #{<<"ok">> := true} = toroco_live_js:run("ros_msgs.js", [File])
    after
        file:delete(File)
    end.

%% An Erlang message and what the reference decoder made of it.
same(M, D) when is_map(M), is_map(D) ->
    lists:all(fun({K, V}) -> same(V, maps:get(atom_to_binary(K), D, missing)) end, maps:to_list(M));
same(L, D) when is_list(L), is_list(D), length(L) =:= length(D) ->
    lists:all(fun({A, B}) -> same(A, B) end, lists:zip(L, D));
same(A, B) when is_number(A), is_number(B) -> A == B;
same(A, B) -> A =:= B.
