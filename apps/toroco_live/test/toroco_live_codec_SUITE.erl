%% The pure codecs under the bridge and the recordings: WebSocket frames
%% (toroco_live_ws) and MCAP (toroco_live_mcap), the channels' topics, and
%% the ROS 2 message types (toroco_live_ros_msgs) checked with the
%% reference ROS 2 libraries in Node.
-module(toroco_live_codec_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [ws_frames_split_anywhere, ws_fragments_and_control, ws_faults, ws_client_frames,
     mcap_round_trip, mcap_every_truncation_refused, topics_round_trip, json_text_as_jiffy,
     ros_definitions_parse, ros_cdr_as_reference, ros_cdr_errors, world_timeline].

ws_frames_split_anywhere() ->
    [{doc, "Masked client frames of every length class decode whole, however the bytes are split"}].
ws_frames_split_anywhere(_Config) ->
    Payloads = [<<>>, <<"a">>, binary:copy(<<"xyz">>, 42), crypto:strong_rand_bytes(126),
                crypto:strong_rand_bytes(70000)],
    Bytes = iolist_to_binary([client_frame(2, 1, P) || P <- Payloads]),
    Want = [{binary, P} || P <- Payloads],
    [Want = decode_in_pieces(Bytes, Cut) || Cut <- [1, 2, 3, 7, 100, 5000, byte_size(Bytes)]],
    ok.

ws_fragments_and_control() ->
    [{doc, "A fragmented text message is reassembled around a ping in its middle; close carries its code"}].
ws_fragments_and_control(_Config) ->
    Bytes = iolist_to_binary([client_frame(1, 0, <<"hel">>), client_frame(9, 1, <<"p">>),
                              client_frame(0, 0, <<"lo ">>), client_frame(0, 1, <<"world">>),
                              client_frame(8, 1, <<1000:16, "bye">>)]),
    {ok, [{ping, <<"p">>}, {text, <<"hello world">>}, {close, 1000, <<"bye">>}], _} =
        toroco_live_ws_frame:decode(Bytes, toroco_live_ws_frame:decoder(1000)),
    ok.

ws_faults() ->
    [{doc, "Unmasked frames, reserved bits, unknown opcodes, oversize messages and stray "
      "continuations are errors, never crashes"}].
ws_faults(_Config) ->
    D = toroco_live_ws_frame:decoder(100),
    {error, unmasked_frame} = toroco_live_ws_frame:decode(<<1:1, 0:3, 1:4, 0:1, 1:7, "a">>, D),
    {error, reserved_bits} = toroco_live_ws_frame:decode(<<1:1, 1:3, 1:4, 1:1, 0:7, 0:32>>, D),
    {error, {opcode, 3}} = toroco_live_ws_frame:decode(iolist_to_binary(client_frame(3, 1, <<>>)), D),
    {error, too_big} = toroco_live_ws_frame:decode(iolist_to_binary(client_frame(2, 1, binary:copy(<<0>>, 101))), D),
    {error, {unexpected_frame, 0}} = toroco_live_ws_frame:decode(iolist_to_binary(client_frame(0, 1, <<"x">>)), D),
    {error, bad_control_frame} = toroco_live_ws_frame:decode(iolist_to_binary(client_frame(9, 0, <<>>)), D),
    [case toroco_live_ws_frame:decode(crypto:strong_rand_bytes(40), D) of
         {ok, _, _} -> ok;
         {error, _} -> ok
     end || _ <- lists:seq(1, 500)],
    ok.

ws_client_frames() ->
    [{doc, "A client's frames are masked and read back by the server's decoder; a server's "
      "unmasked frames are read by the client's decoder, which refuses masked ones"}].
ws_client_frames(_Config) ->
    Payloads = [<<>>, <<"{\"op\":\"advertise\"}">>, crypto:strong_rand_bytes(300),
                crypto:strong_rand_bytes(70000)],
    Server = toroco_live_ws_frame:decoder(1 bsl 20),
    Client = toroco_live_ws_frame:client_decoder(1 bsl 20),
    Masked = iolist_to_binary([toroco_live_ws_frame:client_frame(text, P) || P <- Payloads]
                              ++ [toroco_live_ws_frame:client_close_frame(1000, <<"bye">>)]),
    {ok, FromClient, _} = toroco_live_ws_frame:decode(Masked, Server),
    FromClient = [{text, P} || P <- Payloads] ++ [{close, 1000, <<"bye">>}],
    Plain = iolist_to_binary([toroco_live_ws_frame:frame(binary, P) || P <- Payloads]),
    {ok, FromServer, _} = toroco_live_ws_frame:decode(Plain, Client),
    FromServer = [{binary, P} || P <- Payloads],
    [FromServer = decode_in_pieces(Plain, Cut, Client) || Cut <- [1, 5, 1000]],
    {error, masked_frame} = toroco_live_ws_frame:decode(Masked, Client),
    %% RFC 6455's example key and answer
    <<"s3pPLMBiTxaQ9kYGzzhZRbK+xOo=">> =
        toroco_live_ws_frame:accept_key(<<"dGhlIHNhbXBsZSBub25jZQ==">>),
    ok.

mcap_round_trip() ->
    [{doc, "What the writer writes the reader reads back: schemas, channels, every message in order"}].
mcap_round_trip(_Config) ->
    {Head, W0} = toroco_live_mcap:new(#{chunk_bytes => 500}),
    {S, W1} = toroco_live_mcap:add_schema(W0, 1, <<"toroco.Output">>, <<"{}">>),
    {C1, W2} = toroco_live_mcap:add_channel(W1, 1, 1, <<"/toroco/out/a/b">>, #{}),
    {C2, W3} = toroco_live_mcap:add_channel(W2, 2, 1, <<"/toroco/out/a/c">>, #{<<"k">> => <<"v">>}),
    Msgs = [{1 + I rem 2, I, 1000 + I, integer_to_binary(I)} || I <- lists:seq(1, 300)],
    {Body, W4} = lists:foldl(fun({Ch, Seq, T, D}, {Acc, W}) ->
                                     {B, W9} = toroco_live_mcap:add_message(W, Ch, Seq, T, D),
                                     {[Acc, B], W9}
                             end, {[], W3}, Msgs),
    Bin = iolist_to_binary([Head, S, C1, C2, Body, toroco_live_mcap:finish(W4)]),
    true = byte_size(Bin) =:= toroco_live_mcap:bytes_written(W4) + iolist_size(toroco_live_mcap:finish(W4)),
    {ok, #{library := <<"toroco_live", _/binary>>, schemas := #{1 := #{name := <<"toroco.Output">>}},
           channels := #{1 := #{topic := <<"/toroco/out/a/b">>}, 2 := #{topic := <<"/toroco/out/a/c">>}},
           messages := Read, statistics := #{message_count := 300}}} = toroco_live_mcap:read(Bin),
    Msgs = [{Ch, Seq, T, D} || #{channel := Ch, sequence := Seq, log_time := T, data := D} <- Read],
    ok.

mcap_every_truncation_refused() ->
    [{doc, "Every truncation of a recording, and any single flipped byte, is refused with a reason"}].
mcap_every_truncation_refused(_Config) ->
    {Head, W0} = toroco_live_mcap:new(#{chunk_bytes => 200}),
    {S, W1} = toroco_live_mcap:add_schema(W0, 1, <<"x">>, <<"{}">>),
    {C, W2} = toroco_live_mcap:add_channel(W1, 1, 1, <<"/toroco/lifecycle">>, #{}),
    {Body, W3} = lists:foldl(fun(I, {Acc, W}) ->
                                     {B, W9} = toroco_live_mcap:add_message(W, 1, I, I, <<"{}">>),
                                     {[Acc, B], W9}
                             end, {[], W2}, lists:seq(1, 30)),
    Bin = iolist_to_binary([Head, S, C, Body, toroco_live_mcap:finish(W3)]),
    [{error, _} = toroco_live_mcap:read(binary:part(Bin, 0, K)) || K <- lists:seq(0, byte_size(Bin) - 1)],
    [{error, _} = toroco_live_mcap:read(flip(Bin, K)) || K <- lists:seq(0, byte_size(Bin) - 1, 7)],
    ok.

topics_round_trip() ->
    [{doc, "Topics name their channel back; unknown names do not create atoms"}].
topics_round_trip(_Config) ->
    Keys = [{out, avoid_left, motors}, {in, motors, setvel}, {router, motors, setvel},
            lifecycle, pose, scene],
    [{ok, K} = toroco_live_channels:key(toroco_live_channels:topic(K)) || K <- Keys],
    error = toroco_live_channels:key(<<"/toroco/out/no_such_name_anywhere_42/x">>),
    error = toroco_live_channels:key(<<"/elsewhere">>),
    ok.

json_text_as_jiffy() ->
    [{doc, "The event path's JSON writer says what jiffy says, escapes included, and an "
      "event's message has the fields of SPEC 12"}].
json_text_as_jiffy(_Config) ->
    Terms = [1, -7, 1.5, 1.0e300, -0.0, true, false, null, ok, <<"plain">>, <<"q\"b\\s/\n\t\r\x01\x1f">>,
             <<"é ☃"/utf8>>, <<255, 0>>, [], [[]], #{}, {}, {1, two, <<"3">>}, #{a => 1, <<"b">> => [x]},
             #{{tuple, key} => 1}, [1 | 2], self(), make_ref(), fun() -> ok end, "string", 'quoted atom'],
    [begin
         J = toroco_live_json:value(T),
         Want = jiffy:decode(jiffy:encode(J), [return_maps]),
         Want = jiffy:decode(iolist_to_binary(toroco_live_json_text:encode(J)), [return_maps])
     end || T <- Terms],
    [begin
         {{out, s, o}, 7, Out} = toroco_live_channels:of_event({emit, 7, {s, o}, set, T}),
         #{<<"kind">> := <<"set">>, <<"value">> := V, <<"term">> := Tx} = jiffy:decode(Out, [return_maps]),
         V = jiffy:decode(jiffy:encode(toroco_live_json:value(T)), [return_maps]),
         Tx = toroco_live_json:term_text(T),
         {{in, r, i}, 8, In} = toroco_live_channels:of_event({deliver, 8, {r, i}, T}),
         #{<<"value">> := V, <<"term">> := Tx} = jiffy:decode(In, [return_maps])
     end || T <- Terms],
    ok.

ros_definitions_parse() ->
    [{doc, "Every type's ros2msg definition parses with @foxglove/rosmsg (ros2) into the type "
      "and each of its dependencies once, after 80 '=' and a 'MSG: pkg/Type' line"}].
ros_definitions_parse(_Config) ->
    ok = toroco_live_js:ensure_installed(),
    Types = toroco_live_ros_msgs:types(),
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
    {ok, Def} = toroco_live_ros_msgs:definition(<<"geometry_msgs/msg/Twist">>),
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
             cdr => base64:encode(element(2, toroco_live_ros_msgs:cdr(<<"std_msgs/msg/String">>,
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
    ct:log("~b messages of ~b types, bytes: ~p", [length(Results), length(toroco_live_ros_msgs:types()),
                                                 lists:usort([{T, L} || #{<<"type">> := T, <<"length">> := L} <- Results])]),
    ok.

ros_cdr_errors() ->
    [{doc, "An unknown type, a missing field (named by its path), a value its field cannot "
      "hold and a string with a NUL are errors naming the culprit; a String reads back, "
      "and bytes that are not one are an error"}].
ros_cdr_errors(_Config) ->
    {error, {unknown_type, <<"nav_msgs/msg/Path">>}} = toroco_live_ros_msgs:cdr(<<"nav_msgs/msg/Path">>, #{}),
    {error, {unknown_type, x}} = toroco_live_ros_msgs:definition(x),
    Twist = ros_sample(<<"geometry_msgs/msg/Twist">>, <<>>),
    {error, {missing_field, <<"geometry_msgs/msg/Vector3">>, [angular, z]}} =
        toroco_live_ros_msgs:cdr(<<"geometry_msgs/msg/Twist">>,
                                 Twist#{angular := maps:remove(z, maps:get(angular, Twist))}),
    {error, {bad_value, [linear, x], <<"fast">>}} =
        toroco_live_ros_msgs:cdr(<<"geometry_msgs/msg/Twist">>,
                                 Twist#{linear := #{x => <<"fast">>, y => 0, z => 0}}),
    Range = ros_sample(<<"sensor_msgs/msg/Range">>, <<"ir">>),
    {error, {bad_value, [radiation_type], 256}} =
        toroco_live_ros_msgs:cdr(<<"sensor_msgs/msg/Range">>, Range#{radiation_type := 256}),
    {error, {bad_value, [header, frame_id], <<"a", 0>>}} =
        toroco_live_ros_msgs:cdr(<<"sensor_msgs/msg/Range">>,
                                 Range#{header := #{stamp => #{sec => 0, nanosec => 0},
                                                    frame_id => <<"a", 0>>}}),
    {error, {bad_value, [covariance], [1.0]}} =
        toroco_live_ros_msgs:cdr(<<"geometry_msgs/msg/PoseWithCovariance">>,
                                 (ros_sample(<<"geometry_msgs/msg/PoseWithCovariance">>, <<>>))#{covariance := [1.0]}),
    {error, {bad_value, [], not_a_map}} = toroco_live_ros_msgs:cdr(<<"std_msgs/msg/String">>, not_a_map),
    %% extra keys are not the encoder's business
    {ok, _} = toroco_live_ros_msgs:cdr(<<"std_msgs/msg/String">>, #{data => <<"x">>, other => 1}),
    %% a String read back, and bytes that are not one
    [{ok, D} = toroco_live_ros_msgs:string_data(element(2, toroco_live_ros_msgs:cdr(<<"std_msgs/msg/String">>, #{data => D})))
     || D <- [<<>>, <<"{}">>, <<"{\"é\":1}"/utf8>>, binary:copy(<<"x">>, 1000)]],
    [error = toroco_live_ros_msgs:string_data(B)
     || B <- [<<>>, <<0, 1, 0, 0>>, <<0, 1, 0, 0, 5:32/little, "ab">>, <<0, 1, 0, 0, 0:32>>,
              <<0, 1, 0, 0, 3:32/little, "abc">>, crypto:strong_rand_bytes(3)]],
    ok.

%% One case per type, `Frame' as every string.
ros_cases(Frame) ->
    [#{type => T, definition => element(2, toroco_live_ros_msgs:definition(T)),
       cdr => base64:encode(element(2, toroco_live_ros_msgs:cdr(T, M))), msg => M}
     || T <- toroco_live_ros_msgs:types(), M <- [ros_sample(T, Frame)]].

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

%% Helpers

client_frame(Op, Fin, Payload) ->
    Mask = crypto:strong_rand_bytes(4),
    Len = byte_size(Payload),
    LenBits = if Len < 126 -> <<Len:7>>; Len < 65536 -> <<126:7, Len:16>>; true -> <<127:7, Len:64>> end,
    <<M:32>> = Mask,
    Masked = mask(Payload, <<M:32>>),
    [<<Fin:1, 0:3, Op:4, 1:1, LenBits/bits, Mask/binary>>, Masked].

mask(P, M) ->
    Ms = binary:copy(M, byte_size(P) div 4 + 1),
    crypto:exor(P, binary:part(Ms, 0, byte_size(P))).

decode_in_pieces(Bytes, Cut) ->
    decode_in_pieces(Bytes, Cut, toroco_live_ws_frame:decoder(1 bsl 20)).

decode_in_pieces(Bytes, Cut, D) ->
    decode_in_pieces(Bytes, Cut, D, []).

decode_in_pieces(<<>>, _, _, Acc) -> Acc;
decode_in_pieces(Bytes, Cut, D, Acc) ->
    N = min(Cut, byte_size(Bytes)),
    <<Piece:N/binary, Rest/binary>> = Bytes,
    {ok, Ms, D1} = toroco_live_ws_frame:decode(Piece, D),
    decode_in_pieces(Rest, Cut, D1, Acc ++ Ms).

flip(Bin, K) ->
    <<H:K/binary, B, T/binary>> = Bin,
    <<H/binary, (B bxor 16#5A), T/binary>>.

world_timeline() ->
    [{doc, "A world snapshot's timeline (the robustness lab's faults and violation) reaches "
      "the page's world frame with each mark's time, kind and text; none gives null."}].
world_timeline(_Config) ->
    Snap = #{run => r, t_ms => 2000, arena => {2.0, 1.0}, walls => [], objects => [],
             robots => [],
             timeline => #{duration_ms => 15000,
                           marks => [#{t_ms => 1300, kind => fault, text => <<"kill avoid_left">>},
                                     #{t_ms => 1650, kind => violation,
                                       text => <<"{never,wall_contact}">>}]}},
    #{<<"timeline">> := #{<<"duration_ms">> := 15000,
                          <<"marks">> := [#{<<"t_ms">> := 1300, <<"kind">> := <<"fault">>,
                                            <<"text">> := <<"kill avoid_left">>},
                                          #{<<"t_ms">> := 1650, <<"kind">> := <<"violation">>}]}} =
        toroco_live_world_json:frame(Snap),
    #{<<"timeline">> := null} = toroco_live_world_json:frame(maps:remove(timeline, Snap)).
