%% @doc (API) WebSocket (RFC 6455) for the bridges: the opening handshake
%% answered through mochiweb, and the frame codec as pure code.
%%
%% mochiweb parses the HTTP request and writes the 101 answer; the frames
%% are ours because `mochiweb_websocket' (3.1) only sends text frames, does
%% not answer a subprotocol, and ends its loop on any message that is not
%% from the socket, while the Foxglove protocol needs binary frames, the
%% `foxglove.websocket.v1' subprotocol, and a connection process that also
%% receives the robot's events.
%%
%% {@link decode/2} takes bytes and a decoder state and returns whole
%% messages (`{text, Bin}', `{binary, Bin}', `{ping, Bin}', `{pong, Bin}',
%% `{close, Code, Reason}'), reassembling fragments, or an error naming the
%% fault (unmasked client frame, reserved bits, a message over the size
%% limit, a control frame fragmented or too long).
%%
%% The client's side, for the rosbridge client (`toroco_ros_client'):
%% {@link client_decoder/1} reads a server's frames (unmasked; a masked
%% one is an error), {@link client_frame/2} and {@link client_close_frame/2}
%% write masked frames with a fresh key each (from the kernel's random
%% bytes, read a few thousand at a time), {@link accept_key/1} is the
%% `Sec-WebSocket-Accept' a server must answer to a key.
-module(toroco_live_ws_frame).

-export([accept/2, decoder/1, decode/2, frame/2, close_frame/2]).
-export([client_decoder/1, client_frame/2, client_close_frame/2, accept_key/1]).

-export_type([decoder/0, message/0]).

-define(GUID, <<"258EAFA5-E914-47DA-95CA-C5AB0DC85B11">>).
%% The masking keys not used yet, and how many bytes are read at once.
-define(MASK_KEY, '$toroco_live_ws_masks').
-define(MASK_POOL, 4096).

-record(dec, {buffer = <<>> :: binary(),
              max :: pos_integer(),
              %% the frames this side reads: a server's are unmasked
              masked = true :: boolean(),
              fragments = none :: none | {text | binary, [binary()], non_neg_integer()}}).

-opaque decoder() :: #dec{}.
-type message() :: {text | binary | ping | pong, binary()} | {close, non_neg_integer() | none, binary()}.

%% @doc Answers a WebSocket upgrade that asks for `Subprotocol' (mochiweb
%% request in, 101 written), or with `none' one that may ask for any or none
%% (rosbridge clients name none: the answer names none either);
%% `{error, Why}' when the request is not one.
-spec accept(mochiweb_request:request(), binary() | none) -> ok | {error, term()}.
accept(Req, Subprotocol) ->
    Header = fun(H) -> case mochiweb_request:get_header_value(H, Req) of
                           undefined -> <<>>;
                           V -> list_to_binary(V)
                       end
             end,
    Upgrade = string:lowercase(Header("upgrade")),
    Key = Header("sec-websocket-key"),
    Protocols = [string:trim(P) || P <- binary:split(Header("sec-websocket-protocol"), <<",">>, [global])],
    if
        Upgrade =/= <<"websocket">> -> {error, not_websocket};
        Key =:= <<>> -> {error, no_key};
        true ->
            case Subprotocol =:= none orelse lists:member(Subprotocol, Protocols) of
                false -> {error, {subprotocol, Protocols}};
                true ->
                    Accept = accept_key(Key),
                    Named = [{"Sec-WebSocket-Protocol", binary_to_list(Subprotocol)}
                             || Subprotocol =/= none],
                    _ = mochiweb_request:respond(
                      {101, [{"Upgrade", "websocket"}, {"Connection", "Upgrade"},
                             {"Sec-WebSocket-Accept", binary_to_list(Accept)} | Named], ""}, Req),
                    ok
            end
    end.

