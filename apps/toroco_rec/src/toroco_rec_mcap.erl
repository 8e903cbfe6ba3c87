%% @doc MCAP, the log format Foxglove and ROS 2 read, as pure code: a
%% writer that turns schemas, channels and messages into file bytes, and a
%% reader that checks a whole file and gives its records back. The recorder
%% (`toroco_rec_recorder'), the flight recorder and replay sit on top; this
%% module does no I/O.
%%
%% What is written, following the published format (version 0):
%% ```
%% magic, Header (profile "" or "ros2", library "toroco_live ...")
%% data section: Schema and Channel records as they first appear, then
%%               Chunks (uncompressed) each followed by its Message Index
%%               records, one per channel of the chunk
%% Data End (CRC-32 of every byte before it)
%% summary: every Schema, every Channel, Statistics, one Chunk Index per chunk
%% Summary Offset records (one per group), Footer (summary CRC), magic
%% '''
%% Every record is `opcode:8, length:64/little, content'; strings and maps
%% carry a 32-bit little-endian byte length.
%%
%% Writer: {@link new/1}, {@link add_schema/4} (`jsonschema') or
%% {@link add_schema/5} (any schema encoding, `ros2msg' for ROS 2),
%% {@link add_channel/5} (`json' messages) or {@link add_channel/6} (any
%% message encoding, `cdr' for ROS 2), {@link add_message/5},
%% {@link finish/1}; each returns the bytes to append
%% (possibly none) and the new writer. Reader: {@link read/1} checks magic,
%% footer, summary CRC, data CRC and each chunk's CRC, and refuses with a
%% reason anything that is not a complete MCAP file.
-module(toroco_rec_mcap).

-export([new/1, add_schema/4, add_schema/5, add_channel/5, add_channel/6, add_message/5, finish/1,
         bytes_written/1, message_count/1]).
-export([read/1, library/0]).

-export_type([writer/0, contents/0, message/0]).

-define(MAGIC, <<16#89, "MCAP0\r\n">>).
-define(OP_HEADER, 16#01).
-define(OP_FOOTER, 16#02).
-define(OP_SCHEMA, 16#03).
-define(OP_CHANNEL, 16#04).
-define(OP_MESSAGE, 16#05).
-define(OP_CHUNK, 16#06).
-define(OP_MESSAGE_INDEX, 16#07).
-define(OP_CHUNK_INDEX, 16#08).
-define(OP_STATISTICS, 16#0B).
-define(OP_SUMMARY_OFFSET, 16#0E).
-define(OP_DATA_END, 16#0F).
-define(MAX_U64, 16#FFFFFFFFFFFFFFFF).
%% Uncompressed chunk size that closes a chunk.
-define(CHUNK_BYTES, 262144).

-record(chunk, {records = [] :: iodata(),       % reversed
                size = 0 :: non_neg_integer(),
                start = ?MAX_U64 :: non_neg_integer(),
                stop = 0 :: non_neg_integer(),
                index = #{} :: #{non_neg_integer() => [{non_neg_integer(), non_neg_integer()}]}}).

-record(writer, {offset = 0 :: non_neg_integer(),
                 crc = 0 :: non_neg_integer(),          % data section so far
                 chunk_bytes = ?CHUNK_BYTES :: pos_integer(),
                 schemas = [] :: [binary()],             % records, reversed
                 channels = [] :: [binary()],
                 chunk = #chunk{} :: #chunk{},
                 chunk_indexes = [] :: [binary()],
                 counts = #{} :: #{non_neg_integer() => non_neg_integer()},
                 messages = 0 :: non_neg_integer(),
                 start = ?MAX_U64 :: non_neg_integer(),
                 stop = 0 :: non_neg_integer()}).

-opaque writer() :: #writer{}.
-type message() :: #{channel := non_neg_integer(), sequence := non_neg_integer(),
                     log_time := non_neg_integer(), publish_time := non_neg_integer(),
                     data := binary()}.
-type contents() :: #{profile := binary(), library := binary(),
                      schemas := #{non_neg_integer() => #{name := binary(), encoding := binary(),
                                                          data := binary()}},
                      channels := #{non_neg_integer() => #{schema := non_neg_integer(),
                                                           topic := binary(),
                                                           encoding := binary()}},
                      messages := [message()],
                      statistics := #{message_count := non_neg_integer()}}.

%%====================================================================
%% Writer
%%====================================================================

%% @doc The library string our files carry in their header.
-spec library() -> binary().
library() ->
    %% The files' library is `toroco_live', where recording began: replay
    %% reads files written since then, and only those.
    <<"toroco_live 0.1.0">>.

%% @doc A new file: its first bytes (magic and header) and the writer.
%% Option `chunk_bytes' sets the chunk size (default 256 KiB), `profile'
%% the header's profile (default none, `<<>>'; `<<"ros2">>' for ROS 2 data).
-spec new(#{chunk_bytes => pos_integer(), profile => binary()}) -> {iodata(), writer()}.
new(Opts) ->
    Head = [?MAGIC, record(?OP_HEADER, [str(maps:get(profile, Opts, <<>>)), str(library())])],
    W = #writer{chunk_bytes = maps:get(chunk_bytes, Opts, ?CHUNK_BYTES)},
    {Head, data(Head, W)}.

%% @doc A schema record (written at once, outside chunks, and in the summary).
-spec add_schema(writer(), pos_integer(), binary(), binary()) -> {iodata(), writer()}.
add_schema(W, Id, Name, Data) ->
    add_schema(W, Id, Name, <<"jsonschema">>, Data).

%% @doc A schema record in the schema encoding `Encoding'.
-spec add_schema(writer(), pos_integer(), binary(), binary(), binary()) -> {iodata(), writer()}.
add_schema(W, Id, Name, Encoding, Data) ->
    R = record(?OP_SCHEMA, [<<Id:16/little>>, str(Name), str(Encoding), str(Data)]),
    {R, data(R, W#writer{schemas = [R | W#writer.schemas]})}.

%% @doc A channel record: JSON messages on `Topic' with schema `SchemaId'.
-spec add_channel(writer(), non_neg_integer(), pos_integer(), binary(), #{binary() => binary()}) ->
          {iodata(), writer()}.
add_channel(W, Id, SchemaId, Topic, Metadata) ->
    add_channel(W, Id, SchemaId, Topic, <<"json">>, Metadata).

%% @doc A channel record: messages encoded as `Encoding' on `Topic'.
-spec add_channel(writer(), non_neg_integer(), pos_integer(), binary(), binary(),
                  #{binary() => binary()}) -> {iodata(), writer()}.
add_channel(W, Id, SchemaId, Topic, Encoding, Metadata) ->
    R = record(?OP_CHANNEL, [<<Id:16/little, SchemaId:16/little>>, str(Topic),
                             str(Encoding), map_ss(Metadata)]),
    {R, data(R, W#writer{channels = [R | W#writer.channels]})}.

%% @doc One message, logged and published at `T' (ns). Returns the bytes of
%% a chunk when this message closed one.
-spec add_message(writer(), non_neg_integer(), non_neg_integer(), non_neg_integer(), binary()) ->
          {iodata(), writer()}.
add_message(W = #writer{chunk = C, counts = Counts, messages = N}, Channel, Seq, T, Data) ->
    R = record(?OP_MESSAGE, [<<Channel:16/little, Seq:32/little, T:64/little, T:64/little>>, Data]),
    Index = maps:update_with(Channel, fun(L) -> [{T, C#chunk.size} | L] end,
                             [{T, C#chunk.size}], C#chunk.index),
    C1 = C#chunk{records = [R | C#chunk.records], size = C#chunk.size + byte_size(R),
                 start = min(T, C#chunk.start), stop = max(T, C#chunk.stop), index = Index},
    W1 = W#writer{chunk = C1, counts = Counts#{Channel => maps:get(Channel, Counts, 0) + 1},
                  messages = N + 1, start = min(T, W#writer.start), stop = max(T, W#writer.stop)},
    case C1#chunk.size >= W#writer.chunk_bytes of
        true -> close_chunk(W1);
        false -> {[], W1}
    end.

%% @doc The last bytes of the file: the open chunk, data end, summary, footer.
-spec finish(writer()) -> iodata().
finish(W0) ->
    {Chunk, W} = close_chunk(W0),
    DataEnd = record(?OP_DATA_END, <<(W#writer.crc):32/little>>),
    SummaryStart = W#writer.offset + byte_size(DataEnd),
    Groups = [{?OP_SCHEMA, lists:reverse(W#writer.schemas)},
              {?OP_CHANNEL, lists:reverse(W#writer.channels)},
              {?OP_STATISTICS, [stats_record(W)]},
              {?OP_CHUNK_INDEX, lists:reverse(W#writer.chunk_indexes)}],
    {Summary, Offsets, _} =
        lists:foldl(fun({_, []}, Acc) -> Acc;
                       ({Op, Rs}, {S, O, At}) ->
                            Len = iolist_size(Rs),
                            Off = record(?OP_SUMMARY_OFFSET, <<Op:8, At:64/little, Len:64/little>>),
                            {[S, Rs], [O, Off], At + Len}
                    end, {[], [], SummaryStart}, Groups),
    OffsetStart = SummaryStart + iolist_size(Summary),
    FooterHead = <<?OP_FOOTER:8, 20:64/little, SummaryStart:64/little, OffsetStart:64/little>>,
    Crc = erlang:crc32([Summary, Offsets, FooterHead]),
    [Chunk, DataEnd, Summary, Offsets, FooterHead, <<Crc:32/little>>, ?MAGIC].

%% @doc Bytes handed out so far (the file's size if all were written).
-spec bytes_written(writer()) -> non_neg_integer().
bytes_written(#writer{offset = O}) -> O.

%% @doc Messages added so far.
-spec message_count(writer()) -> non_neg_integer().
message_count(#writer{messages = N}) -> N.

close_chunk(W = #writer{chunk = #chunk{size = 0}}) ->
    {[], W};
close_chunk(W = #writer{chunk = C, offset = Offset}) ->
    Records = lists:reverse(C#chunk.records),
    Size = C#chunk.size,
    Chunk = record(?OP_CHUNK, [<<(C#chunk.start):64/little, (C#chunk.stop):64/little,
                                 Size:64/little, (erlang:crc32(Records)):32/little>>,
                               str(<<>>), <<Size:64/little>>, Records]),
    ChunkLen = byte_size(Chunk),
    {Indexes, IndexOffsets, _} =
        lists:foldl(fun({Ch, Entries}, {Acc, Offs, At}) ->
                            Body = << <<T:64/little, O:64/little>> || {T, O} <- lists:reverse(Entries) >>,
                            R = record(?OP_MESSAGE_INDEX, [<<Ch:16/little>>, bytes32(Body)]),
                            {[Acc, R], [{Ch, At} | Offs], At + byte_size(R)}
                    end, {[], [], Offset + ChunkLen}, lists:sort(maps:to_list(C#chunk.index))),
    IndexLen = iolist_size(Indexes),
    OffsetMap = bytes32(<< <<Ch:16/little, At:64/little>> || {Ch, At} <- lists:reverse(IndexOffsets) >>),
    ChunkIndex = record(?OP_CHUNK_INDEX,
                        [<<(C#chunk.start):64/little, (C#chunk.stop):64/little,
                           Offset:64/little, ChunkLen:64/little>>, OffsetMap,
                         <<IndexLen:64/little>>, str(<<>>), <<Size:64/little, Size:64/little>>]),
    Bytes = [Chunk, Indexes],
    {Bytes, data(Bytes, W#writer{chunk = #chunk{},
                                 chunk_indexes = [ChunkIndex | W#writer.chunk_indexes]})}.

stats_record(#writer{messages = N, schemas = S, channels = Ch, chunk_indexes = Ci,
                   counts = Counts, start = Start, stop = Stop}) ->
    {Start1, Stop1} = case N of 0 -> {0, 0}; _ -> {Start, Stop} end,
    PerChannel = << <<C:16/little, K:64/little>> || {C, K} <- lists:sort(maps:to_list(Counts)) >>,
    record(?OP_STATISTICS, [<<N:64/little, (length(S)):16/little, (length(Ch)):32/little,
                              0:32, 0:32, (length(Ci)):32/little,
                              Start1:64/little, Stop1:64/little>>, bytes32(PerChannel)]).

data(Bytes, W = #writer{offset = O, crc = Crc}) ->
    W#writer{offset = O + iolist_size(Bytes), crc = erlang:crc32(Crc, Bytes)}.

record(Op, Content) ->
    Bin = iolist_to_binary(Content),
    <<Op:8, (byte_size(Bin)):64/little, Bin/binary>>.

str(B) -> bytes32(B).

bytes32(B) -> <<(byte_size(B)):32/little, B/binary>>.

map_ss(M) ->
    bytes32(iolist_to_binary([[str(K), str(V)] || {K, V} <- lists:sort(maps:to_list(M))])).

%%====================================================================
%% Reader
%%====================================================================

%% @doc The contents of a whole MCAP file, checked: `{error, Reason}' for a
%% file too short, without the magic, truncated, with a bad CRC, a
%% compressed chunk, or a record that does not parse.
-spec read(binary()) -> {ok, contents()} | {error, term()}.
read(Bin) when byte_size(Bin) < 8 + 9 + 8 + 29 ->
    {error, {not_mcap, too_short}};
read(<<Magic:8/binary, _/binary>> = Bin) when Magic =:= ?MAGIC ->
    MagicAtEnd = binary:part(Bin, byte_size(Bin) - 8, 8),
    case MagicAtEnd of
        ?MAGIC ->
            try contents(Bin)
            catch throw:Reason -> {error, Reason};
                  error:_ -> {error, {not_mcap, malformed_record}}
            end;
        _ ->
            {error, {not_mcap, truncated}}
    end;
read(_) ->
    {error, {not_mcap, no_magic}}.

contents(Bin) ->
    Size = byte_size(Bin),
    <<?OP_FOOTER:8, 20:64/little, SummaryStart:64/little, OffsetStart:64/little,
      SummaryCrc:32/little>> = binary:part(Bin, Size - 8 - 29, 29),
    SummaryStart >= 8 + 13 andalso SummaryStart =< Size - 37 orelse throw({not_mcap, bad_footer}),
    Checked = binary:part(Bin, SummaryStart, Size - 8 - 4 - SummaryStart),
    SummaryCrc =:= 0 orelse erlang:crc32(Checked) =:= SummaryCrc
        orelse throw({not_mcap, summary_crc}),
    OffsetStart >= SummaryStart orelse throw({not_mcap, bad_footer}),
    DataEndAt = SummaryStart - 13,
    <<?OP_DATA_END:8, 4:64/little, DataCrc:32/little>> = binary:part(Bin, DataEndAt, 13),
    Data = binary:part(Bin, 0, DataEndAt),
    DataCrc =:= 0 orelse erlang:crc32(Data) =:= DataCrc orelse throw({not_mcap, data_crc}),
    <<_:8/binary, Records/binary>> = Data,
    {Header, Rest} = next_record(Records),
    {?OP_HEADER, <<PL:32/little, Profile:PL/binary, LL:32/little, Library:LL/binary>>} = Header,
    Acc = lists:foldl(fun collect/2, #{schemas => #{}, channels => #{}, messages => []},
                      all_records(Rest)),
    Summary = binary:part(Bin, SummaryStart, OffsetStart - SummaryStart),
    Stats = lists:foldl(fun({?OP_STATISTICS, <<N:64/little, _/binary>>}, _) -> #{message_count => N};
                           (_, S) -> S
                        end, #{message_count => length(maps:get(messages, Acc))},
                        all_records(Summary)),
    {ok, Acc#{profile => Profile, library => Library,
              messages := lists:reverse(maps:get(messages, Acc)), statistics => Stats}}.

all_records(<<>>) -> [];
all_records(Bin) ->
    {R, Rest} = next_record(Bin),
    [R | all_records(Rest)].

next_record(<<Op:8, Len:64/little, Content:Len/binary, Rest/binary>>) ->
    {{Op, Content}, Rest};
next_record(_) ->
    throw({not_mcap, truncated_record}).

collect({?OP_SCHEMA, <<Id:16/little, NL:32/little, Name:NL/binary, EL:32/little, Enc:EL/binary,
                       DL:32/little, D:DL/binary>>}, Acc = #{schemas := S}) ->
    Acc#{schemas := S#{Id => #{name => Name, encoding => Enc, data => D}}};
collect({?OP_CHANNEL, <<Id:16/little, SId:16/little, TL:32/little, Topic:TL/binary,
                        EL:32/little, Enc:EL/binary, _/binary>>}, Acc = #{channels := C}) ->
    Acc#{channels := C#{Id => #{schema => SId, topic => Topic, encoding => Enc}}};
collect({?OP_MESSAGE, <<Ch:16/little, Seq:32/little, LogT:64/little, PubT:64/little, D/binary>>},
        Acc = #{messages := M}) ->
    Acc#{messages := [#{channel => Ch, sequence => Seq, log_time => LogT,
                        publish_time => PubT, data => D} | M]};
collect({?OP_CHUNK, <<_:64, _:64, USize:64/little, UCrc:32/little, CL:32/little,
                      Compression:CL/binary, RL:64/little, Records:RL/binary>>}, Acc) ->
    Compression =:= <<>> orelse throw({unsupported_compression, Compression}),
    byte_size(Records) =:= USize orelse throw({not_mcap, chunk_size}),
    UCrc =:= 0 orelse erlang:crc32(Records) =:= UCrc orelse throw({not_mcap, chunk_crc}),
    lists:foldl(fun collect/2, Acc, all_records(Records));
collect({Op, _}, Acc) when Op =:= ?OP_MESSAGE_INDEX; Op =:= ?OP_DATA_END; Op > 16#0F;
                            Op =:= 16#09; Op =:= 16#0C ->
    Acc;
collect({Op, _}, _Acc) ->
    throw({not_mcap, {unexpected_record, Op}}).
