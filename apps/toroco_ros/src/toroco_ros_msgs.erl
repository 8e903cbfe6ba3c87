%% @doc The ROS 2 message types the robot's topics use (SPEC §15), as pure
%% code: each type's `.msg' definition with its dependencies, the way ROS 2
%% tooling stores it in a bag (MCAP schema encoding `ros2msg'), and the
%% CDR bytes of a message (MCAP message encoding `cdr'). The ros2 profile
%% of a recording (`toroco_rec_recorder') writes both; this module does
%% no I/O.
%%
%% Types: `geometry_msgs/msg/Twist', `nav_msgs/msg/Odometry',
%% `sensor_msgs/msg/Range' (the layout of ROS 2 Jazzy, with `variance':
%% a reader of an older layout ignores the trailing field),
%% `std_msgs/msg/String', and what they are made of: `std_msgs/msg/Header',
%% `builtin_interfaces/msg/Time', `geometry_msgs/msg/{Vector3, Point,
%% Quaternion, Pose, PoseWithCovariance, TwistWithCovariance}'.
%%
%% A message is a map with atom keys named as the ROS 2 fields, every
%% field present (extra keys are ignored): numbers for the numeric fields
%% (an integer is taken for a float), binaries for strings, a list of 36
%% numbers for a covariance, `#{sec, nanosec}' for a time.
%%
%% {@link definition/1}: the top type's text first, then each dependency
%% once (depth first, in the order they are first used) after a line of
%% 80 `=' and a line `MSG: pkg/Type'. {@link cdr/2}: the 4-byte
%% encapsulation header of plain CDR, little endian (`00 01 00 00'), then
%% the fields in order, each primitive aligned to its size counted from the
%% end of the header (XCDR1: a float64 on 8), a string as its uint32
%% length with the terminating zero, its bytes and the zero, a fixed array
%% as its elements without a length. {@link types/0} lists what is known;
%% {@link string_data/1} reads a `std_msgs/msg/String' back (replay).
-module(toroco_ros_msgs).

-export([types/0, fields/1, definition/1, cdr/2, string_data/1]).

-export_type([type_name/0, msg/0]).

-type type_name() :: binary().
-type msg() :: #{atom() => term()}.

-type primitive() :: float64 | float32 | int32 | uint32 | uint8 | string.
-type field_type() :: primitive() | {array, primitive(), pos_integer()} | {msg, type_name()}.
%% A field, or a constant (written in the definition only).
-type field() :: {atom(), field_type()} | {atom(), field_type(), Default :: binary()}
               | {const, atom(), primitive(), binary()}.

-define(SEPARATOR, <<"================================================================================\n">>).

%%====================================================================
%% The types
%%====================================================================

%% @doc The fields of a type in the order of its definition, with the
%% defaults and constants its definition writes.
-spec fields(type_name()) -> {ok, [field()]} | error.
fields(<<"builtin_interfaces/msg/Time">>) ->
    {ok, [{sec, int32}, {nanosec, uint32}]};
fields(<<"std_msgs/msg/Header">>) ->
    {ok, [{stamp, {msg, <<"builtin_interfaces/msg/Time">>}}, {frame_id, string}]};
fields(<<"std_msgs/msg/String">>) ->
    {ok, [{data, string}]};
fields(<<"geometry_msgs/msg/Vector3">>) ->
    {ok, [{x, float64}, {y, float64}, {z, float64}]};
fields(<<"geometry_msgs/msg/Point">>) ->
    {ok, [{x, float64}, {y, float64}, {z, float64}]};
fields(<<"geometry_msgs/msg/Quaternion">>) ->
    {ok, [{x, float64, <<"0">>}, {y, float64, <<"0">>}, {z, float64, <<"0">>},
          {w, float64, <<"1">>}]};
fields(<<"geometry_msgs/msg/Pose">>) ->
    {ok, [{position, {msg, <<"geometry_msgs/msg/Point">>}},
          {orientation, {msg, <<"geometry_msgs/msg/Quaternion">>}}]};
fields(<<"geometry_msgs/msg/Twist">>) ->
    {ok, [{linear, {msg, <<"geometry_msgs/msg/Vector3">>}},
          {angular, {msg, <<"geometry_msgs/msg/Vector3">>}}]};
fields(<<"geometry_msgs/msg/PoseWithCovariance">>) ->
    {ok, [{pose, {msg, <<"geometry_msgs/msg/Pose">>}}, {covariance, {array, float64, 36}}]};
fields(<<"geometry_msgs/msg/TwistWithCovariance">>) ->
    {ok, [{twist, {msg, <<"geometry_msgs/msg/Twist">>}}, {covariance, {array, float64, 36}}]};
fields(<<"nav_msgs/msg/Odometry">>) ->
    {ok, [{header, {msg, <<"std_msgs/msg/Header">>}}, {child_frame_id, string},
          {pose, {msg, <<"geometry_msgs/msg/PoseWithCovariance">>}},
          {twist, {msg, <<"geometry_msgs/msg/TwistWithCovariance">>}}]};
fields(<<"sensor_msgs/msg/Range">>) ->
    {ok, [{header, {msg, <<"std_msgs/msg/Header">>}},
          {const, 'ULTRASOUND', uint8, <<"0">>}, {const, 'INFRARED', uint8, <<"1">>},
          {radiation_type, uint8}, {field_of_view, float32}, {min_range, float32},
          {max_range, float32}, {range, float32}, {variance, float32}]};
fields(_) ->
    error.

%% @doc Every type this module knows.
-spec types() -> [type_name()].
types() ->
    [<<"builtin_interfaces/msg/Time">>, <<"std_msgs/msg/Header">>, <<"std_msgs/msg/String">>,
     <<"geometry_msgs/msg/Vector3">>, <<"geometry_msgs/msg/Point">>,
     <<"geometry_msgs/msg/Quaternion">>, <<"geometry_msgs/msg/Pose">>,
     <<"geometry_msgs/msg/Twist">>, <<"geometry_msgs/msg/PoseWithCovariance">>,
     <<"geometry_msgs/msg/TwistWithCovariance">>, <<"nav_msgs/msg/Odometry">>,
     <<"sensor_msgs/msg/Range">>].

%%====================================================================
%% Definitions
%%====================================================================

%% @doc The `ros2msg' text of `Type' with its dependencies.
-spec definition(type_name()) -> {ok, binary()} | {error, {unknown_type, term()}}.
definition(Type) ->
    case fields(Type) of
        {ok, Fields} ->
            Deps = dependencies(Fields, []),
            {ok, iolist_to_binary([text(Fields)
                                   | [[?SEPARATOR, <<"MSG: ">>, short(D), $\n, text(element(2, fields(D)))]
                                      || D <- Deps]])};
        error ->
            {error, {unknown_type, Type}}
    end.

%% Depth first, each once, in the order first used.
dependencies(Fields, Seen0) ->
    lists:foldl(fun(T, Seen) ->
                        case lists:member(T, Seen) of
                            true -> Seen;
                            false ->
                                {ok, Fs} = fields(T),
                                dependencies(Fs, Seen ++ [T])
                        end
                end, Seen0, [T || {_, {msg, T}} <- Fields]).

text(Fields) ->
    [line(F) || F <- Fields].

line({const, Name, Prim, Value}) ->
    [type_text(Prim), $\s, atom_to_binary(Name), $=, Value, $\n];
line({Name, Type}) ->
    [type_text(Type), $\s, atom_to_binary(Name), $\n];
line({Name, Type, Default}) ->
    [type_text(Type), $\s, atom_to_binary(Name), $\s, Default, $\n].

type_text({msg, T}) -> short(T);
type_text({array, P, N}) -> [type_text(P), $[, integer_to_binary(N), $]];
type_text(P) -> atom_to_binary(P).

%% `pkg/msg/Type' as `.msg' files and `MSG:' lines name it: `pkg/Type'.
short(T) ->
    case binary:split(T, <<"/">>, [global]) of
        [Pkg, <<"msg">>, Name] -> <<Pkg/binary, $/, Name/binary>>;
        _ -> T
    end.

%%====================================================================
%% CDR
%%====================================================================

%% @doc The CDR bytes of `Msg' as a `Type', header included;
%% `{error, {missing_field, Type, Path}}' for a field not in the map (Path
%% the field names from the top), `{error, {bad_value, Path, Value}}' for
%% a value the field cannot hold.
-spec cdr(type_name(), msg()) -> {ok, binary()} | {error, term()}.
cdr(Type, Msg) ->
    case fields(Type) of
        error -> {error, {unknown_type, Type}};
        {ok, _} when not is_map(Msg) -> {error, {bad_value, [], Msg}};
        {ok, _} ->
            try struct(Type, Msg, [], {[], 0}) of
                {Acc, _} -> {ok, iolist_to_binary([<<0, 1, 0, 0>> | lists:reverse(Acc)])}
            catch throw:Reason -> {error, Reason}
            end
    end.

%% The accumulator: the bytes so far (reversed iolist) and their count,
%% which is what alignment is counted from.
struct(Type, Msg, Path, Acc0) ->
    {ok, Fields} = fields(Type),
    lists:foldl(fun({const, _, _, _}, Acc) -> Acc;
                   (F, Acc) ->
                        Name = element(1, F),
                        FieldPath = Path ++ [Name],
                        case Msg of
                            #{Name := V} -> value(element(2, F), V, FieldPath, Acc);
                            #{} -> throw({missing_field, Type, FieldPath})
                        end
                end, Acc0, Fields).

value({msg, T}, V, Path, Acc) when is_map(V) ->
    struct(T, V, Path, Acc);
value({array, P, N}, V, Path, Acc) when is_list(V), length(V) =:= N ->
    lists:foldl(fun(E, A) -> value(P, E, Path, A) end, Acc, V);
value(string, V, Path, Acc) when is_binary(V) ->
    case binary:match(V, <<0>>) of
        nomatch -> put_aligned(4, [<<(byte_size(V) + 1):32/little>>, V, 0], 5 + byte_size(V), Acc);
        _ -> throw({bad_value, Path, V})
    end;
value(float64, V, _Path, Acc) when is_number(V) ->
    put_aligned(8, <<V:64/float-little>>, 8, Acc);
value(float32, V, Path, Acc) when is_number(V) ->
    try <<V:32/float-little>> of
        B -> put_aligned(4, B, 4, Acc)
    catch error:badarg -> throw({bad_value, Path, V})
    end;
value(int32, V, _Path, Acc) when is_integer(V), V >= -16#80000000, V =< 16#7FFFFFFF ->
    put_aligned(4, <<V:32/signed-little>>, 4, Acc);
value(uint32, V, _Path, Acc) when is_integer(V), V >= 0, V =< 16#FFFFFFFF ->
    put_aligned(4, <<V:32/little>>, 4, Acc);
value(uint8, V, _Path, Acc) when is_integer(V), V >= 0, V =< 255 ->
    put_aligned(1, <<V>>, 1, Acc);
value(_, V, Path, _Acc) ->
    throw({bad_value, Path, V}).

put_aligned(Align, Bytes, Size, {Acc, At}) ->
    Pad = (Align - At rem Align) rem Align,
    {[Bytes, <<0:(Pad * 8)>> | Acc], At + Pad + Size}.

%% @doc The `data' of a `std_msgs/msg/String' in CDR (either byte order),
%% `error' for bytes that are not one.
-spec string_data(binary()) -> {ok, binary()} | error.
string_data(<<0, 1, _:2/binary, Len:32/little, Rest/binary>>) -> string_bytes(Len, Rest);
string_data(<<0, 0, _:2/binary, Len:32/big, Rest/binary>>) -> string_bytes(Len, Rest);
string_data(_) -> error.

string_bytes(Len, Rest) when Len >= 1, byte_size(Rest) >= Len ->
    N = Len - 1,
    case Rest of
        <<Data:N/binary, 0, _/binary>> -> {ok, Data};
        _ -> error
    end;
string_bytes(_, _) ->
    error.