%% @doc A decoder for messages of at most `MaxBytes'.
-spec decoder(pos_integer()) -> decoder().
decoder(MaxBytes) ->
    #dec{max = MaxBytes}.

%% @doc A decoder of a server's frames, for a client.
-spec client_decoder(pos_integer()) -> decoder().
client_decoder(MaxBytes) ->
    #dec{max = MaxBytes, masked = false}.

%% @doc The `Sec-WebSocket-Accept' value that answers `Key'.
-spec accept_key(binary()) -> binary().
accept_key(Key) ->
    base64:encode(toroco_live_digest:sha(<<Key/binary, ?GUID/binary>>)).

%% @doc Whole messages from `Bytes' and what came before them.
-spec decode(binary(), decoder()) -> {ok, [message()], decoder()} | {error, term()}.
decode(Bytes, D = #dec{buffer = Buf}) ->
    messages(D#dec{buffer = <<Buf/binary, Bytes/binary>>}, []).

messages(D = #dec{buffer = Buf, max = Max, masked = Masked}, Acc) ->
    case frame_of(Buf, Max, Masked) of
        more -> {ok, lists:reverse(Acc), D};
        {error, _} = E -> E;
        {ok, Fin, Op, Payload, Rest} ->
            case message(Fin, Op, Payload, D#dec{buffer = Rest}) of
                {ok, none, D1} -> messages(D1, Acc);
                {ok, M, D1} -> messages(D1, [M | Acc]);
                {error, _} = E -> E
            end
    end.

frame_of(<<_:1, Rsv:3, _/bits>>, _, _) when Rsv =/= 0 -> {error, reserved_bits};
frame_of(<<_:8, 0:1, _/bits>>, _, true) -> {error, unmasked_frame};
frame_of(<<_:8, 1:1, _/bits>>, _, false) -> {error, masked_frame};
frame_of(<<Fin:1, 0:3, Op:4, M:1, Len:7, Rest/binary>>, Max, _Masked) ->
    case length_of(Len, Rest) of
        more -> more;
        {N, _} when N > Max -> {error, too_big};
        {N, R} -> payload(M, N, R, Fin, Op)
    end;
frame_of(_, _, _) -> more.

%% The payload (unmasked) and what follows it, or more to read.
payload(1, N, R, Fin, Op) ->
    case R of
        <<Mask:4/binary, Payload:N/binary, After/binary>> -> {ok, Fin, Op, unmask(Payload, Mask), After};
        _ -> more
    end;
payload(0, N, R, Fin, Op) ->
    case R of
        <<Payload:N/binary, After/binary>> -> {ok, Fin, Op, Payload, After};
        _ -> more
    end.

length_of(126, <<N:16, R/binary>>) -> {N, R};
length_of(127, <<0:1, N:63, R/binary>>) -> {N, R};
length_of(N, R) when N < 126 -> {N, R};
length_of(_, _) -> more.

message(_, Op, _, _) when Op >= 3, Op =< 7; Op >= 11 -> {error, {opcode, Op}};
message(Fin, Op, P, _) when Op >= 8, (Fin =:= 0 orelse byte_size(P) > 125) -> {error, bad_control_frame};
message(1, 8, <<Code:16, Reason/binary>>, D) -> {ok, {close, Code, Reason}, D};
message(1, 8, _, D) -> {ok, {close, none, <<>>}, D};
message(1, 9, P, D) -> {ok, {ping, P}, D};
message(1, 10, P, D) -> {ok, {pong, P}, D};
message(Fin, Op, P, D = #dec{fragments = none}) when Op =:= 1; Op =:= 2 ->
    Kind = case Op of 1 -> text; 2 -> binary end,
    case Fin of
        1 -> {ok, {Kind, P}, D};
        0 -> {ok, none, D#dec{fragments = {Kind, [P], byte_size(P)}}}
    end;
message(Fin, 0, P, D = #dec{fragments = {Kind, Ps, Size}, max = Max}) ->
    Size1 = Size + byte_size(P),
    if
        Size1 > Max -> {error, too_big};
        Fin =:= 1 -> {ok, {Kind, iolist_to_binary(lists:reverse([P | Ps]))}, D#dec{fragments = none}};
        true -> {ok, none, D#dec{fragments = {Kind, [P | Ps], Size1}}}
    end;
message(_, Op, _, _) -> {error, {unexpected_frame, Op}}.

unmask(Payload, <<M:32>>) ->
    Words = byte_size(Payload) div 4,
    <<Body:Words/binary-unit:32, Tail/binary>> = Payload,
    Tail1 = case Tail of
                <<>> -> <<>>;
                _ ->
                    Bits = bit_size(Tail),
                    <<T:Bits>> = Tail,
                    <<Mt:Bits, _/bits>> = <<M:32>>,
                    <<(T bxor Mt):Bits>>
            end,
    <<(<< <<(W bxor M):32>> || <<W:32>> <= Body >>)/binary, Tail1/binary>>.

%% @doc A server frame (unmasked, unfragmented).
-spec frame(text | binary | ping | pong, iodata()) -> iodata().
frame(Kind, Payload) ->
    Op = case Kind of text -> 1; binary -> 2; ping -> 9; pong -> 10 end,
    Len = iolist_size(Payload),
    Head = if
               Len < 126 -> <<1:1, 0:3, Op:4, 0:1, Len:7>>;
               Len < 65536 -> <<1:1, 0:3, Op:4, 0:1, 126:7, Len:16>>;
               true -> <<1:1, 0:3, Op:4, 0:1, 127:7, Len:64>>
           end,
    [Head, Payload].

%% @doc A close frame with a status code (1000 normal, 1002 protocol error,
%% 1008 policy, 1009 too big, 1011 server error).
-spec close_frame(non_neg_integer(), binary()) -> iodata().
close_frame(Code, Reason) ->
    R = binary:part(Reason, 0, min(byte_size(Reason), 120)),
    [<<1:1, 0:3, 8:4, 0:1, (2 + byte_size(R)):7, Code:16>>, R].

%% @doc A client frame (masked with a fresh key, unfragmented).
-spec client_frame(text | binary | ping | pong, iodata()) -> iodata().
client_frame(Kind, Payload) ->
    Op = case Kind of text -> 1; binary -> 2; ping -> 9; pong -> 10 end,
    masked(Op, iolist_to_binary(Payload)).

%% @doc A client's close frame with a status code.
-spec client_close_frame(non_neg_integer(), binary()) -> iodata().
client_close_frame(Code, Reason) ->
    R = binary:part(Reason, 0, min(byte_size(Reason), 120)),
    masked(8, <<Code:16, R/binary>>).

masked(Op, Payload) ->
    Len = byte_size(Payload),
    Head = if
               Len < 126 -> <<1:1, 0:3, Op:4, 1:1, Len:7>>;
               Len < 65536 -> <<1:1, 0:3, Op:4, 1:1, 126:7, Len:16>>;
               true -> <<1:1, 0:3, Op:4, 1:1, 127:7, Len:64>>
           end,
    Mask = mask_key(),
    [Head, Mask, unmask(Payload, Mask)].

%% A fresh masking key (RFC 6455 §5.3: from a strong source, unpredictable
%% to the page's script of a browser; here it is seen on the wire anyway).
%% The kernel's bytes are read `?MASK_POOL' at a time into the writing
%% process's dictionary, not once a frame: opening `/dev/urandom' costs
%% tens of microseconds, a frame of a robot's topic a few.
mask_key() ->
    <<Mask:4/binary, Rest/binary>> =
        case get(?MASK_KEY) of
            <<_:4/binary, _/binary>> = Pool -> Pool;
            _ -> toroco_live_digest:random_bytes(?MASK_POOL)
        end,
    put(?MASK_KEY, Rest),
    Mask.
