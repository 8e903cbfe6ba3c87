%% @doc One rosbridge client of the server (`toroco_ros_server'): the
%% protocol's side of a `toroco_live_ws_conn', the process that answered
%% the WebSocket upgrade and owns the socket. JSON text frames, one
%% rosbridge v2 operation each (`toroco_ros_protocol' builds and reads
%% them).
%%
%% <ul>
%% <li>`subscribe' (`topic', `id', `type', `throttle_rate' ms,
%%     `queue_length', `fragment_size', `compression') / `unsubscribe'
%%     (`topic', `id'): one subscription per topic with the ids on it; the
%%     topic gets the smallest throttle, the longest queue and the smallest
%%     fragment size of its ids. A throttled topic sends at most one
%%     message per `throttle_rate' and keeps the newest `queue_length'
%%     (at least 1) meanwhile. A message longer than `fragment_size' goes
%%     out as `fragment' operations (`id', `data', `num' from 0, `total').</li>
%% <li>`advertise' / `unadvertise' / `publish': on the inbound topics
%%     (`/cmd_vel'), checked against the topic's type
%%     (`toroco_ros_topics:normalise/1') and handed to the `ros' device
%%     (`toroco_ros_device:publish/3') and to the topic's
%%     subscribers; or on a topic the robot does not have, which the hub
%%     relays to its subscribers (`toroco_ros_server', relaying: how
%%     a robot in client mode shows its topics here). Publishing needs the
%%     dashboard's token.</li>
%% <li>`call_service' (`service', `args', `id'): the services of
%%     `toroco_ros_rosapi', answered with `service_response'. None of
%%     them changes the robot, so none needs the token.</li>
%% <li>`auth' (`mac' or `token': the dashboard's token; `?token=T' on the
%%     URL does the same), `set_level' (`none', `error', `warning', `info':
%%     the least severe `status' sent; `error' at first), `fragment' (a
%%     message in pieces, reassembled: at most `?MAX_PENDING' messages at
%%     once, `?MAX_FRAGMENTS' pieces each, their bytes within the message
%%     limit, each completed within the app env `rosbridge_fragment_ms'
%%     [10000] or dropped), `status' (ignored), `service_response' (refused:
%%     this server calls no client services).</li>
%% </ul>
%% Topic and service names are taken with or without the leading slash.
%% A subscription's `compression' may be `none' (JSON text), `cbor' (the
%% publish operation as CBOR, a binary frame: `toroco_ros_cbor') or
%% `cbor-raw' (CBOR with `msg' `{bytes, secs, nsecs}', the message's CDR
%% bytes: `toroco_ros_msgs:cdr/2'; what Foxglove's Rosbridge connection asks
%% for); any other (`png') is refused naming it, and so is any compression
%% on another operation.
%%
%% Bad input gets a `status' of level `error' naming the fault and the
%% operation's `id', and changes nothing. Messages are at most the app env
%% `rosbridge_max_message' [1048576] bytes (a longer one is answered, then
%% the connection closes: its rest cannot be read); at most
%% `?MAX_SUB_CHANGES' subscribe and unsubscribe operations a second and
%% `?MAX_SUBS' subscriptions. A client that keeps sending faults
%% (`?MAX_FAULTS') or stops reading (a send blocked `?SEND_TIMEOUT_MS') is
%% disconnected; one that reads slowly loses messages (the hub counts them
%% and tells it, a `warning').
-module(toroco_ros_server_conn).
-behaviour(toroco_live_ws_conn).

-export([serve/2]).
-export([join/2, handle_frame/2, handle_info/2, handle_framing_error/2]).

-define(MAX_MESSAGE, 1048576).
-define(MAX_FAULTS, 20).
-define(MAX_SUBS, 256).
-define(MAX_SUB_CHANGES, 100).
-define(MAX_PENDING, 8).
-define(MAX_FRAGMENTS, 10000).
-define(FRAGMENT_MS, 10000).
-define(LOG, #{domain => [toroco, ros]}).
-define(UNAUTHORIZED, "publishing needs the dashboard's token: connect with ?token=T on "
        "the URL or send {\"op\": \"auth\", \"mac\": T}; without it this connection may only "
        "subscribe and call the read-only services").

-record(sub, {ids = #{} :: #{term() => #{throttle := non_neg_integer(), queue := pos_integer(),
                                          fragment := pos_integer() | none}},
              last = none :: none | integer(),
              %% the last subscribe's: none, cbor or cbor_raw
              compression = none :: none | cbor | cbor_raw,
              queue = [] :: [{binary(), binary(), toroco_ros_topics:message()}],
              timer = none :: none | reference()}).

-record(conn, {socket :: toroco_live_ws_conn:socket(),
               max :: pos_integer(),
               peer :: inet:ip_address() | unknown,
               authorized :: boolean(),
               level = 3 :: 1..4,
               subs = #{} :: #{binary() => #sub{}},
               advertised = #{} :: #{binary() => binary()},
               fragments = #{} :: #{term() => {pos_integer(), #{non_neg_integer() => binary()},
                                               non_neg_integer(), reference()}},
               out_id = 0 :: non_neg_integer(),
               window = {0, 0} :: {integer(), non_neg_integer()},
               faults = 0 :: non_neg_integer()}).

%% @doc The mochiweb loop of the server's port: a WebSocket upgrade becomes
%% a connection (authorized when the URL has the token), anything else a 400.
-spec serve(mochiweb_request:request(), map()) -> ok.
serve(Req, Opts) ->
    Max = maps:get(max_message, Opts,
                   application:get_env(toroco_ros, rosbridge_max_message, ?MAX_MESSAGE)),
    toroco_live_ws_conn:serve(Req, #{subprotocol => none, max => Max,
                                     endpoint => "a rosbridge v2 WebSocket endpoint"},
                              {?MODULE, {Max, toroco_live_http:peer(Req), toroco_live_http:token(Req)}}).

-spec join(toroco_live_ws_conn:socket(),
           {pos_integer(), inet:ip_address() | unknown, binary() | none}) ->
          {ok, #conn{}} | {error, term()}.
join(Socket, {Max, Peer, Token}) ->
    case toroco_ros_server:join() of
        ok -> {ok, #conn{socket = Socket, max = Max, peer = Peer,
                         authorized = authorize(Peer, Token) =:= true}};
        {error, _} = Error -> Error
    end.

%% The token checks of every port, failures per address (toroco_live_auth).
authorize(_Peer, none) -> false;
authorize(Peer, Token) -> toroco_live_auth:authorize(Peer, {token, Token}).

%%====================================================================
%% toroco_live_ws_conn
%%====================================================================

-spec handle_frame({text | binary, binary()}, #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_frame({text, Text}, C) ->
    text_message(Text, C);
handle_frame({binary, _}, C) ->
    fault(C, null, <<"binary messages are not taken: JSON text only (no CBOR, no BSON)">>).

-spec handle_framing_error(term(), #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_framing_error(too_big, C) ->
    toroco_ros_server:count(faults),
    {ok, status(C, error, null,
                io_lib:format("a message over the limit of ~b bytes: closing, the rest of "
                              "it cannot be read", [C#conn.max]))};
handle_framing_error(_, C) ->
    {ok, C}.

-spec handle_info(term(), #conn{}) -> toroco_live_ws_conn:result(#conn{}).
handle_info({flush, Topic}, C) ->
    {ok, flush(Topic, C)};
handle_info({fragments_expired, Id, Ref}, C = #conn{fragments = F}) ->
    case F of
        #{Id := {Total, Got, _, Ref}} ->
            toroco_ros_server:count(fragments_expired),
            Ms = application:get_env(toroco_ros, rosbridge_fragment_ms, ?FRAGMENT_MS),
            fault(C#conn{fragments = maps:remove(Id, F)}, Id,
                  io_lib:format("fragments of message ~ts never completed: ~b of ~b "
                                "came in ~b ms; dropped", [text(Id), map_size(Got), Total, Ms]));
        #{} -> {ok, C}
    end;
handle_info(Msg, C) ->
    case toroco_ros_server:receive_hub(Msg) of
        {ok, {message, Topic, Message}} -> {ok, message(Topic, Message, C)};
        {ok, {dropped, N}} ->
            {ok, status(C, warning, null,
                        io_lib:format("~b messages were dropped: this client reads more "
                                      "slowly than the robot emits", [N]))};
        error -> {ok, C}
    end.


%%====================================================================
%% From the hub: messages on subscribed topics
%%====================================================================

message(Topic, Message, C = #conn{subs = Subs}) ->
    case Subs of
        #{Topic := Sub} ->
            Throttle = throttle(Sub),
            Now = erlang:monotonic_time(millisecond),
            case Sub#sub.last of
                Last when Throttle =:= 0; Last =:= none; Now - Last >= Throttle ->
                    publish_out(Topic, Message, C#conn{subs = Subs#{Topic := Sub#sub{last = Now}}});
                Last ->
                    Queue0 = Sub#sub.queue ++ [Message],
                    Queue = lists:nthtail(max(0, length(Queue0) - queue_length(Sub)), Queue0),
                    Timer = case Sub#sub.timer of
                                none -> erlang:send_after(Last + Throttle - Now, self(), {flush, Topic});
                                T -> T
                            end,
                    C#conn{subs = Subs#{Topic := Sub#sub{queue = Queue, timer = Timer}}}
            end;
        #{} -> C
    end.

flush(Topic, C = #conn{subs = Subs}) ->
    case Subs of
        #{Topic := Sub = #sub{queue = [Message | Rest]}} ->
            Timer = case Rest of
                        [] -> none;
                        _ -> erlang:send_after(throttle(Sub), self(), {flush, Topic})
                    end,
            publish_out(Topic, Message,
                        C#conn{subs = Subs#{Topic := Sub#sub{queue = Rest, timer = Timer,
                                                             last = erlang:monotonic_time(millisecond)}}});
        #{Topic := Sub} -> C#conn{subs = Subs#{Topic := Sub#sub{timer = none}}};
        #{} -> C
    end.

throttle(#sub{ids = Ids}) -> lists:min([T || #{throttle := T} <- maps:values(Ids)]).
queue_length(#sub{ids = Ids}) -> lists:max([Q || #{queue := Q} <- maps:values(Ids)]).
fragment_size(#sub{ids = Ids}) ->
    case [F || #{fragment := F} <- maps:values(Ids), F =/= none] of
        [] -> none;
        Fs -> lists:min(Fs)
    end.

publish_out(Topic, {Type, Json, Msg}, C = #conn{subs = Subs}) ->
    Sub = maps:get(Topic, Subs),
    case Sub#sub.compression of
        none ->
            Text = toroco_ros_protocol:publish_text(Topic, Json),
            case fragment_size(Sub) of
                Size when is_integer(Size), byte_size(Text) > Size -> send_fragments(Text, Size, C);
                _ -> send_text(C, Text)
            end;
        cbor ->
            send_binary(C, toroco_ros_protocol:cbor(toroco_ros_protocol:publish(Topic, Msg)));
        cbor_raw ->
            case toroco_ros_protocol:publish_raw(Topic, Type, Msg) of
                {ok, Op} ->
                    send_binary(C, toroco_ros_protocol:cbor(Op));
                {error, Why} ->
                    %% A relayed topic of a type this server cannot encode.
                    status(C, warning, null, [<<"cannot send ">>, Topic, <<" as cbor-raw: ">>,
                                              toroco_rec_json:term_text(Why)])
            end
    end.

send_fragments(Text, Size, C = #conn{out_id = N}) ->
    Id = <<"toroco_fragment_", (integer_to_binary(N))/binary>>,
    lists:foldl(fun(Op, Acc) -> send_json(Acc, Op) end, C#conn{out_id = N + 1},
                toroco_ros_protocol:fragments(Text, Size, Id)).

%%====================================================================
%% From the client
%%====================================================================

text_message(Text, C) ->
    case toroco_ros_protocol:decode(Text) of
        {ok, {Op, _, M}} -> safe_op(Op, M, C);
        {error, not_json} -> fault(C, null, <<"not JSON">>);
        {error, not_an_op} -> fault(C, null, <<"a JSON object with an \"op\" field was expected">>)
    end.

%% A message this module did not foresee is a fault of the client's, logged,
%% never a crash of the connection.
safe_op(Op, M, C) ->
    try op(Op, M, C)
    catch
        exit:normal:_ -> exit(normal);
        Class:Why:Stack ->
            logger:error("rosbridge: ~ts failed: ~0p:~0P ~0P", [text(Op), Class, Why, 20, Stack, 20],
                         ?LOG),
            fault(C, maps:get(<<"id">>, M, null), [<<"op ">>, text(Op), <<" could not be handled">>])
    end.

op(Op, M, C) ->
    Id = maps:get(<<"id">>, M, null),
    case {Op, maps:get(<<"compression">>, M, <<"none">>)} of
        {_, Comp} when Comp =:= <<"none">>; Comp =:= null; Op =:= <<"fragment">> -> op(Op, Id, M, C);
        {<<"subscribe">>, Comp} when Comp =:= <<"cbor">>; Comp =:= <<"cbor-raw">> -> op(Op, Id, M, C);
        {<<"subscribe">>, Comp} ->
            fault(C, Id, [<<"compression ">>, text(Comp), <<" is not supported: "
                                                          "none (JSON), cbor or cbor-raw">>]);
        {_, Comp} ->
            fault(C, Id, [<<"compression ">>, text(Comp), <<" is not supported for ">>, Op,
                          <<": JSON only">>])
    end.

op(<<"subscribe">>, Id, M, C) ->
    rate(Id, C, fun(C1) -> subscribe(Id, M, C1) end);
op(<<"unsubscribe">>, Id, M, C) ->
    rate(Id, C, fun(C1) -> unsubscribe(Id, M, C1) end);
op(<<"advertise">>, Id, M, C) ->
    with_topic(Id, M, C, fun(Topic) -> advertise(Id, Topic, M, C) end);
op(<<"unadvertise">>, Id, M, C = #conn{advertised = A}) ->
    with_topic(Id, M, C, fun(Topic) ->
                                 toroco_ros_server:unadvertise(self(), Topic),
                                 {ok, C#conn{advertised = maps:remove(Topic, A)}}
                         end);
op(<<"publish">>, Id, M, C) ->
    with_topic(Id, M, C, fun(Topic) -> publish(Id, Topic, M, C) end);
op(<<"call_service">>, Id, M, C) ->
    case maps:get(<<"service">>, M, null) of
        S when is_binary(S), S =/= <<>> -> call_service(Id, toroco_ros_rosapi:slash(S), maps:get(<<"args">>, M, #{}), C);
        _ -> fault(C, Id, <<"call_service needs a \"service\" name">>)
    end;
op(<<"service_response">>, Id, _M, C) ->
    fault(C, Id, [<<"no service call of this server waits for id ">>, text(Id),
                  <<": it calls no client services">>]);
op(<<"set_level">>, Id, M, C) ->
    case toroco_ros_protocol:level(maps:get(<<"level">>, M, null)) of
        {ok, L} -> {ok, C#conn{level = L}};
        error -> fault(C, Id, [<<"set_level: unknown level ">>, text(maps:get(<<"level">>, M, null)),
                               <<" (none, error, warning, info)">>])
    end;
op(<<"status">>, _Id, _M, C) ->
    {ok, C};
op(<<"auth">>, Id, M, C) ->
    case authorize(C#conn.peer, toroco_ros_protocol:auth_token(M)) of
        true -> {ok, status(C#conn{authorized = true}, info, Id, <<"authorized: this connection may publish">>)};
        false -> fault(C, Id, <<"auth: not the dashboard's token">>);
        {limited, Ms} ->
            fault(C, Id, iolist_to_binary(io_lib:format("auth: too many wrong tokens from this "
                                                        "address: refused for ~b s more",
                                                        [(Ms + 999) div 1000])))
    end;
op(<<"fragment">>, Id, M, C) ->
    fragment(Id, M, C);
op(Op, Id, _M, C) when Op =:= <<"advertise_service">>; Op =:= <<"unadvertise_service">>;
                       Op =:= <<"send_action_goal">>; Op =:= <<"advertise_action">> ->
    fault(C, Id, [<<"op ">>, Op, <<" is not supported: this server takes no services or "
                                  "actions from clients">>]);
op(Op, Id, _M, C) ->
    fault(C, Id, [<<"unknown op ">>, text(Op)]).

with_topic(Id, M, C, Fun) ->
    case maps:get(<<"topic">>, M, null) of
        T when is_binary(T), T =/= <<>>, byte_size(T) =< 256 -> Fun(toroco_ros_rosapi:slash(T));
        _ -> fault(C, Id, <<"a \"topic\" name is needed">>)
    end.


%% Subscription changes: at most ?MAX_SUB_CHANGES a second.
rate(Id, C = #conn{window = {Start, N}}, Fun) ->
    Now = erlang:monotonic_time(millisecond),
    case Now - Start >= 1000 of
        true -> Fun(C#conn{window = {Now, 1}});
        false when N < ?MAX_SUB_CHANGES -> Fun(C#conn{window = {Start, N + 1}});
        false -> fault(C, Id, io_lib:format("too many subscribe and unsubscribe operations: at "
                                            "most ~b a second; this one was ignored",
                                            [?MAX_SUB_CHANGES]))
    end.

%%--------------------------------------------------------------------
%% subscribe / unsubscribe
%%--------------------------------------------------------------------

subscribe(Id, M, C = #conn{subs = Subs}) ->
    with_topic(Id, M, C, fun(Topic) ->
        Compression = case maps:get(<<"compression">>, M, null) of
                          <<"cbor">> -> cbor;
                          <<"cbor-raw">> -> cbor_raw;
                          _ -> none
                      end,
        Opts = #{throttle => int(maps:get(<<"throttle_rate">>, M, 0), 0),
                 queue => max(1, int(maps:get(<<"queue_length">>, M, 1), 1)),
                 fragment => case int(maps:get(<<"fragment_size">>, M, 0), 0) of
                                 0 -> none;
                                 F -> F
                             end},
        Count = lists:sum([map_size(S#sub.ids) || S <- maps:values(Subs)]),
        case {toroco_ros_rosapi:topic_type(Topic), maps:get(<<"type">>, M, null)} of
            _ when Count >= ?MAX_SUBS ->
                fault(C, Id, io_lib:format("at most ~b subscriptions per connection", [?MAX_SUBS]));
            {{error, _}, _} ->
                fault(C, Id, [<<"unknown topic ">>, Topic, <<" (the robot's topics: call /rosapi/topics)">>]);
            {{ok, Type}, Asked} when Asked =/= null, Asked =/= <<>> ->
                case same_type(Asked, Type) of
                    true -> {ok, add_sub(Topic, Id, Opts, Compression, C)};
                    false -> fault(C, Id, [<<"topic ">>, Topic, <<" is of type ">>, Type,
                                           <<", not ">>, text(Asked)])
                end;
            {{ok, _}, _} ->
                {ok, add_sub(Topic, Id, Opts, Compression, C)}
        end
    end).

int(N, _) when is_integer(N), N >= 0, N =< 1 bsl 31 -> N;
int(F, _) when is_float(F), F >= 0, F =< 1 bsl 31 -> round(F);
int(_, Default) -> Default.

add_sub(Topic, Id, Opts, Compression, C = #conn{subs = Subs}) ->
    Sub = case Subs of
              #{Topic := S} -> S;
              #{} -> toroco_ros_server:subscribe(self(), Topic), #sub{}
          end,
    C#conn{subs = Subs#{Topic => Sub#sub{ids = (Sub#sub.ids)#{Id => Opts},
                                         compression = Compression}}}.

unsubscribe(Id, M, C = #conn{subs = Subs}) ->
    with_topic(Id, M, C, fun(Topic) ->
        case {Subs, Id} of
            {#{Topic := Sub}, _} when Id =:= null; is_map_key(Id, Sub#sub.ids) ->
                Ids = case Id of
                          null -> #{};
                          _ -> maps:remove(Id, Sub#sub.ids)
                      end,
                case map_size(Ids) of
                    0 ->
                        toroco_ros_server:unsubscribe(self(), Topic),
                        Sub#sub.timer =:= none orelse erlang:cancel_timer(Sub#sub.timer),
                        {ok, C#conn{subs = maps:remove(Topic, Subs)}};
                    _ ->
                        {ok, C#conn{subs = Subs#{Topic := Sub#sub{ids = Ids}}}}
                end;
            _ ->
                {ok, status(C, warning, Id, [<<"unsubscribe: no subscription to ">>, Topic,
                                             <<" with id ">>, text(Id)])}
        end
    end).

%% `pkg/Type' (as ROS 1 and many clients write it) is `pkg/msg/Type'; no
%% type is the topic's.
same_type(null, _) -> true;
same_type(Asked, Type) when is_binary(Asked) ->
    case binary:split(Asked, <<"/">>, [global]) of
        [Pkg, Name] -> <<Pkg/binary, "/msg/", Name/binary>> =:= Type;
        _ -> Asked =:= Type
    end;
same_type(_, _) -> false.

%%--------------------------------------------------------------------
%% advertise / publish
%%--------------------------------------------------------------------

inbound(Topic) ->
    case [Ty || #{topic := T, type := Ty, dir := in} <- toroco_ros_server:topics(), T =:= Topic] of
        [Type | _] -> {ok, Type};
        [] -> error
    end.

not_inbound(C, Id, Topic) ->
    Inbound = [T || #{topic := T, dir := in} <- toroco_ros_server:topics()],
    fault(C, Id, [<<"cannot publish on ">>, Topic, <<": the robot takes ">>,
                  lists:join(<<", ">>, Inbound)]).

unauthorized(C, Id) ->
    toroco_ros_server:count(refused_unauthorized),
    fault(C, Id, <<?UNAUTHORIZED>>).

advertise(Id, _Topic, _M, C = #conn{authorized = false}) ->
    unauthorized(C, Id);
advertise(Id, Topic, M, C = #conn{advertised = A}) ->
    case {inbound(Topic), maps:get(<<"type">>, M, null)} of
        {error, Asked} -> advertise_relayed(Id, Topic, Asked, C);
        {{ok, Type}, Asked} ->
            case same_type(Asked, Type) of
                true -> {ok, C#conn{advertised = A#{Topic => Type}}};
                false -> fault(C, Id, [<<"topic ">>, Topic, <<" is of type ">>, Type, <<", not ">>,
                                       text(Asked)])
            end
    end.

publish(Id, _Topic, _M, C = #conn{authorized = false}) ->
    unauthorized(C, Id);
publish(Id, Topic, M, C) ->
    case inbound(Topic) of
        error -> publish_relayed(Id, Topic, M, C);
        {ok, Type} ->
            case toroco_ros_topics:normalise({Type, maps:get(<<"msg">>, M, null)}) of
                {ok, Msg} ->
                    toroco_ros_server:relay(Topic, Type, Msg),
                    hand_over(Id, Topic, Msg, C);
                {error, {bad_field, Path}} ->
                    fault(C, Id, [<<"publish on ">>, Topic, <<": not a ">>, Type, <<": field ">>,
                                  Path, <<" does not fit">>]);
                {error, _} ->
                    fault(C, Id, [<<"publish on ">>, Topic, <<": \"msg\" must be a ">>, Type,
                                  <<" object">>])
            end
    end.

%% A topic the robot does not have, relayed by the hub to its subscribers.
advertise_relayed(Id, Topic, Type, C = #conn{advertised = A}) when is_binary(Type), Type =/= <<>> ->
    case toroco_ros_server:advertise(self(), Topic, Type) of
        ok -> {ok, C#conn{advertised = A#{Topic => Type}}};
        {error, robot_topic} ->
            fault(C, Id, [<<"cannot advertise ">>, Topic, <<": the robot publishes it">>]);
        {error, {type, Other}} ->
            fault(C, Id, [<<"topic ">>, Topic, <<" is of type ">>, Other, <<", not ">>, Type]);
        {error, _} ->
            fault(C, Id, [<<"cannot advertise ">>, Topic, <<": the server is going down">>])
    end;
advertise_relayed(Id, Topic, _Type, C) ->
    fault(C, Id, [<<"advertise ">>, Topic, <<" needs a \"type\"">>]).

publish_relayed(Id, Topic, M, C = #conn{advertised = A}) ->
    case {A, maps:get(<<"msg">>, M, null)} of
        {#{Topic := Type}, Msg} when is_map(Msg) ->
            toroco_ros_server:relay(Topic, Type, Msg),
            {ok, C};
        {#{Topic := Type}, _} ->
            fault(C, Id, [<<"publish on ">>, Topic, <<": \"msg\" must be a ">>, Type, <<" object">>]);
        {#{}, _} ->
            not_inbound(C, Id, Topic)
    end.

hand_over(Id, <<$/, Name/binary>> = Topic, Msg, C) ->
    Output = binary_to_existing_atom(Name),
    case toroco_ros_device:publish(ros, Output, Msg) of
        ok ->
            toroco_ros_server:count(published),
            {ok, C};
        {error, busy} ->
            toroco_ros_server:count(publish_dropped),
            {ok, status(C, warning, Id, [<<"publish on ">>, Topic, <<" dropped: the robot is behind">>])};
        {error, {not_running, _}} ->
            fault(C, Id, [<<"publish on ">>, Topic, <<": no ros device runs; the wiring needs ">>,
                          <<"{device, ros, toroco_ros_device, #{}}">>])
    end.

%%--------------------------------------------------------------------
%% Services
%%--------------------------------------------------------------------

call_service(Id, Service, Args, C) ->
    case toroco_ros_rosapi:call(Service, Args) of
        {ok, Values} ->
            {ok, send_json(C, toroco_ros_protocol:service_response(Id, Service, Values, true))};
        {error, Why} ->
            C1 = send_json(C, toroco_ros_protocol:service_response(Id, Service,
                                                                    iolist_to_binary(Why), false)),
            fault(C1, Id, Why)
    end.

%%--------------------------------------------------------------------
%% Fragments in
%%--------------------------------------------------------------------

fragment(Id, M, C = #conn{fragments = F, max = Max}) ->
    case toroco_ros_protocol:fragment(M) of
        {ok, Num, Total, Data} when Id =/= null, Total =< ?MAX_FRAGMENTS ->
            Held = lists:sum([B || {_, _, B, _} <- maps:values(F)]),
            case F of
                #{Id := {T, _, _, _}} when T =/= Total ->
                    fault(C, Id, io_lib:format("fragment ~b of message ~ts says ~b pieces, not ~b",
                                               [Num, text(Id), Total, T]));
                _ when Held + byte_size(Data) > Max ->
                    fault(drop_fragments(Id, C), Id,
                          io_lib:format("fragments over the limit of ~b bytes: message ~ts dropped",
                                        [Max, text(Id)]));
                #{Id := {_, Got, Bytes, Ref}} ->
                    pieces_in(Id, Total, Got#{Num => Data}, Bytes + byte_size(Data), Ref, C);
                #{} when map_size(F) >= ?MAX_PENDING ->
                    fault(C, Id, io_lib:format("at most ~b fragmented messages at once", [?MAX_PENDING]));
                #{} ->
                    Ms = application:get_env(toroco_ros, rosbridge_fragment_ms, ?FRAGMENT_MS),
                    Ref = make_ref(),
                    erlang:send_after(Ms, self(), {fragments_expired, Id, Ref}),
                    pieces_in(Id, Total, #{Num => Data}, byte_size(Data), Ref, C)
            end;
        _ ->
            fault(C, Id, io_lib:format("a fragment needs an id, a string \"data\", and integers "
                                       "0 =< num < total =< ~b", [?MAX_FRAGMENTS]))
    end.

pieces_in(Id, Total, Got, _Bytes, _Ref, C) when map_size(Got) =:= Total ->
    Whole = iolist_to_binary([maps:get(N, Got) || N <- lists:seq(0, Total - 1)]),
    C1 = drop_fragments(Id, C),
    case toroco_ros_protocol:decode(Whole) of
        {ok, {<<"fragment">>, _, _}} -> fault(C1, Id, <<"fragments of fragments are not taken">>);
        {ok, {Op, _, M}} -> safe_op(Op, M, C1);
        {error, _} -> fault(C1, Id, [<<"the fragments of message ">>, text(Id),
                                     <<" do not make a JSON object with an \"op\"">>])
    end;
pieces_in(Id, Total, Got, Bytes, Ref, C = #conn{fragments = F}) ->
    {ok, C#conn{fragments = F#{Id => {Total, Got, Bytes, Ref}}}}.

drop_fragments(Id, C = #conn{fragments = F}) ->
    C#conn{fragments = maps:remove(Id, F)}.

%%====================================================================
%% Sending
%%====================================================================

text(B) when is_binary(B) -> binary:part(B, 0, min(200, byte_size(B)));
text(Other) -> toroco_rec_json:encode(toroco_rec_json:value(Other)).

fault(C = #conn{faults = N}, _Id, Msg) when N >= ?MAX_FAULTS ->
    toroco_ros_server:count(faults),
    toroco_ros_server:count(disconnected),
    logger:notice("rosbridge: a client was disconnected after ~b faults, the last: ~ts",
                  [N + 1, iolist_to_binary(Msg)], ?LOG),
    {close, 1008, too_many_faults,
     status(C, error, null, [<<"too many faults: disconnected; the last: ">>, Msg])};
fault(C = #conn{faults = N}, Id, Msg) ->
    toroco_ros_server:count(faults),
    {ok, status(C#conn{faults = N + 1}, error, Id, Msg)}.

status(C = #conn{level = Min}, Level, Id, Msg) ->
    case toroco_ros_protocol:level(Level) >= {ok, Min} of
        true -> send_json(C, toroco_ros_protocol:status(Level, Id, Msg));
        false -> C
    end.

send_json(C, Op) ->
    {ok, Text} = toroco_ros_protocol:encode(Op),
    send_text(C, Text).

send_binary(C, Bin) ->
    send(C, toroco_live_ws_frame:frame(binary, Bin)).

send_text(C, Text) ->
    send(C, toroco_live_ws_frame:frame(text, Text)).

send(C = #conn{socket = S}, Frame) ->
    ok = toroco_live_ws_conn:send(S, Frame),
    C.
