%% @doc (API, a behaviour) One WebSocket client of a `toroco_live' port, whatever protocol it
%% speaks: the mochiweb connection process that answered the upgrade
%% becomes this gen_server, owns the socket and runs the WebSocket's side of
%% the conversation, and a callback module (the Foxglove bridge's
%% `toroco_live_foxglove_conn', the rosbridge server's
%% `toroco_ros_server_conn') runs the protocol's.
%%
%% This module does: the upgrade (`toroco_live_ws_frame:accept/2') or a
%% 400 naming what was wrong; the socket's options (one read at a time,
%% sends bounded by `?SEND_TIMEOUT_MS', after which the client is gone);
%% frames cut from the bytes with a size bound; pings answered; the close
%% handshake (our close frame, then reading on for `?CLOSING_MS' until the
%% client closes, so it gets the frame); the socket closed at the end; and
%% the idle bound: a client silent for `ping_ms' (app env `ws_ping_ms',
%% default 30000) gets a ping, which every WebSocket client answers by
%% itself, and one silent for twice that is closed (1001), so half-open
%% connections do not hold slots forever. The
%% callback gets each text or binary message, every other Erlang message,
%% and a framing error, and answers with its new state or a close.
%%
%% Sending from a callback: {@link send/2} (a frame of
%% `toroco_live_ws_frame:frame/2'): a client that cannot take it within the
%% send timeout ends the connection (the process exits `normal').
-module(toroco_live_ws_conn).
-behaviour(gen_server).

-export([serve/3, send/2, offer/5]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([result/1, socket/0]).

-define(SEND_TIMEOUT_MS, 5000).
%% After our close frame, how long the client has to close its side.
-define(CLOSING_MS, 2000).
-define(PING_MS, 30000).

-type socket() :: mochiweb_socket:socket().
%% What a callback answers: go on with the new state, or close with a
%% WebSocket close code and a reason (sent as text in the close frame).
-type result(State) :: {ok, State} | {close, 1000..4999, term(), State}.

%% The protocol's side, once the upgrade succeeded: `State' or a reason the
%% connection cannot start (the client gets close code 1011).
-callback join(socket(), Args :: term()) -> {ok, State :: term()} | {error, term()}.
%% A text or binary message from the client.
-callback handle_frame({text | binary, binary()}, State) -> result(State).
%% Any other Erlang message to the connection (the hub's).
-callback handle_info(term(), State) -> result(State).
%% The client's bytes are not WebSocket frames (`too_big': a message over
%% the bound): the callback may tell the client why before the close.
-callback handle_framing_error(term(), State) -> result(State).

-record(ws, {socket :: socket(),
             decoder :: toroco_live_ws_frame:decoder(),
             mod :: module(),
             state :: term(),
             ping_ms :: pos_integer(),
             last_in :: integer(),
             closing = false :: boolean()}).

%% @doc The mochiweb loop's answer to a request on a WebSocket port: an
%% upgrade (to `Subprotocol', or `none') becomes a connection run by `Mod'
%% with messages up to `Max' bytes; anything else gets a 400 saying what
%% `Endpoint' is and what was wrong.
-spec serve(mochiweb_request:request(), #{subprotocol := binary() | none, max := pos_integer(),
                                          endpoint := iodata()},
            {module(), term()}) -> ok.
serve(Req, #{subprotocol := Sub, max := Max, endpoint := Endpoint}, {Mod, Args}) ->
    case toroco_live_ws_frame:accept(Req, Sub) of
        ok ->
            Socket = mochiweb_request:get(socket, Req),
            ok = mochiweb_socket:setopts(Socket, [{packet, raw}, {send_timeout, ?SEND_TIMEOUT_MS},
                                                  {send_timeout_close, true}]),
            case Mod:join(Socket, Args) of
                {ok, State} ->
                    ok = mochiweb_socket:setopts(Socket, [{active, once}]),
                    Ping = application:get_env(toroco_live, ws_ping_ms, ?PING_MS),
                    _ = erlang:send_after(Ping, self(), {?MODULE, idle_check}),
                    gen_server:enter_loop(?MODULE, [],
                                          #ws{socket = Socket, decoder = toroco_live_ws_frame:decoder(Max),
                                              mod = Mod, state = State, ping_ms = Ping,
                                              last_in = now_ms()});
                {error, _} ->
                    _ = mochiweb_socket:send(Socket, toroco_live_ws_frame:close_frame(1011, <<"server down">>)),
                    exit(normal)
            end;
        {error, Why} ->
            Text = io_lib:format("~s: ~0p~n", [Endpoint, Why]),
            _ = mochiweb_request:respond({400, [{"Content-Type", "text/plain"}], Text}, Req),
            ok
    end.

%% @doc Sends a frame, or ends the connection when the client cannot take it.
-spec send(socket(), iodata()) -> ok.
send(Socket, Frame) ->
    case mochiweb_socket:send(Socket, Frame) of
        ok -> ok;
        {error, _} -> exit(normal)
    end.

%% @doc A hub's bounded send to one of its connections: `Msg' goes to
%% `Conn' unless `Conn''s mailbox holds more than `Max' messages, in which
%% case it is counted in `Dropped' (a count per connection); the next message
%% that goes is preceded by `DroppedMsg(Count)', so the client hears how many
%% it missed. `gone' when `Conn' is not alive.
-spec offer(pid(), term(), fun((pos_integer()) -> term()), pos_integer(),
            #{pid() => pos_integer()}) -> {sent | dropped | gone, #{pid() => pos_integer()}}.
offer(Conn, Msg, DroppedMsg, Max, Dropped) ->
    case erlang:process_info(Conn, message_queue_len) of
        {message_queue_len, N} when N > Max ->
            {dropped, maps:update_with(Conn, fun(K) -> K + 1 end, 1, Dropped)};
        {message_queue_len, _} ->
            _ = case Dropped of
                    #{Conn := Missed} -> Conn ! DroppedMsg(Missed);
                    #{} -> ok
                end,
            Conn ! Msg,
            {sent, maps:remove(Conn, Dropped)};
        undefined ->
            {gone, Dropped}
    end.

%%====================================================================
%% gen_server
%%====================================================================

-spec init(term()) -> {stop, not_started_this_way}.
init(_) ->
    {stop, not_started_this_way}.

-spec handle_call(term(), gen_server:from(), #ws{}) -> {reply, term(), #ws{}}.
handle_call(_, _From, W) ->
    {reply, {error, unknown_call}, W}.

-spec handle_cast(term(), #ws{}) -> {noreply, #ws{}}.
handle_cast(_, W) ->
    {noreply, W}.

-spec handle_info(term(), #ws{}) -> {noreply, #ws{}} | {noreply, #ws{}, timeout()}
                                        | {stop, normal, #ws{}}.
handle_info({Tcp, _, _}, W = #ws{socket = S, closing = true}) when Tcp =:= tcp; Tcp =:= ssl ->
    %% Read on until the client closes: closing with unread bytes would
    %% reset the connection and lose our close frame.
    ok = mochiweb_socket:setopts(S, [{active, once}]),
    {noreply, W, ?CLOSING_MS};
handle_info(timeout, W = #ws{closing = true}) ->
    {stop, normal, W};
handle_info(_, W = #ws{closing = true}) ->
    {noreply, W, ?CLOSING_MS};
handle_info({Tcp, _, Bytes}, W0 = #ws{socket = S, decoder = D, mod = Mod, state = State})
  when Tcp =:= tcp; Tcp =:= ssl ->
    W = W0#ws{last_in = now_ms()},
    case toroco_live_ws_frame:decode(Bytes, D) of
        {ok, Messages, D1} ->
            case lists:foldl(fun message/2, {ok, W#ws{decoder = D1}}, Messages) of
                {ok, W1} ->
                    ok = mochiweb_socket:setopts(S, [{active, once}]),
                    {noreply, W1};
                {close, Code, Why, W1} ->
                    close(W1, Code, Why)
            end;
        {error, Why} ->
            Code = case Why of too_big -> 1009; _ -> 1002 end,
            case Mod:handle_framing_error(Why, State) of
                {ok, State1} -> close(W#ws{state = State1}, Code, Why);
                {close, _, _, State1} -> close(W#ws{state = State1}, Code, Why)
            end
    end;
handle_info({?MODULE, idle_check}, W = #ws{socket = S, ping_ms = Ping, last_in = Last}) ->
    Silent = now_ms() - Last,
    if
        Silent >= 2 * Ping ->
            close(W, 1001, idle);
        Silent >= Ping ->
            send(S, toroco_live_ws_frame:frame(ping, <<>>)),
            _ = erlang:send_after(Ping, self(), {?MODULE, idle_check}),
            {noreply, W};
        true ->
            _ = erlang:send_after(Ping - Silent, self(), {?MODULE, idle_check}),
            {noreply, W}
    end;
handle_info({Closed, _}, W) when Closed =:= tcp_closed; Closed =:= ssl_closed ->
    {stop, normal, W};
handle_info({Err, _, _}, W) when Err =:= tcp_error; Err =:= ssl_error ->
    {stop, normal, W};
handle_info(Msg, W = #ws{mod = Mod, state = State}) ->
    case Mod:handle_info(Msg, State) of
        {ok, State1} -> {noreply, W#ws{state = State1}};
        {close, Code, Why, State1} -> close(W#ws{state = State1}, Code, Why)
    end.

-spec terminate(term(), #ws{}) -> ok.
terminate(_, #ws{socket = S}) ->
    mochiweb_socket:close(S).

%% One message of the client's, while no close is under way.
message(_, Closing = {close, _, _, _}) ->
    Closing;
message({ping, P}, {ok, W = #ws{socket = S}}) ->
    send(S, toroco_live_ws_frame:frame(pong, P)),
    {ok, W};
message({pong, _}, Acc) ->
    Acc;
message({close, _, _}, {ok, W}) ->
    {close, 1000, normal, W};
message(Frame, {ok, W = #ws{mod = Mod, state = State}}) ->
    case Mod:handle_frame(Frame, State) of
        {ok, State1} -> {ok, W#ws{state = State1}};
        {close, Code, Why, State1} -> {close, Code, Why, W#ws{state = State1}}
    end.

close(W = #ws{socket = S}, Code, Why) ->
    Text = iolist_to_binary(io_lib:format("~0p", [Why])),
    case mochiweb_socket:send(S, toroco_live_ws_frame:close_frame(Code, Text)) of
        ok ->
            ok = mochiweb_socket:setopts(S, [{active, once}]),
            {noreply, W#ws{closing = true}, ?CLOSING_MS};
        {error, _} ->
            {stop, normal, W}
    end.

now_ms() -> erlang:monotonic_time(millisecond).
