%% @doc One Foxglove client of the bridge (`toroco_live_foxglove'): the
%% protocol's side of a `toroco_live_ws_conn', the process that answered
%% the WebSocket upgrade and owns the socket.
%%
%% What it does, by the protocol's messages (`foxglove.websocket.v1'):
%% <ul>
%% <li>sends `serverInfo' (capabilities `connectionGraph', and
%%     `clientPublish' when the node's configuration enables it), then
%%     `advertise' with the channels, and later `advertise'/`unadvertise'
%%     as the hub says;</li>
%% <li>`subscribe'/`unsubscribe': keeps the client's subscription ids and
%%     tells the hub; each event on a subscribed channel goes out as a
%%     binary Message Data frame (opcode 1, subscription id, the event's
%%     nanosecond time, the JSON);</li>
%% <li>`subscribeConnectionGraph'/`unsubscribeConnectionGraph': the graph
%%     now and at each change (`connectionGraphUpdate');</li>
%% <li>with `clientPublish': client `advertise'/`unadvertise' of
%%     `/toroco/out/E/O' or `/toroco/in/R/I' topics, and binary Client
%%     Message Data frames carrying `{"term": "..."}', read by
%%     `toroco_rec_json:parse_term/1' (never evaluated) and injected with
%%     `toroco:inject/2': on an output as that output, on an input as the
%%     input's highest-priority source (what would win it).</li>
%% </ul>
%% Everything else gets a `status' error naming the fault; a client that
%% keeps sending faults (`?MAX_FAULTS'), breaks the framing, or stops
%% reading (a send blocked `?SEND_TIMEOUT_MS') is disconnected. Nothing a
%% client sends reaches the robot other than a valid published term.
-module(toroco_live_foxglove_conn).
-behaviour(toroco_live_ws_conn).

-export([serve/3]).
-export([join/2, handle_frame/2, handle_info/2, handle_framing_error/2]).

-define(MAX_MESSAGE, 1048576).
-define(MAX_FAULTS, 20).

-record(conn, {socket :: toroco_live_ws_conn:socket(),
               publish :: boolean(),
               channels = #{} :: #{pos_integer() => toroco_live_foxglove:channel()},
               subs = #{} :: #{non_neg_integer() => pos_integer()},      % sub id => channel
               by_channel = #{} :: #{pos_integer() => non_neg_integer()},
               client_channels = #{} :: #{non_neg_integer() => toroco_rec_channels:key()},
               graph = none :: none | {list(), list()},
               graph_subscribed = false :: boolean(),
               faults = 0 :: non_neg_integer()}).

%% @doc The mochiweb loop of the bridge's port: a WebSocket upgrade to
%% `Subprotocol' becomes a connection, anything else gets a 400.
-spec serve(mochiweb_request:request(), binary(), #{client_publish := boolean(),
                                                    session := binary()}) -> ok.
serve(Req, Subprotocol, Opts) ->
    Endpoint = io_lib:format("a Foxglove WebSocket endpoint (subprotocol ~s)", [Subprotocol]),
    toroco_live_ws_conn:serve(Req, #{subprotocol => Subprotocol, max => ?MAX_MESSAGE,
                                     endpoint => Endpoint}, {?MODULE, Opts}).

-spec join(toroco_live_ws_conn:socket(), #{client_publish := boolean(), session := binary()}) ->
          {ok, #conn{}} | {error, term()}.
join(Socket, Opts) ->
    case toroco_live_foxglove:join() of
        {ok, Channels, Graph} ->
            C = #conn{socket = Socket, publish = maps:get(client_publish, Opts), graph = Graph},
            {ok, advertise(send_json(C, server_info(C, maps:get(session, Opts))), Channels)};
        {error, _} = Error ->
            Error
    end.

server_info(#conn{publish = Publish}, Session) ->
    Caps = [<<"connectionGraph">> | [<<"clientPublish">> || Publish]],
    Base = #{op => serverInfo, name => iolist_to_binary(["toroco ", atom_to_binary(node())]),
             capabilities => Caps, metadata => #{node => node()}, sessionId => Session},
    case Publish of
        true -> Base#{supportedEncodings => [json]};
        false -> Base
    end.

%%====================================================================
%% toroco_live_ws_conn
%%====================================================================

-spec handle_frame({text | binary, binary()}, #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_frame(Frame, C) ->
    client_message(Frame, C).

-spec handle_info(term(), #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_info(Msg, C) ->
    case toroco_live_foxglove:receive_fox(Msg) of
        {ok, Fox} -> hub(Fox, C);
        error -> {ok, C}
    end.

-spec handle_framing_error(term(), #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_framing_error(_Why, C) ->
    {ok, C}.

%%====================================================================
%% From the hub
%%====================================================================

hub({message, Id, T, Json}, C = #conn{by_channel = By}) ->
    case By of
        #{Id := Sub} -> {ok, send(C, toroco_live_ws_frame:frame(binary, [<<1, Sub:32/little, T:64/little>>, Json]))};
        #{} -> {ok, C}
    end;
hub({advertise, Channels}, C) ->
    {ok, advertise(C, Channels)};
hub({unadvertise, Ids}, C = #conn{channels = Chs, subs = Subs, by_channel = By}) ->
    C1 = C#conn{channels = maps:without(Ids, Chs),
                subs = maps:filter(fun(_, Ch) -> not lists:member(Ch, Ids) end, Subs),
                by_channel = maps:without(Ids, By)},
    {ok, send_json(C1, #{op => unadvertise, channelIds => Ids})};
hub({graph, Graph}, C = #conn{graph_subscribed = true, graph = Old}) ->
    {ok, send_json(C#conn{graph = Graph}, graph_update(Old, Graph))};
hub({graph, Graph}, C) ->
    {ok, C#conn{graph = Graph}};
hub({dropped, N}, C) ->
    {ok, status(C, 1, io_lib:format("~b messages were dropped: this client reads "
                                         "more slowly than the robot emits", [N]))}.

advertise(C, []) -> C;
advertise(C = #conn{channels = Chs}, Channels) ->
    New = [Ch || Ch = #{id := Id} <- Channels, not maps:is_key(Id, Chs)],
    C1 = C#conn{channels = maps:merge(Chs, maps:from_list([{Id, Ch} || Ch = #{id := Id} <- New]))},
    case New of
        [] -> C1;
        _ ->
            send_json(C1, #{op => advertise,
                            channels => [#{id => Id, topic => T, encoding => json,
                                           schemaName => N, schema => S,
                                           schemaEncoding => jsonschema}
                                         || #{id := Id, topic := T, schema_name := N, schema := S} <- New]})
    end.

graph_update({OldPub, _}, {Pub, Sub}) ->
    Removed = [T || {T, _} <- OldPub] -- [T || {T, _} <- Pub],
    #{op => connectionGraphUpdate,
      publishedTopics => [#{name => T, publisherIds => Ids} || {T, Ids} <- Pub],
      subscribedTopics => [#{name => T, subscriberIds => Ids} || {T, Ids} <- Sub],
      advertisedServices => [], removedTopics => Removed, removedServices => []}.

%%====================================================================
%% From the client
%%====================================================================

client_message({text, Text}, C) ->
    try jiffy:decode(Text, [return_maps]) of
        #{<<"op">> := Op} = M when is_binary(Op) -> op(Op, M, C);
        _ -> fault(C, <<"a JSON object with an \"op\" field was expected">>)
    catch _:_ -> fault(C, <<"not JSON">>)
    end;
client_message({binary, <<1, Id:32/little, Payload/binary>>}, C) ->
    publish(Id, Payload, C);
client_message({binary, <<Op, _/binary>>}, C) ->
    fault(C, io_lib:format("unknown binary opcode ~b", [Op]));
client_message({binary, <<>>}, C) ->
    fault(C, <<"empty binary message">>).

op(<<"subscribe">>, #{<<"subscriptions">> := Subs}, C) when is_list(Subs) ->
    lists:foldl(fun(S, {ok, Acc}) -> subscribe(S, Acc); (_, Stop) -> Stop end, {ok, C}, Subs);
op(<<"unsubscribe">>, #{<<"subscriptionIds">> := Ids}, C) when is_list(Ids) ->
    lists:foldl(fun(Id, {ok, Acc}) -> unsubscribe(Id, Acc); (_, Stop) -> Stop end, {ok, C}, Ids);
op(<<"advertise">>, _, C = #conn{publish = false}) ->
    fault(C, <<"clientPublish is off on this node">>);
op(<<"advertise">>, #{<<"channels">> := Chs}, C) when is_list(Chs) ->
    lists:foldl(fun(Ch, {ok, Acc}) -> client_advertise(Ch, Acc); (_, Stop) -> Stop end, {ok, C}, Chs);
op(<<"unadvertise">>, _, C = #conn{publish = false}) ->
    fault(C, <<"clientPublish is off on this node">>);
op(<<"unadvertise">>, #{<<"channelIds">> := Ids}, C = #conn{client_channels = CC}) when is_list(Ids) ->
    {ok, C#conn{client_channels = maps:without(Ids, CC)}};
op(<<"subscribeConnectionGraph">>, _, C = #conn{graph = G}) ->
    {ok, send_json(C#conn{graph_subscribed = true}, graph_update({[], []}, G))};
op(<<"unsubscribeConnectionGraph">>, _, C) ->
    {ok, C#conn{graph_subscribed = false}};
op(Op, _, C) when Op =:= <<"subscribe">>; Op =:= <<"unsubscribe">>; Op =:= <<"advertise">>;
                  Op =:= <<"unadvertise">> ->
    fault(C, [<<"malformed ">>, Op]);
op(Op, _, C) ->
    fault(C, [<<"unsupported op ">>, binary:part(Op, 0, min(64, byte_size(Op)))]).

subscribe(#{<<"id">> := Sub, <<"channelId">> := Ch}, C = #conn{channels = Chs, subs = Subs, by_channel = By})
  when is_integer(Sub), Sub >= 0, is_integer(Ch) ->
    if
        not is_map_key(Ch, Chs) -> fault(C, io_lib:format("unknown channel ~b", [Ch]));
        is_map_key(Sub, Subs) -> fault(C, io_lib:format("subscription id ~b is in use", [Sub]));
        is_map_key(Ch, By) -> fault(C, io_lib:format("channel ~b is already subscribed", [Ch]));
        true ->
            toroco_live_foxglove:subscribe(self(), [Ch]),
            {ok, C#conn{subs = Subs#{Sub => Ch}, by_channel = By#{Ch => Sub}}}
    end;
subscribe(_, C) ->
    fault(C, <<"a subscription needs an integer id and channelId">>).

unsubscribe(Sub, C = #conn{subs = Subs, by_channel = By}) ->
    case Subs of
        #{Sub := Ch} ->
            toroco_live_foxglove:unsubscribe(self(), [Ch]),
            {ok, C#conn{subs = maps:remove(Sub, Subs), by_channel = maps:remove(Ch, By)}};
        #{} ->
            fault(C, io_lib:format("unknown subscription ~0p", [Sub]))
    end.

client_advertise(#{<<"id">> := Id, <<"topic">> := Topic} = Ch, C = #conn{client_channels = CC})
  when is_integer(Id), is_binary(Topic) ->
    case {maps:get(<<"encoding">>, Ch, <<"json">>), toroco_rec_channels:key(Topic)} of
        {<<"json">>, {ok, {Kind, _, _} = Key}} when Kind =:= out; Kind =:= in ->
            {ok, C#conn{client_channels = CC#{Id => Key}}};
        {<<"json">>, _} ->
            fault(C, [<<"cannot publish on ">>, binary:part(Topic, 0, min(200, byte_size(Topic))),
                      <<": only /toroco/out/<emitter>/<output> and /toroco/in/<receiver>/<input>">>]);
        {_, _} ->
            fault(C, <<"only the json encoding is supported">>)
    end;
client_advertise(_, C) ->
    fault(C, <<"a client channel needs an integer id and a topic">>).

publish(_, _, C = #conn{publish = false}) ->
    fault(C, <<"clientPublish is off on this node">>);
publish(Id, Payload, C = #conn{client_channels = CC}) ->
    case CC of
        #{Id := Key} ->
            case inject(Key, Payload) of
                ok -> {ok, C};
                {error, Why} -> fault(C, io_lib:format("not injected: ~0p", [Why]))
            end;
        #{} ->
            fault(C, io_lib:format("unknown client channel ~b", [Id]))
    end.

inject(Key, Payload) ->
    try jiffy:decode(Payload, [return_maps]) of
        #{<<"term">> := Text} when is_binary(Text) ->
            case toroco_rec_json:parse_term(Text) of
                {ok, Term} ->
                    case source(Key) of
                        {ok, Src} -> toroco:inject(Src, Term);
                        Err -> Err
                    end;
                Err -> Err
            end;
        _ -> {error, {bad_message, <<"{\"term\": \"<Erlang literal>\"} expected">>}}
    catch _:_ -> {error, {bad_message, not_json}}
    end.

source({out, E, O}) -> {ok, {E, O}};
source({in, R, I}) ->
    case toroco:inspect(R) of
        #{inputs := #{I := #{sources := [Top | _]}}} -> {ok, Top};
        #{} -> {error, {unwired_input, {R, I}}};
        Err -> Err
    end.

%%====================================================================
%% Sending
%%====================================================================

fault(C = #conn{faults = N}, _Msg) when N >= ?MAX_FAULTS ->
    {close, 1008, too_many_faults, C};
fault(C = #conn{faults = N}, Msg) ->
    {ok, status(C#conn{faults = N + 1}, 2, Msg)}.

status(C, Level, Msg) ->
    send_json(C, #{op => status, level => Level, message => iolist_to_binary(Msg)}).

send_json(C, Map) ->
    send(C, toroco_live_ws_frame:frame(text, jiffy:encode(Map))).

send(C = #conn{socket = S}, Frame) ->
    ok = toroco_live_ws_conn:send(S, Frame),
    C.
