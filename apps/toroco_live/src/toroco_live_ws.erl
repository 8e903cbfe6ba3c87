%% @doc One browser's WebSocket: the page's live state goes out, controls
%% come in. The protocol's side of a `toroco_live_ws_conn' (the process
%% that answered the upgrade owns the socket, as for the Foxglove bridge
%% and the rosbridge server): one process per client.
%%
%% It joins `toroco_live_hub' before the upgrade and writes what the hub
%% pushes; the hub pushes one message at a time and waits for the ack, so
%% a client that does not read holds only its own frame. A write that stays
%% blocked past the send timeout (5 s) ends the connection. Each frame the
%% client sends is a control request (`toroco_live_control', answered on
%% the socket with `{"type": "reply", "id": Id, "ok": true}' or
%% `{"type": "error", "id": Id, "error": Reason, "message": Why}').
%%
%% Refusals at connection time are HTTP answers: 400 when the request is
%% not a WebSocket upgrade, 503 `too_many_clients' past `max_clients'.
%% Controls need the page's session cookie or the bearer header
%% (`toroco_live_http' checks both, and the `Origin', before the upgrade);
%% without them every control is refused (read-only). The first frame
%% after the node's hello says which: `{"type": "session", "controls":
%% true | false}'. A frame larger
%% than `max_body' is refused with `too_large' and the connection stays;
%% one over `?MAX_FRAME' breaks the framing and closes it.
-module(toroco_live_ws).
-behaviour(toroco_live_ws_conn).

-export([upgrade/2]).
-export([join/2, handle_frame/2, handle_info/2, handle_framing_error/2]).

-define(MAX_FRAME, 1048576).

%% @doc Turns an HTTP request on `/ws' into a client (never returns after
%% the upgrade), or answers why not.
-spec upgrade(term(), boolean()) -> term().
upgrade(Req, Authorized) ->
    case string:lowercase(header(Req, "upgrade")) of
        "websocket" -> join_hub(Req, Authorized);
        _ -> refuse(Req, 400, not_websocket, <<"/ws is a WebSocket: send Upgrade: websocket">>)
    end.

header(Req, Name) ->
    case mochiweb_request:get_header_value(Name, Req) of
        undefined -> "";
        V -> V
    end.

%% This process is the client: it joins before the upgrade, so a full
%% dashboard is an HTTP refusal.
join_hub(Req, Authorized) ->
    case toroco_live_hub:join(self()) of
        {ok, Hello} ->
            State = #{authorized => Authorized, max => toroco_live_config:get(max_body, 16384)},
            toroco_live_ws_conn:serve(Req, #{subprotocol => none, max => ?MAX_FRAME,
                                             endpoint => "the dashboard's WebSocket (/ws)"},
                                      {?MODULE, {Hello, State}});
        {error, Reason} ->
            refuse(Req, 503, Reason, case Reason of
                                         too_many_clients ->
                                             <<"the dashboard has as many clients as it takes">>;
                                         _ -> <<"the dashboard is not running">>
                                     end)
    end.

refuse(Req, Status, Reason, Message) ->
    mochiweb_request:respond({Status, [{"Content-Type", "application/json"}],
                              toroco_rec_json:encode(#{<<"error">> => toroco_rec_json:value(Reason),
                                                        <<"message">> => Message})}, Req).

%%====================================================================
%% toroco_live_ws_conn
%%====================================================================

-spec join(toroco_live_ws_conn:socket(), {binary(), map()}) -> {ok, map()}.
join(Socket, {Hello, State = #{authorized := Auth}}) ->
    write(Socket, [Hello, toroco_rec_json:encode(#{<<"type">> => <<"session">>,
                                                    <<"controls">> => Auth})]),
    {ok, State#{socket => Socket}}.

-spec handle_frame({text | binary, binary()}, map()) -> toroco_live_ws_conn:result(map()).
handle_frame({_, <<>>}, State) ->
    {ok, State};
handle_frame({_, Payload}, State = #{authorized := Auth, max := Max, socket := S}) ->
    {Id, Answer} = case toroco_live_control:decode(Payload, Max) of
                       {ok, Req} -> {request_id(Req), toroco_live_control:run(Auth, Req, Max)};
                       Refused -> {null, Refused}
                   end,
    Json = case Answer of
               {ok, Ok} -> Ok#{<<"type">> => <<"reply">>, <<"id">> => Id};
               {error, _Status, Reason, Message} ->
                   #{<<"type">> => <<"error">>, <<"id">> => Id,
                     <<"error">> => toroco_rec_json:value(Reason), <<"message">> => Message}
           end,
    write(S, [toroco_rec_json:encode(Json)]),
    {ok, State}.

-spec handle_info(term(), map()) -> toroco_live_ws_conn:result(map()).
handle_info({toroco_live_hub, frames, Frames}, State = #{socket := S}) ->
    write(S, Frames),
    toroco_live_hub:ack(self()),
    {ok, State};
handle_info(_, State) ->
    {ok, State}.

-spec handle_framing_error(term(), map()) -> toroco_live_ws_conn:result(map()).
handle_framing_error(_, State) ->
    {ok, State}.

request_id(#{<<"id">> := Id}) when is_integer(Id); is_binary(Id) -> Id;
request_id(#{}) -> null.

write(Socket, Frames) ->
    lists:foreach(fun(F) -> toroco_live_ws_conn:send(Socket, toroco_live_ws_frame:frame(text, F)) end,
                  Frames).
