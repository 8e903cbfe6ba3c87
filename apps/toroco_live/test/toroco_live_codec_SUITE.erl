%% The pure codecs under the dashboard and the bridges: WebSocket frames
%% (toroco_live_ws_frame) and the page's world frame (toroco_live_world_json).
%% Those of the recordings are toroco_rec_codec_SUITE's.
-module(toroco_live_codec_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [ws_frames_split_anywhere, ws_fragments_and_control, ws_faults, ws_client_frames,
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
    [{doc, "A client's frames are masked, each with a fresh key, and read back by the server's "
      "decoder; a server's unmasked frames are read by the client's decoder, which refuses "
      "masked ones"}].
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
    %% every frame a fresh key, across the reads of the kernel's bytes
    %% (a thousand keys a read): 3000 frames, their keys all but surely
    %% different (a repeat among 3000 random 32-bit keys: p < 0.002)
    Many = [iolist_to_binary(toroco_live_ws_frame:client_frame(text, integer_to_binary(I)))
            || I <- lists:seq(1, 3000)],
    Keys = [Key || <<_:16, Key:4/binary, _/binary>> <- Many],
    true = length(lists:usort(Keys)) >= 2998,
    {ok, Texts, _} = toroco_live_ws_frame:decode(iolist_to_binary(Many), Server),
    Texts = [{text, integer_to_binary(I)} || I <- lists:seq(1, 3000)],
    %% RFC 6455's example key and answer
    <<"s3pPLMBiTxaQ9kYGzzhZRbK+xOo=">> =
        toroco_live_ws_frame:accept_key(<<"dGhlIHNhbXBsZSBub25jZQ==">>),
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
