%% The robot as ROS 2 messages (toroco_ros_topics), pure: the wheel geometry
%% both ways, every message complete for its type, the topics of a wiring.
-module(toroco_ros_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [twist_wheels_round_trip, twist_checked_against_its_type, messages_have_every_field,
     topics_of_a_wiring, geometry_from_env, stamps, definitions, cbor_vectors, cdr_layout].

twist_wheels_round_trip() ->
    [{doc, "Wheels -> Twist -> wheels gives the same servo units; forward is +x, left wheel "
      "slower turns left (+z); out-of-range commands clamp to -100..100"}].
twist_wheels_round_trip(_Config) ->
    G = toroco_ros_topics:geometry(),
    #{wheel_base := 0.2, max_wheel_speed := 0.25} = G,
    [{ok, W} = toroco_ros_topics:twist_to_wheels(toroco_ros_topics:wheels_to_twist(W, G), G)
     || W <- [{0, 0}, {100, 100}, {-100, -100}, {50, -50}, {-30, 70}, {1, 0}, {100, -100}]],
    #{linear := #{x := 0.25}, angular := #{z := +0.0}} = toroco_ros_topics:wheels_to_twist({100, 100}, G),
    #{linear := #{x := X}, angular := #{z := Z}} = toroco_ros_topics:wheels_to_twist({20, 60}, G),
    true = X > 0 andalso Z > 0,
    {ok, {100, 100}} = toroco_ros_topics:twist_to_wheels(
                         #{<<"linear">> => #{<<"x">> => 5.0}}, G),
    {ok, {-40, 40}} = toroco_ros_topics:twist_to_wheels(
                        #{<<"angular">> => #{<<"z">> => 1.0}}, G),
    {ok, {-100, 100}} = toroco_ros_topics:twist_to_wheels(#{angular => #{z => 50}}, G),
    ok.

twist_checked_against_its_type() ->
    [{doc, "A message that does not fit geometry_msgs/msg/Twist is an error naming the field"}].
twist_checked_against_its_type(_Config) ->
    G = toroco_ros_topics:geometry(),
    {error, {bad_field, <<"linear.x">>}} =
        toroco_ros_topics:twist_to_wheels(#{<<"linear">> => #{<<"x">> => <<"fast">>}}, G),
    {error, {bad_field, <<"linear.w">>}} =
        toroco_ros_topics:twist_to_wheels(#{<<"linear">> => #{<<"w">> => 1}}, G),
    {error, {bad_field, <<"speed">>}} = toroco_ros_topics:twist_to_wheels(#{<<"speed">> => 1}, G),
    {error, {bad_field, <<"angular">>}} = toroco_ros_topics:twist_to_wheels(#{<<"angular">> => 3}, G),
    {error, not_a_message} = toroco_ros_topics:twist_to_wheels([1, 2], G),
    {error, {unknown_type, <<"foo/msg/Bar">>}} = toroco_ros_topics:normalise({<<"foo/msg/Bar">>, #{}}),
    ok.

messages_have_every_field() ->
    [{doc, "Every message made (Twist, Odometry, Range, String) has exactly the fields of its "
      "ROS 2 type, each of the field's type (36 covariances, Range's limits, ...)"}].
messages_have_every_field(_Config) ->
    T = 1700000000123456789,
    Msgs = toroco_ros_topics:of_event({emit, T, {motors, applied}, send, {40, 60}})
        ++ toroco_ros_topics:of_event({emit, T, {range, front}, send, 0.42})
        ++ toroco_ros_topics:of_event({emit, T, {cruise, motors}, set, {80, 80}})
        ++ toroco_ros_topics:of_world(#{robots => [#{name => torobot, pose => {1.0, 2.0, 90.0}}]}, T),
    [<<"geometry_msgs/msg/Twist">>, <<"sensor_msgs/msg/Range">>, <<"std_msgs/msg/String">>,
     <<"nav_msgs/msg/Odometry">>] = [Type || {_, Type, _} <- Msgs],
    [complete(Type, Msg) || {_, Type, Msg} <- Msgs],
    [{<<"/toroco/motors/applied">>, _, _}, {<<"/range/front">>, _, Range},
     {<<"/toroco/out/cruise/motors">>, _, #{data := Data}}, {<<"/odom">>, _, Odom}] = Msgs,
    #{range := 0.42, radiation_type := 1, max_range := 1.5,
      header := #{stamp := #{sec := 1700000000, nanosec := 123456789},
                  frame_id := <<"range_front">>}} = Range,
    #{<<"kind">> := <<"set">>, <<"value">> := [80, 80], <<"term">> := <<"{80,80}">>} =
        jiffy:decode(Data, [return_maps]),
    #{header := #{frame_id := <<"odom">>}, child_frame_id := <<"base_link">>,
      pose := #{pose := #{position := #{x := 1.0, y := 2.0}, orientation := #{z := Qz, w := Qw}}}} = Odom,
    true = abs(Qz - math:sqrt(0.5)) < 1.0e-9 andalso abs(Qw - math:sqrt(0.5)) < 1.0e-9,
    %% the same map is what rosbridge sends
    _ = [jiffy:encode(M) || {_, _, M} <- Msgs],
    [] = toroco_ros_topics:of_event({emit, T, {ros, cmd_vel}, send, {1, 1}}),
    [] = toroco_ros_topics:of_event({emit, T, {range, front}, unset, none}),
    [] = toroco_ros_topics:of_event({deliver, T, {motors, setvel}, {1, 1}}),
    ok.

%% Msg has every field of Type and nothing else, each of its field's type.
complete(Type, Msg) ->
    Fields = toroco_ros_topics:fields(Type),
    Names = lists:sort([N || {N, _} <- Fields]),
    Names = lists:sort(maps:keys(Msg)),
    [ok = fits(FT, maps:get(N, Msg)) || {N, FT} <- Fields],
    {ok, Msg} = toroco_ros_topics:normalise({Type, Msg}),
    ok.

fits(T, V) when T =:= float64; T =:= float32 -> true = is_float(V), ok;
fits(string, V) -> true = is_binary(V), ok;
fits({array, E, N}, L) -> N = length(L), [ok = fits(E, X) || X <- L], ok;
fits(T, V) when is_binary(T) -> complete(T, V);
fits(_, V) -> true = is_integer(V), ok.

topics_of_a_wiring() ->
    [{doc, "A wiring's outputs become topics with their ROS 2 types; /cmd_vel is inbound; "
      "/odom only while a world runs"}].
topics_of_a_wiring(_Config) ->
    Outs = [{cruise, motors}, {motors, applied}, {range, front}, {range, left}, {ros, cmd_vel},
            {bumper, contact}],
    Topics = toroco_ros_topics:topics(#{outputs => Outs, world => true}),
    #{<<"/cmd_vel">> := {<<"geometry_msgs/msg/Twist">>, in},
      <<"/odom">> := {<<"nav_msgs/msg/Odometry">>, out},
      <<"/toroco/motors/applied">> := {<<"geometry_msgs/msg/Twist">>, out},
      <<"/range/front">> := {<<"sensor_msgs/msg/Range">>, out},
      <<"/range/left">> := {<<"sensor_msgs/msg/Range">>, out},
      <<"/toroco/out/cruise/motors">> := {<<"std_msgs/msg/String">>, out},
      <<"/toroco/out/bumper/contact">> := {<<"std_msgs/msg/String">>, out}} = Map =
        maps:from_list([{T, {Ty, D}} || #{topic := T, type := Ty, dir := D} <- Topics]),
    7 = map_size(Map),
    false = lists:member(<<"/odom">>, [T || #{topic := T} <- toroco_ros_topics:topics(
                                                                #{outputs => Outs, world => false})]),
    ok.

geometry_from_env() ->
    [{doc, "ros_geometry in the app env overrides the Torobot's wheel geometry; bad values are ignored"}].
geometry_from_env(_Config) ->
    application:set_env(toroco_ros, ros_geometry, #{wheel_base => 0.5, max_wheel_speed => -1}),
    try
        #{wheel_base := 0.5, max_wheel_speed := 0.25} = toroco_ros_topics:geometry()
    after
        application:unset_env(toroco_ros, ros_geometry)
    end,
    ok.

stamps() ->
    [{doc, "Times in ns become sec and nanosec with nanosec in 0..1e9-1, before 1970 too"}].
stamps(_Config) ->
    #{sec := 1, nanosec := 5} = toroco_ros_topics:stamp(1000000005),
    #{sec := -1, nanosec := 999999999} = toroco_ros_topics:stamp(-1),
    #{sec := 0, nanosec := 0} = toroco_ros_topics:stamp(0),
    ok.

definitions() ->
    [{doc, "A type's message definition lists its fields in order, then each type it uses "
      "once, after the separator and MSG: line ROS 2 tools write"}].
definitions(_Config) ->
    Odom = toroco_ros_topics:definition(<<"nav_msgs/msg/Odometry">>),
    [Own | Deps] = binary:split(Odom, <<"\n", (binary:copy(<<"=">>, 80))/binary, "\nMSG: ">>, [global]),
    <<"std_msgs/Header header\nstring child_frame_id\n"
      "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist">> =
        string:trim(Own),
    Names = [hd(binary:split(D, <<"\n">>)) || D <- Deps],
    true = length(Names) =:= length(lists:usort(Names)),   % each once
    [<<"builtin_interfaces/Time">>, <<"geometry_msgs/Point">>, <<"geometry_msgs/Pose">>,
     <<"geometry_msgs/PoseWithCovariance">>, <<"geometry_msgs/Quaternion">>, <<"geometry_msgs/Twist">>,
     <<"geometry_msgs/TwistWithCovariance">>, <<"geometry_msgs/Vector3">>, <<"std_msgs/Header">>] =
        lists:sort(Names),
    true = nomatch =/= binary:match(Odom, <<"float64[36] covariance">>),
    <<"std_msgs/Header header\nuint8 ULTRASOUND=0\nuint8 INFRARED=1\n", _/binary>> =
        toroco_ros_topics:definition(<<"sensor_msgs/msg/Range">>),
    <<"string data\n">> = toroco_ros_topics:definition(<<"std_msgs/msg/String">>),
    ok.

cbor_vectors() ->
    [{doc, "CBOR encodes as RFC 8949's examples: small and large integers, negatives, "
      "floats as 64-bit, text and byte strings, arrays, maps, true and null"}].
cbor_vectors(_Config) ->
    E = fun toroco_ros_cbor:encode/1,
    <<16#00>> = E(0), <<16#17>> = E(23), <<16#18, 16#18>> = E(24), <<16#19, 16#03, 16#e8>> = E(1000),
    <<16#1a, 16#00, 16#0f, 16#42, 16#40>> = E(1000000), <<16#20>> = E(-1), <<16#38, 16#63>> = E(-100),
    <<16#fb, 16#3f, 16#f1, 16#99, 16#99, 16#99, 16#99, 16#99, 16#9a>> = E(1.1),
    <<16#61, $a>> = E(<<"a">>), <<16#41, 1>> = E({bytes, <<1>>}),
    <<16#83, 1, 2, 3>> = E([1, 2, 3]), <<16#a1, 16#61, $a, 1>> = E(#{a => 1}),
    <<16#f5>> = E(true), <<16#f6>> = E(null), <<16#63, "ros">> = E(ros),
    ok.

cdr_layout() ->
    [{doc, "CDR: the little-endian encapsulation header, primitives aligned to their size "
      "from the start of the data, strings with their length and NUL"}].
cdr_layout(_Config) ->
    {ok, <<0, 1, 0, 0, 3:32/little, "hi", 0>>} =
        toroco_ros_msgs:cdr(<<"std_msgs/msg/String">>, #{data => <<"hi">>}),
    G = toroco_ros_topics:geometry(),
    {ok, <<0, 1, 0, 0, X:64/float-little, 0:64, 0:64, 0:64, 0:64, Z:64/float-little>>} =
        toroco_ros_msgs:cdr(<<"geometry_msgs/msg/Twist">>, toroco_ros_topics:wheels_to_twist({50, 100}, G)),
    #{linear := #{x := X}, angular := #{z := Z}} = toroco_ros_topics:wheels_to_twist({50, 100}, G),
    [{_, _, Range}] = toroco_ros_topics:of_event({emit, 1000000002, {range, front}, send, 0.5}),
    %% stamp (8), frame_id "range_front" (4 + 12), radiation_type (1), 3 bytes of padding,
    %% then five float32.
    {ok, <<0, 1, 0, 0, 1:32/little, 2:32/little, 12:32/little, "range_front", 0, 1, 0, 0, 0,
           _Fov:32/float-little, _Min:32/float-little, _Max:32/float-little, R:32/float-little,
           0:32>>} = toroco_ros_msgs:cdr(<<"sensor_msgs/msg/Range">>, Range),
    true = R == 0.5,
    ok.
