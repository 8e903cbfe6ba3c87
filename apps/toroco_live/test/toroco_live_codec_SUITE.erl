%% The pure codecs under the bridge and the recordings: WebSocket frames
%% (toroco_live_ws) and MCAP (toroco_live_mcap), the channels' topics and
%% the JSON text.
-module(toroco_live_codec_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [ws_frames_split_anywhere, ws_fragments_and_control, ws_faults, ws_client_frames,
     mcap_round_trip, mcap_every_truncation_refused, topics_round_trip, json_text_as_jiffy,
     world_timeline].

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
