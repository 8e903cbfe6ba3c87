%% @doc One browser's WebSocket: the page's live state goes out, controls
%% come in.
%%
%% Two processes per client. The connection process (mochiweb's, running
%% `mochiweb_websocket''s loop) reads the client's frames, each a control
%% request (`toroco_live_control', answered on the socket with
%% `{"type": "reply", "id": Id, "ok": true}' or `{"type": "error", "id": Id,
%% "error": Reason, "message": Why}'). The sender, linked to it, joins
%% `toroco_live_hub' and writes what the hub pushes; the hub pushes one
%% message at a time and waits for the sender's ack, so a client that does
%% not read blocks only its own sender, whose mailbox holds at most one
%% push. A write that stays blocked past 5 seconds closes
%% the socket, which ends both processes.
%%
%% Refusals at connection time are HTTP answers: 400 when the request is
%% not a WebSocket upgrade, 503 `too_many_clients' past `max_clients'.
%% Controls need the token on the URL (`/ws?token=T') or the bearer
%% header; without it every control is refused (read-only). A frame larger
%% than `max_body' is refused with `too_large' and the connection stays.
-module(toroco_live_ws).

-export([upgrade/2, frames/3]).

-define(SEND_TIMEOUT, 5000).

%% @doc Turns an HTTP request on `/ws' into a client (never returns after
%% the upgrade), or answers why not.
-spec upgrade(term(), boolean()) -> term().
upgrade(Req, Authorized) ->
    case string:lowercase(header(Req, "upgrade")) of
        "websocket" -> join(Req, Authorized);
        _ -> refuse(Req, 400, not_websocket, <<"/ws is a WebSocket: send Upgrade: websocket">>)
    end.

header(Req, Name) ->
    case mochiweb_request:get_header_value(Name, Req) of
        undefined -> "";
        V -> V
    end.

join(Req, Authorized) ->
    Sender = proc_lib:spawn_link(fun() -> sender_wait() end),
    case toroco_live_hub:join(Sender) of
        {ok, Hello} ->
            Socket = mochiweb_request:get(socket, Req),
            {Reentry, Reply} = mochiweb_websocket:upgrade_connection(Req, {?MODULE, frames}),
            _ = mochiweb_socket:setopts(Socket, [{send_timeout, ?SEND_TIMEOUT},
                                                 {send_timeout_close, true}]),
            Sender ! {go, Reply, Hello},
            Reentry(#{authorized => Authorized, max => toroco_live_config:get(max_body, 16384),
                      reply => Reply});
        {error, Reason} ->
            unlink(Sender),
            exit(Sender, kill),
            refuse(Req, 503, Reason, case Reason of
                                         too_many_clients ->
                                             <<"the dashboard has as many clients as it takes">>;
                                         _ -> <<"the dashboard is not running">>
                                     end)
    end.

refuse(Req, Status, Reason, Message) ->
    mochiweb_request:respond({Status, [{"Content-Type", "application/json"}],
                              toroco_live_json:encode(#{<<"error">> => toroco_live_json:value(Reason),
                                                        <<"message">> => Message})}, Req).

%% @doc mochiweb's callback with the frames that came in one read.
-spec frames([binary()], map(), fun((iodata()) -> term())) -> map().
frames(Payloads, State, Reply) when is_list(Payloads) ->
    lists:foldl(fun(P, S) -> frame(P, S, Reply) end, State, Payloads);
frames(Payload, State, Reply) ->
    frame(Payload, State, Reply).

frame(<<>>, State, _Reply) ->
    State;
frame(Payload, State = #{authorized := Auth, max := Max}, Reply) ->
    {Id, Answer} = case toroco_live_control:decode(Payload, Max) of
                       {ok, Req} -> {request_id(Req), toroco_live_control:run(Auth, Req, Max)};
                       Refused -> {null, Refused}
                   end,
    Json = case Answer of
               {ok, Ok} -> Ok#{<<"type">> => <<"reply">>, <<"id">> => Id};
               {error, _Status, Reason, Message} ->
                   #{<<"type">> => <<"error">>, <<"id">> => Id,
                     <<"error">> => toroco_live_json:value(Reason), <<"message">> => Message}
           end,
    _ = Reply(toroco_live_json:encode(Json)),
    State.

request_id(#{<<"id">> := Id}) when is_integer(Id); is_binary(Id) -> Id;
request_id(#{}) -> null.

%%====================================================================
%% The sender
%%====================================================================

sender_wait() ->
    receive
        {go, Reply, Hello} ->
            write(Reply, [Hello]),
            sender(Reply)
    end.

sender(Reply) ->
    receive
        {toroco_live_hub, frames, Frames} ->
            write(Reply, Frames),
            toroco_live_hub:ack(self()),
            sender(Reply)
    end.

write(Reply, Frames) ->
    lists:foreach(fun(F) ->
                          case Reply(F) of
                              ok -> ok;
                              {error, Why} -> exit({shutdown, {send, Why}})
                          end
                  end, Frames).
