%% Test clients of the dashboard: HTTP requests with httpc, and a small
%% WebSocket client (RFC 6455, client side) that hands each text frame,
%% decoded, to its owner as `{wsc, Pid, Json}'.
-module(toroco_live_test_client).

-export([get/2, get/3, post/3, post/4, ws/2, ws/3, ws_send/2, ws_send_raw/2, ws_close/1,
         ws_next/3, raw_ws/2, raw_ws/3, handshake/3, handshake/4]).

%%--------------------------------------------------------------------- HTTP

get(Port, Path) -> get(Port, Path, []).

get(Port, Path, Headers) ->
    request(get, {url(Port, Path), Headers}).

post(Port, Path, Body) -> post(Port, Path, Body, []).

post(Port, Path, Body, Headers) ->
    request(post, {url(Port, Path), Headers, "application/json", Body}).

request(Method, Req) ->
    {ok, {{_, Status, _}, Headers, Body}} =
        httpc:request(Method, Req, [{timeout, 10000}], [{body_format, binary}]),
    Json = case proplists:get_value("content-type", Headers) of
               "application/json" -> jiffy:decode(Body, [return_maps]);
               _ -> Body
           end,
    {Status, Headers, Json}.

url(Port, Path) -> "http://127.0.0.1:" ++ integer_to_list(Port) ++ Path.

%%--------------------------------------------------------------------- WebSocket

%% A client process connected to /ws (Query: "" or "?k=v"), with more
%% headers on the upgrade request (`Authorization', `Cookie', `Origin').
ws(Port, Query) -> ws(Port, Query, []).

ws(Port, Query, Headers) ->
    Owner = self(),
    Pid = spawn_link(fun() ->
                             {ok, Sock, Rest} = raw_ws(Port, Query, Headers),
                             ok = inet:setopts(Sock, [{active, true}]),
                             Owner ! {wsc_up, self()},
                             loop(Sock, Owner, frames(Rest, Sock, Owner))
                     end),
    receive {wsc_up, Pid} -> Pid after 5000 -> error(ws_connect_timeout) end.

%% A connected socket after the handshake, passive: {ok, Sock, BytesAfterIt}.
raw_ws(Port, Query) -> raw_ws(Port, Query, []).

raw_ws(Port, Query, Headers) ->
    {ok, Sock} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false},
                                                        {recbuf, 4096}, {packet, 0}]),
    case handshake(Sock, Port, Query, Headers) of
        {101, Rest} -> {ok, Sock, Rest};
        Other -> gen_tcp:close(Sock), {error, Other}
    end.

%% Sends the upgrade request; {Status, BytesAfterHeaders}.
handshake(Sock, Port, Query) -> handshake(Sock, Port, Query, []).

handshake(Sock, Port, Query, Headers) ->
    Key = base64:encode(crypto:strong_rand_bytes(16)),
    ok = gen_tcp:send(Sock, ["GET /ws", Query, " HTTP/1.1\r\nHost: 127.0.0.1:", integer_to_list(Port),
                             "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n",
                             [[K, ": ", V, "\r\n"] || {K, V} <- Headers],
                             "Sec-WebSocket-Key: ", Key, "\r\nSec-WebSocket-Version: 13\r\n\r\n"]),
    read_headers(Sock, <<>>).

read_headers(Sock, Acc) ->
    case binary:split(Acc, <<"\r\n\r\n">>) of
        [Head, Rest] ->
            <<"HTTP/1.1 ", Code:3/binary, _/binary>> = Head,
            {binary_to_integer(Code), Rest};
        [_] ->
            {ok, More} = gen_tcp:recv(Sock, 0, 5000),
            read_headers(Sock, <<Acc/binary, More/binary>>)
    end.

ws_send(Pid, Json) -> ws_send_raw(Pid, jiffy:encode(Json)).

ws_send_raw(Pid, Bin) -> Pid ! {send, iolist_to_binary(Bin)}, ok.

ws_close(Pid) -> unlink(Pid), exit(Pid, kill), ok.

%% The next frame from Pid for which Pred holds, within Timeout ms.
ws_next(Pid, Pred, Timeout) ->
    Deadline = erlang:monotonic_time(millisecond) + Timeout,
    next(Pid, Pred, Deadline).

next(Pid, Pred, Deadline) ->
    Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
    receive
        {wsc, Pid, Json} ->
            case Pred(Json) of
                true -> {ok, Json};
                false -> next(Pid, Pred, Deadline)
            end;
        {wsc_closed, Pid} -> {error, closed}
    after Left -> {error, timeout}
    end.

loop(Sock, Owner, Buf) ->
    receive
        {tcp, Sock, Data} -> loop(Sock, Owner, frames(<<Buf/binary, Data/binary>>, Sock, Owner));
        {tcp_closed, Sock} -> Owner ! {wsc_closed, self()};
        {send, Bin} -> ok = gen_tcp:send(Sock, mask(1, Bin)), loop(Sock, Owner, Buf)
    end.

frames(<<_:4, Op:4, 0:1, 126:7, Len:16, P:Len/binary, Rest/binary>>, Sock, Owner) ->
    deliver(Op, P, Sock, Owner), frames(Rest, Sock, Owner);
frames(<<_:4, Op:4, 0:1, 127:7, Len:64, P:Len/binary, Rest/binary>>, Sock, Owner) ->
    deliver(Op, P, Sock, Owner), frames(Rest, Sock, Owner);
frames(<<_:4, Op:4, 0:1, Len:7, P:Len/binary, Rest/binary>>, Sock, Owner) when Len < 126 ->
    deliver(Op, P, Sock, Owner), frames(Rest, Sock, Owner);
frames(Partial, _Sock, _Owner) ->
    Partial.

deliver(1, P, _Sock, Owner) -> Owner ! {wsc, self(), jiffy:decode(P, [return_maps])};
%% a ping is answered, as every WebSocket client does (the server closes
%% one that stays silent)
deliver(9, P, Sock, _Owner) -> gen_tcp:send(Sock, mask(10, P));
deliver(_, _, _, _) -> ok.

mask(Op, Bin) ->
    Key = crypto:strong_rand_bytes(4),
    Len = byte_size(Bin),
    LenBits = if Len < 126 -> <<1:1, Len:7>>;
                 Len < 65536 -> <<1:1, 126:7, Len:16>>;
                 true -> <<1:1, 127:7, Len:64>>
              end,
    <<1:1, 0:3, Op:4, LenBits/bitstring, Key/binary, (xor_mask(Bin, Key))/binary>>.

xor_mask(Bin, <<K:32>>) ->
    Pad = (4 - byte_size(Bin) rem 4) rem 4,
    <<Padded/binary>> = <<Bin/binary, 0:(Pad * 8)>>,
    Masked = << <<(W bxor K):32>> || <<W:32>> <= Padded >>,
    binary:part(Masked, 0, byte_size(Bin)).
