%% @doc The robot as ROS 2 topics (SPEC §15): which topics it has, their
%% ROS 2 types, and the ROS 2 message each tap event (SPEC §10) and each
%% world snapshot (`toroco_live_world') becomes. The rosbridge server
%% (`toroco_ros_server') encodes these messages as JSON, a ros2
%% recording as CDR: a message is an Erlang map with atom keys named as the
%% ROS 2 fields, numbers as integers or floats, strings as binaries, and
%% every field of its type present. Pure except {@link topics/0} and
%% {@link geometry/0}, which read the running wiring and the app env.
%%
%% | topic                            | type                       | dir | from |
%% |----------------------------------|----------------------------|-----|------|
%% | `/cmd_vel'                       | `geometry_msgs/msg/Twist'  | in  | source `{ros, cmd_vel}' (`toroco_ros_device') |
%% | `/toroco/motors/applied'         | `geometry_msgs/msg/Twist'  | out | output `{motors, applied}' |
%% | `/odom'                          | `nav_msgs/msg/Odometry'    | out | the simulated world's snapshots |
%% | `/range/<output>'                | `sensor_msgs/msg/Range'    | out | each output of the device named `range' |
%% | `/toroco/out/<emitter>/<output>' | `std_msgs/msg/String'      | out | every other output; `data' is SPEC §12's JSON |
%%
%% <h3>Wheel geometry</h3>
%% Wheel velocities are servo units, -100..100 = -`max_wheel_speed'..
%% `max_wheel_speed' m/s (as the simulated world moves the robot). A
%% differential drive: `linear.x = (Vl + Vr) / 2', `angular.z = (Vr - Vl) /
%% wheel_base'; the other components are 0 going out and ignored coming in
%% (the robot cannot move sideways). {@link twist_to_wheels/2} rounds each
%% wheel to an integer servo unit and clamps it to -100..100.
%%
%% <h3>Frames and stamps</h3>
%% `/odom': `header.frame_id' `odom' (the arena: origin at its bottom-left
%% corner, x right, y up), `child_frame_id' `base_link' (with several robots
%% `<robot>/base_link', one message per robot per step). The simulated pose is
%% exact, so the pose covariance is all zeros; the snapshot carries no
%% velocity, so `twist' is zero with its covariance's first element -1
%% (ROS's "not provided"): `/toroco/motors/applied' has the command.
%% `/range/<name>': `header.frame_id' `range_<name>', `radiation_type'
%% `INFRARED' (1: time-of-flight light), `field_of_view', `min_range' and
%% `max_range' from the app env `ros_range' (defaults 0.05 rad, 0.02 m,
%% 1.5 m: the simulated sensor's defaults), `variance' 0 (the field ROS 2
%% Jazzy added). Stamps are the event's `T' (ns; simulated time in a
%% lockstep run) as `builtin_interfaces/msg/Time' `#{sec, nanosec}'.
-module(toroco_ros_topics).

-export([geometry/0, wheels_to_twist/2, twist_to_wheels/2]).
-export([topics/0, topics/1, of_event/1, event_topic/1, of_world/1, of_world/2]).
-export([types/0, type_of/1, fields/1, definition/1, normalise/1, stamp/1]).

-export_type([geometry/0, topic/0, message/0]).

-type geometry() :: #{wheel_base := float(), max_wheel_speed := float()}.
-type topic() :: #{topic := binary(), type := binary(), dir := out | in}.
-type message() :: #{atom() => term()}.

-define(TWIST, <<"geometry_msgs/msg/Twist">>).
-define(ODOMETRY, <<"nav_msgs/msg/Odometry">>).
-define(RANGE, <<"sensor_msgs/msg/Range">>).
-define(STRING, <<"std_msgs/msg/String">>).
-define(INFRARED, 1).

%% The name of the device whose outputs are inbound topics, and the one
%% whose outputs are range sensors.
-define(ROS_DEVICE, ros).
-define(RANGE_DEVICE, range).

%%====================================================================
%% Wheel geometry
%%====================================================================

%% @doc The robot's wheel geometry: the Torobot's (`wheel_base' 0.20 m,
%% `max_wheel_speed' 0.25 m/s) with the app env `toroco_ros' `ros_geometry'
%% (a map with either key) over it.
-spec geometry() -> geometry().
geometry() ->
    Defaults = #{wheel_base => 0.20, max_wheel_speed => 0.25},
    Env = case application:get_env(toroco_ros, ros_geometry, #{}) of
              #{} = M -> maps:with([wheel_base, max_wheel_speed], M);
              _ -> #{}
          end,
    maps:map(fun(_, V) -> float(V) end,
             maps:merge(Defaults, maps:filter(fun(_, V) -> is_number(V) andalso V > 0 end, Env))).

%% @doc The Twist of wheel velocities `{Left, Right}' (servo units).
-spec wheels_to_twist({number(), number()}, geometry()) -> message().
wheels_to_twist({L, R}, #{wheel_base := Base, max_wheel_speed := Vmax})
  when is_number(L), is_number(R) ->
    Vl = clamp(L) / 100 * Vmax,
    Vr = clamp(R) / 100 * Vmax,
    twist((Vl + Vr) / 2, (Vr - Vl) / Base).

%% @doc The wheel velocities (integer servo units, clamped to -100..100) a
%% Twist asks for. The message is checked against
%% `geometry_msgs/msg/Twist' (atom or binary keys, missing fields are 0,
%% as rosbridge fills them): an unknown field or a field of the wrong type
%% is `{error, {bad_field, Path}}'; anything else `{error, not_a_message}'.
-spec twist_to_wheels(term(), geometry()) ->
          {ok, {integer(), integer()}} | {error, {bad_field, binary()} | not_a_message}.
twist_to_wheels(Msg, #{wheel_base := Base, max_wheel_speed := Vmax}) ->
    case normalise_as(?TWIST, Msg) of
        {ok, #{linear := #{x := V}, angular := #{z := W}}} ->
            Servo = fun(Speed) -> round(clamp(Speed / Vmax * 100)) end,
            {ok, {Servo(V - W * Base / 2), Servo(V + W * Base / 2)}};
        {error, _} = Error -> Error
    end.

clamp(V) -> max(-100.0, min(100.0, float(V))).

twist(V, W) ->
    #{linear => vector3(V, 0.0, 0.0), angular => vector3(0.0, 0.0, W)}.

vector3(X, Y, Z) -> #{x => float(X), y => float(Y), z => float(Z)}.

%%====================================================================
%% Types
%%====================================================================

%% @doc The ROS 2 types this module makes and reads (those of
%% `toroco_ros_msgs', the one table of them), each with its fields (in
%% order) as `{Name, FieldType}': a primitive, `{array, Primitive, N}' or
%% another of these types. {@link fields/1} gives one.
-spec types() -> [binary()].
types() ->
    toroco_ros_msgs:types().

-type field_type() :: float64 | float32 | uint8 | int32 | uint32 | string
                    | {array, float64, pos_integer()} | binary().

%% @doc The fields of a ROS 2 type, in the order of its definition (its
%% constants, which only its definition carries, left out).
-spec fields(binary()) -> [{atom(), field_type()}].
fields(Type) ->
    {ok, Fields} = toroco_ros_msgs:fields(Type),
    [{Name, field_type(FT)} || Field <- Fields, {Name, FT} <- [name_type(Field)]].

name_type({const, _, _, _}) -> none;
name_type({Name, FT}) -> {Name, FT};
name_type({Name, FT, _Default}) -> {Name, FT}.

field_type({msg, Type}) -> Type;
field_type(FT) -> FT.

%% @doc The ROS 2 message definition of a type with its dependencies, as
%% ROS 2 tools concatenate them (rosbag2, rosapi's `typedefs_full_text'):
%% `toroco_ros_msgs:definition/1', the one place the ros2 recordings
%% take them from too.
-spec definition(binary()) -> binary().
definition(Type) ->
    {ok, Definition} = toroco_ros_msgs:definition(Type),
    Definition.

%% @doc The type of one of the robot's topics now, `error' if it has none.
-spec type_of(binary()) -> {ok, binary()} | error.
type_of(Topic) ->
    case [Ty || #{topic := T, type := Ty} <- topics(), T =:= Topic] of
        [Type | _] -> {ok, Type};
        [] -> error
    end.

%% @doc A message from outside (JSON-decoded: binary keys) checked against
%% `Type' and made a message of this module (atom keys, every field, missing
%% ones their zero); `{error, {bad_field, Path}}' names the first field
%% that does not fit.
-spec normalise({binary(), term()}) ->
          {ok, message()} | {error, {bad_field, binary()} | {unknown_type, binary()} | not_a_message}.
normalise({Type, Msg}) ->
    try normalise_as(Type, Msg)
    catch throw:{unknown_type, _} = Why -> {error, Why}
    end.

normalise_as(Type, Msg) when is_map(Msg) ->
    lists:member(Type, types()) orelse throw({unknown_type, Type}),
    try {ok, struct(Type, Msg, <<>>)}
    catch throw:{bad_field, _} = Why -> {error, Why}
    end;
normalise_as(_, _) ->
    {error, not_a_message}.

struct(Type, Msg, Path) when is_map(Msg) ->
    Fields = fields(Type),
    Names = [atom_to_binary(N) || {N, _} <- Fields],
    _ = [throw({bad_field, join(Path, key_text(K))})
         || K <- maps:keys(Msg), not lists:member(key_text(K), Names)],
    maps:from_list([{N, field(FT, lookup(N, Msg), join(Path, atom_to_binary(N)))}
                    || {N, FT} <- Fields]).

lookup(N, Msg) ->
    case Msg of
        #{N := V} -> V;
        #{} -> maps:get(atom_to_binary(N), Msg, missing)
    end.

key_text(K) when is_atom(K) -> atom_to_binary(K);
key_text(K) when is_binary(K) -> K;
key_text(K) -> toroco_rec_json:term_text(K).

join(<<>>, N) -> N;
join(P, N) -> <<P/binary, $., N/binary>>.

field(T, missing, Path) -> field(T, zero(T), Path);
field(T, V, _) when (T =:= float64 orelse T =:= float32), is_number(V) -> float(V);
field(uint8, V, _) when is_integer(V), V >= 0, V =< 255 -> V;
field(uint32, V, _) when is_integer(V), V >= 0, V =< 16#FFFFFFFF -> V;
field(int32, V, _) when is_integer(V), V >= -16#80000000, V =< 16#7FFFFFFF -> V;
field(string, V, _) when is_binary(V) -> V;
field({array, E, N}, L, Path) when is_list(L), length(L) =:= N ->
    [field(E, X, Path) || X <- L];
field(T, V, Path) when is_binary(T), is_map(V) -> struct(T, V, Path);
field(_, _, Path) -> throw({bad_field, Path}).

zero(T) when T =:= float64; T =:= float32 -> 0.0;
zero(string) -> <<>>;
zero({array, E, N}) -> lists:duplicate(N, zero(E));
zero(T) when is_binary(T) -> #{};
zero(_) -> 0.

%%====================================================================
%% The robot's topics
%%====================================================================

%% @doc The robot's topics now: `/cmd_vel' always (publishing reaches the
%% wiring when a `ros' device runs), the outputs of the running wiring
%% (`toroco:inspect/0,1'), `/odom' once a simulated world has sent a snapshot.
-spec topics() -> [topic()].
topics() ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    Outputs = lists:usort([{N, O} || Name <- Bs ++ Ds,
                                     #{name := N, outputs := Outs} <- [catch toroco:inspect(Name)],
                                     O <- maps:keys(Outs)]),
    World = case whereis(toroco_live_world) =/= undefined andalso
                catch toroco_live_world:latest() of
                #{robots := [_ | _]} -> true;
                _ -> false
            end,
    topics(#{outputs => Outputs, world => World}).

%% @doc The topics of a wiring's outputs (`{Emitter, Output}') and whether
%% a world runs: the pure half of {@link topics/0}.
-spec topics(#{outputs := [{atom(), atom()}], world := boolean()}) -> [topic()].
topics(#{outputs := Outputs, world := World}) ->
    Inbound = [<<"/cmd_vel">> | [topic_of(?ROS_DEVICE, O) || {?ROS_DEVICE, O} <- Outputs]],
    [#{topic => T, type => ?TWIST, dir => in} || T <- lists:usort(Inbound)]
        ++ [#{topic => <<"/odom">>, type => ?ODOMETRY, dir => out} || World]
        ++ [#{topic => topic_of(E, O), type => type_of(E, O), dir => out}
            || {E, O} <- Outputs, E =/= ?ROS_DEVICE].

topic_of(?ROS_DEVICE, O) -> <<$/, (atom_to_binary(O, utf8))/binary>>;
topic_of(motors, applied) -> <<"/toroco/motors/applied">>;
topic_of(?RANGE_DEVICE, O) -> <<"/range/", (atom_to_binary(O, utf8))/binary>>;
topic_of(E, O) ->
    toroco_rec_channels:topic({out, E, O}).

type_of(motors, applied) -> ?TWIST;
type_of(?RANGE_DEVICE, _) -> ?RANGE;
type_of(_, _) -> ?STRING.

%%====================================================================
%% Messages
%%====================================================================

%% @doc The ROS 2 messages of one tap event: an emission on an output
%% becomes its topic's message (none for the `ros' device's outputs, which
%% are inbound, nor for an unset or an unreadable value on a typed topic);
%% other events none.
-spec of_event(tuple()) -> [{binary(), binary(), message()}].
of_event({emit, _T, {?ROS_DEVICE, _}, _, _}) ->
    [];
of_event({emit, _T, {motors, applied}, Kind, {L, R}}) when Kind =/= unset, is_number(L),
                                                           is_number(R) ->
    [{<<"/toroco/motors/applied">>, ?TWIST, wheels_to_twist({L, R}, geometry())}];
of_event({emit, _T, {motors, applied}, _, _}) ->
    [];
of_event({emit, T, {?RANGE_DEVICE, O}, Kind, V}) when Kind =/= unset, is_number(V) ->
    #{field_of_view := Fov, min_range := Min, max_range := Max} = range_limits(),
    [{topic_of(?RANGE_DEVICE, O), ?RANGE,
      #{header => header(T, <<"range_", (atom_to_binary(O, utf8))/binary>>),
        radiation_type => ?INFRARED, field_of_view => Fov, min_range => Min,
        max_range => Max, range => float(V), variance => 0.0}}];
of_event({emit, _T, {?RANGE_DEVICE, _}, _, _}) ->
    [];
of_event({emit, _, {E, O}, _, _} = Event) ->
    {_, _, Json} = toroco_rec_channels:of_event(Event),
    [{topic_of(E, O), ?STRING, #{data => Json}}];
of_event(_) ->
    [].

%% @doc The topic of a tap event's messages without making them (cheap):
%% `none' for events that make none.
-spec event_topic(tuple()) -> binary() | none.
event_topic({emit, _, {?ROS_DEVICE, _}, _, _}) -> none;
event_topic({emit, _, {E, O}, _, _}) -> topic_of(E, O);
event_topic(_) -> none.

range_limits() ->
    Defaults = #{field_of_view => 0.05, min_range => 0.02, max_range => 1.5},
    Env = case application:get_env(toroco_ros, ros_range, #{}) of
              #{} = M -> maps:filter(fun(_, V) -> is_number(V) end,
                                     maps:with(maps:keys(Defaults), M));
              _ -> #{}
          end,
    maps:map(fun(_, V) -> float(V) end, maps:merge(Defaults, Env)).

%% @doc The `/odom' messages of a world snapshot, stamped now.
-spec of_world(map() | none) -> [{binary(), binary(), message()}].
of_world(Snapshot) ->
    of_world(Snapshot, erlang:system_time(nanosecond)).

%% @doc The `/odom' messages of a world snapshot (`toroco_live_world''s
%% shape: `robots' with `name' and `pose' `{X, Y, HeadingDeg}'), stamped
%% `T' (ns): one per robot.
-spec of_world(map() | none, integer()) -> [{binary(), binary(), message()}].
of_world(#{robots := Robots}, T) when is_list(Robots) ->
    Child = case Robots of
                [_] -> fun(_) -> <<"base_link">> end;
                _ -> fun(N) -> <<(atom_to_binary(N, utf8))/binary, "/base_link">> end
            end,
    [{<<"/odom">>, ?ODOMETRY,
      #{header => header(T, <<"odom">>), child_frame_id => Child(Name),
        pose => #{pose => #{position => #{x => float(X), y => float(Y), z => 0.0},
                            orientation => yaw(H)},
                  covariance => lists:duplicate(36, 0.0)},
        twist => #{twist => twist(0.0, 0.0),
                   covariance => [-1.0 | lists:duplicate(35, 0.0)]}}}
     || #{name := Name, pose := {X, Y, H}} <- Robots, is_atom(Name)];
of_world(_, _) ->
    [].

header(T, Frame) -> #{stamp => stamp(T), frame_id => Frame}.

%% @doc A time in ns as `builtin_interfaces/msg/Time'.
-spec stamp(integer()) -> #{sec := integer(), nanosec := non_neg_integer()}.
stamp(T) when is_integer(T) ->
    #{sec => T div 1000000000 - (case T rem 1000000000 < 0 of true -> 1; false -> 0 end),
      nanosec => ((T rem 1000000000) + 1000000000) rem 1000000000}.

yaw(Deg) ->
    Half = Deg * math:pi() / 360,
    #{x => 0.0, y => 0.0, z => math:sin(Half), w => math:cos(Half)}.
