%% The pure codecs under the recordings and the bridges: MCAP
%% (toroco_rec_mcap), the channels' topics (toroco_rec_channels) and the
%% JSON text (toroco_rec_json, toroco_rec_json_text).
-module(toroco_rec_codec_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [mcap_round_trip, mcap_every_truncation_refused, topics_round_trip, json_text_as_jiffy].

mcap_round_trip() ->
    [{doc, "What the writer writes the reader reads back: schemas, channels, every message in order"}].
mcap_round_trip(_Config) ->
    {Head, W0} = toroco_rec_mcap:new(#{chunk_bytes => 500}),
    {S, W1} = toroco_rec_mcap:add_schema(W0, 1, <<"toroco.Output">>, <<"{}">>),
    {C1, W2} = toroco_rec_mcap:add_channel(W1, 1, 1, <<"/toroco/out/a/b">>, #{}),
    {C2, W3} = toroco_rec_mcap:add_channel(W2, 2, 1, <<"/toroco/out/a/c">>, #{<<"k">> => <<"v">>}),
    Msgs = [{1 + I rem 2, I, 1000 + I, integer_to_binary(I)} || I <- lists:seq(1, 300)],
    {Body, W4} = lists:foldl(fun({Ch, Seq, T, D}, {Acc, W}) ->
                                     {B, W9} = toroco_rec_mcap:add_message(W, Ch, Seq, T, D),
                                     {[Acc, B], W9}
                             end, {[], W3}, Msgs),
    Bin = iolist_to_binary([Head, S, C1, C2, Body, toroco_rec_mcap:finish(W4)]),
    true = byte_size(Bin) =:= toroco_rec_mcap:bytes_written(W4) + iolist_size(toroco_rec_mcap:finish(W4)),
    {ok, #{library := <<"toroco_live", _/binary>>, schemas := #{1 := #{name := <<"toroco.Output">>}},
           channels := #{1 := #{topic := <<"/toroco/out/a/b">>}, 2 := #{topic := <<"/toroco/out/a/c">>}},
           messages := Read, statistics := #{message_count := 300}}} = toroco_rec_mcap:read(Bin),
    Msgs = [{Ch, Seq, T, D} || #{channel := Ch, sequence := Seq, log_time := T, data := D} <- Read],
    ok.

mcap_every_truncation_refused() ->
    [{doc, "Every truncation of a recording, and any single flipped byte, is refused with a reason"}].
mcap_every_truncation_refused(_Config) ->
    {Head, W0} = toroco_rec_mcap:new(#{chunk_bytes => 200}),
    {S, W1} = toroco_rec_mcap:add_schema(W0, 1, <<"x">>, <<"{}">>),
    {C, W2} = toroco_rec_mcap:add_channel(W1, 1, 1, <<"/toroco/lifecycle">>, #{}),
    {Body, W3} = lists:foldl(fun(I, {Acc, W}) ->
                                     {B, W9} = toroco_rec_mcap:add_message(W, 1, I, I, <<"{}">>),
                                     {[Acc, B], W9}
                             end, {[], W2}, lists:seq(1, 30)),
    Bin = iolist_to_binary([Head, S, C, Body, toroco_rec_mcap:finish(W3)]),
    [{error, _} = toroco_rec_mcap:read(binary:part(Bin, 0, K)) || K <- lists:seq(0, byte_size(Bin) - 1)],
    [{error, _} = toroco_rec_mcap:read(flip(Bin, K)) || K <- lists:seq(0, byte_size(Bin) - 1, 7)],
    ok.

topics_round_trip() ->
    [{doc, "Topics name their channel back; unknown names do not create atoms"}].
topics_round_trip(_Config) ->
    Keys = [{out, avoid_left, motors}, {in, motors, setvel}, {router, motors, setvel},
            lifecycle, pose, scene],
    [{ok, K} = toroco_rec_channels:key(toroco_rec_channels:topic(K)) || K <- Keys],
    error = toroco_rec_channels:key(<<"/toroco/out/no_such_name_anywhere_42/x">>),
    error = toroco_rec_channels:key(<<"/elsewhere">>),
    ok.

json_text_as_jiffy() ->
    [{doc, "The event path's JSON writer says what jiffy says, escapes included, and an "
      "event's message has the fields of SPEC 12"}].
json_text_as_jiffy(_Config) ->
    Terms = [1, -7, 1.5, 1.0e300, -0.0, true, false, null, ok, <<"plain">>, <<"q\"b\\s/\n\t\r\x01\x1f">>,
             <<"é ☃"/utf8>>, <<255, 0>>, [], [[]], #{}, {}, {1, two, <<"3">>}, #{a => 1, <<"b">> => [x]},
             #{{tuple, key} => 1}, [1 | 2], self(), make_ref(), fun() -> ok end, "string", 'quoted atom'],
    [begin
         J = toroco_rec_json:value(T),
         Want = jiffy:decode(jiffy:encode(J), [return_maps]),
         Want = jiffy:decode(iolist_to_binary(toroco_rec_json_text:encode(J)), [return_maps])
     end || T <- Terms],
    [begin
         {{out, s, o}, 7, Out} = toroco_rec_channels:of_event({emit, 7, {s, o}, set, T}),
         #{<<"kind">> := <<"set">>, <<"value">> := V, <<"term">> := Tx} = jiffy:decode(Out, [return_maps]),
         V = jiffy:decode(jiffy:encode(toroco_rec_json:value(T)), [return_maps]),
         Tx = toroco_rec_json:term_text(T),
         {{in, r, i}, 8, In} = toroco_rec_channels:of_event({deliver, 8, {r, i}, T}),
         #{<<"value">> := V, <<"term">> := Tx} = jiffy:decode(In, [return_maps])
     end || T <- Terms],
    ok.

%% Helpers

flip(Bin, K) ->
    <<H:K/binary, B, T/binary>> = Bin,
    <<H/binary, (B bxor 16#5A), T/binary>>.
