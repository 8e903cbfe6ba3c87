%% @doc The rosbridge v2 server (SPEC §15): a WebSocket server speaking
%% the rosbridge protocol with JSON (RobotWebTools `ROSBRIDGE_PROTOCOL.md'),
%% so `roslib' clients and Foxglove's Rosbridge connection see the robot as
%% ROS 2 topics (`toroco_ros_topics') and may drive it through `/cmd_vel'.
%%
%% This module is the server's hub, a callback module of
%% `toroco_live_bridge' like the Foxglove bridge (a child of
%% `toroco_ros_sup'), which owns the listener (registered as
%% `toroco_ros_server_listener', the same bounds as the dashboard's port),
%% the observer tap (SPEC §10; taken only while a client is connected), the
%% world subscription (for `/odom') and who subscribed to which topic; this
%% module keeps the robot's topics (read again at most every `?TOPICS_MS'
%% and on lifecycle events) and the counters `/metrics' shows. Each client
%% is its own process (`toroco_ros_server_conn', the mochiweb
%% connection process that took the upgrade), so a slow or hostile client
%% stalls only itself. A message is made (`toroco_ros_topics') and encoded
%% once, here, and only when someone subscribed to its topic.
%%
%% Messages between the hub and a connection, built and matched only here:
%% | from | to   | message                              | when                    | answer |
%% |------|------|--------------------------------------|-------------------------|--------|
%% | conn | hub  | join (`toroco_live_bridge')          | after the handshake     | `ok' |
%% | conn | hub  | `topics' (call)                      | a subscribe, a service  | `[topic()]' |
%% | conn | hub  | subscribe (`toroco_live_bridge', `[Topic]') | first subscription to a topic | none |
%% | conn | hub  | unsubscribe (`toroco_live_bridge')   | its last one went       | none |
%% | conn | hub  | `{count, Counter}'                   | a fault, a publish, ... | none |
%% | conn | hub  | `{advertise, Conn, Topic, Type}' (call) | a client advertised a topic the robot does not have | `ok' or `{error, Why}' |
%% | conn | hub  | `{unadvertise, Conn, Topic}'         | it unadvertised it      | none |
%% | conn | hub  | `{relay, Topic, Type, Msg}'          | a publish on a relayed topic or on an inbound one | none |
%% | hub  | conn | `{rosbridge, message, Topic, Type, Json, Msg}' | a message on a subscribed topic (its JSON, and the map for CBOR) | none |
%% | hub  | conn | `{rosbridge, dropped, N}'            | N messages were not sent to it | none |
%% A connection whose mailbox holds more than `?CONN_QUEUE' messages gets no
%% more until it drains (`toroco_live_bridge:send/3'); the hub counts what
%% it skipped and tells it.
%%
%% <b>Relaying</b>, as a rosbridge server in a ROS graph does: a topic a
%% client advertises that the robot does not have (another robot in client
%% mode, `toroco_ros_client', advertising its own) is listed among the
%% topics while an advertiser is connected, and what is published on it goes
%% to the clients subscribed to it; a publish on an inbound topic
%% (`/cmd_vel') goes to its subscribers too, besides the `ros' device.
-module(toroco_ros_server).
-behaviour(toroco_live_bridge).

-export([port/0, stats/0]).
-export([join/0, topics/0, subscribe/2, unsubscribe/2, count/1, receive_hub/1]).
-export([advertise/3, unadvertise/2, relay/3]).
-export([init/1, handle_join/2, handle_event/2, handle_world/2, handle_down/2, handle_call/3,
         handle_cast/2, handle_info/2, stats/1, dropped/1]).

-define(LISTENER, toroco_ros_server_listener).
-define(CONN_QUEUE, 1000).
-define(TAP_BUFFER, 1000).
-define(TOPICS_MS, 1000).
-define(RETAP_MS, 2000).
-define(CALL_MS, 15000).

-type hub() :: toroco_live_bridge:hub().

-record(ros, {topics = {[], -1} :: {[toroco_ros_topics:topic()], integer()},
              %% topics clients advertised: type and advertisers
              relayed = #{} :: #{binary() => {binary(), [pid()]}},
              counters = #{} :: #{atom() => non_neg_integer()}}).

%%====================================================================
%% API
%%====================================================================

%% @doc The port the server listens on, `off' when it does not run.
-spec port() -> inet:port_number() | off.
port() ->
    toroco_live_bridge:port(?MODULE).

%% @doc The counters (`/metrics'): `clients' and `subscriptions' (of
%% clients to topics) now, and totals: `connections',
%% `messages' sent to clients, `dropped' (not sent to a client behind),
%% `tap_dropped' (events the hub itself fell behind on, SPEC §10),
%% `published' (handed to the `ros' device), `refused_unauthorized',
%% `faults' (status errors for bad input), `disconnected' (clients closed
%% for misbehaving), `fragments_expired'. Empty when the server does not run.
-spec stats() -> #{atom() => non_neg_integer()}.
stats() ->
    toroco_live_bridge:stats(?MODULE).

%%====================================================================
%% The connections' side
%%====================================================================

-spec join() -> ok | {error, bridge_down}.
join() ->
    toroco_live_bridge:join(?MODULE).

%% @doc The robot's topics now (cached for `?TOPICS_MS').
-spec topics() -> [toroco_ros_topics:topic()].
topics() ->
    try gen_server:call(?MODULE, topics, ?CALL_MS)
    catch exit:_ -> []
    end.

-spec subscribe(pid(), binary()) -> ok.
subscribe(Conn, Topic) -> toroco_live_bridge:subscribe(?MODULE, Conn, [Topic]).

-spec unsubscribe(pid(), binary()) -> ok.
unsubscribe(Conn, Topic) -> toroco_live_bridge:unsubscribe(?MODULE, Conn, [Topic]).

%% @doc A client advertises `Topic' of `Type', a topic the robot does not
%% have: `{error, robot_topic}' if it does, `{error, {type, Other}}' if
%% another client advertised it as `Other'.
-spec advertise(pid(), binary(), binary()) -> ok | {error, robot_topic | {type, binary()} | server_down}.
advertise(Conn, Topic, Type) ->
    try gen_server:call(?MODULE, {advertise, Conn, Topic, Type}, ?CALL_MS)
    catch exit:_ -> {error, server_down}
    end.

-spec unadvertise(pid(), binary()) -> ok.
unadvertise(Conn, Topic) -> gen_server:cast(?MODULE, {unadvertise, Conn, Topic}).

%% @doc A message (its `msg' as JSON) for the clients subscribed to `Topic'.
-spec relay(binary(), binary(), map()) -> ok.
relay(Topic, Type, Msg) -> gen_server:cast(?MODULE, {relay, Topic, Type, Msg}).

%% @doc Counts one of {@link stats/0}'s totals.
-spec count(atom()) -> ok.
count(Counter) -> gen_server:cast(?MODULE, {count, Counter}).

%% @doc What a hub message says, for the connection's `handle_info'.
-spec receive_hub(term()) ->
          {ok, {message, binary(), {binary(), binary(), toroco_ros_topics:message()}}
               | {dropped, pos_integer()}} | error.
receive_hub({rosbridge, message, Topic, Type, Json, Msg}) -> {ok, {message, Topic, {Type, Json, Msg}}};
receive_hub({rosbridge, dropped, N}) -> {ok, {dropped, N}};
receive_hub(_) -> error.

%%====================================================================
%% toroco_live_bridge
%%====================================================================

%% @doc The hub, listening on `rosbridge' (0 for any free port) of `Opts'
%% (`toroco_live''s configuration).
-spec init(map()) -> {ok, toroco_live_bridge:spec(), #ros{}}.
init(Opts) ->
    ConnOpts = maps:with([max_message], Opts),
    Serve = fun(Req) -> toroco_ros_server_conn:serve(Req, ConnOpts) end,
    {ok, #{listener => ?LISTENER, serve => Serve, conn_queue => ?CONN_QUEUE,
           tap => #{kinds => [emit, lifecycle], buffer => ?TAP_BUFFER, retry_ms => ?RETAP_MS,
                    world => true, who => <<"rosbridge">>}}, #ros{}}.

-spec handle_join(pid(), hub()) -> {ok, hub()}.
handle_join(_Conn, H) ->
    {ok, bump(connections, H)}.

-spec handle_call(term(), gen_server:from(), hub()) -> {reply, term(), hub()}.
handle_call(topics, _From, H0) ->
    H = fresh_topics(H0),
    #ros{topics = {Topics, _}, relayed = R} = toroco_live_bridge:state(H),
    Robot = [T || #{topic := T} <- Topics],
    Relayed = [#{topic => T, type => Ty, dir => out}
               || {T, {Ty, _}} <- lists:sort(maps:to_list(R)), not lists:member(T, Robot)],
    {reply, Topics ++ Relayed, H};
handle_call({advertise, Conn, Topic, Type}, _From, H0) ->
    case toroco_live_clients:member(Conn, toroco_live_bridge:clients(H0)) of
        true ->
            H = fresh_topics(H0),
            S = #ros{relayed = R, topics = {Topics, _}} = toroco_live_bridge:state(H),
            {Reply, R1} = advertised(lists:any(fun(#{topic := T}) -> T =:= Topic end, Topics),
                                     Conn, Topic, Type, R),
            {reply, Reply, set(S#ros{relayed = R1}, H)};
        false ->
            {reply, {error, unknown_call}, H0}
    end;
handle_call(_, _From, H) ->
    {reply, {error, unknown_call}, H}.

%% A topic a client advertises: one of the robot's, one another client
%% advertised (with the same type or another), or a new one.
advertised(true, _Conn, _Topic, _Type, R) ->
    {{error, robot_topic}, R};
advertised(false, Conn, Topic, Type, R) ->
    case R of
        #{Topic := {Type, Conns}} -> {ok, R#{Topic := {Type, lists:usort([Conn | Conns])}}};
        #{Topic := {Other, _}} -> {{error, {type, Other}}, R};
        #{} -> {ok, R#{Topic => {Type, [Conn]}}}
    end.

-spec handle_cast(term(), hub()) -> hub().
handle_cast({count, Counter}, H) when is_atom(Counter) ->
    bump(Counter, H);
handle_cast({unadvertise, Conn, Topic}, H) ->
    unadvertise_all(Conn, [Topic], H);
handle_cast({relay, Topic, Type, Msg}, H) ->
    deliver_msg(Topic, Type, Msg, H);
handle_cast(_, H) ->
    H.

-spec handle_world(map() | none, hub()) -> hub().
handle_world(Snapshot, H) ->
    case toroco_live_bridge:subscribed(<<"/odom">>, H) of
        true -> lists:foldl(fun deliver/2, H, toroco_ros_topics:of_world(Snapshot));
        false -> H
    end.

-spec handle_event(tuple() | retapped, hub()) -> hub().
handle_event(retapped, H) ->
    H;
handle_event({lifecycle, _, _, _}, H) ->
    %% The wiring may have changed: read the topics again when next asked.
    S = #ros{topics = {Topics, _}} = toroco_live_bridge:state(H),
    set(S#ros{topics = {Topics, -1}}, H);
handle_event({dropped, N}, H) ->
    ok = toroco_live_bridge:broadcast(dropped(N), H),
    bump(tap_dropped, N, H);
handle_event(Event, H) ->
    case toroco_ros_topics:event_topic(Event) of
        none -> H;
        Topic ->
            case toroco_live_bridge:subscribed(Topic, H) of
                true -> lists:foldl(fun deliver/2, H, toroco_ros_topics:of_event(Event));
                false -> H
            end
    end.

-spec handle_down(pid(), hub()) -> hub().
handle_down(Conn, H) ->
    unadvertise_all(Conn, maps:keys((toroco_live_bridge:state(H))#ros.relayed), H).

-spec handle_info(term(), hub()) -> hub().
handle_info(_, H) -> H.

-spec stats(hub()) -> map().
stats(H) -> (toroco_live_bridge:state(H))#ros.counters.

-spec dropped(pos_integer()) -> term().
dropped(N) -> {rosbridge, dropped, N}.

%%====================================================================
%% Inside
%%====================================================================

set(S, H) -> toroco_live_bridge:set_state(S, H).

bump(Counter, H) ->
    bump(Counter, 1, H).

bump(Counter, N, H) ->
    S = #ros{counters = Cs} = toroco_live_bridge:state(H),
    set(S#ros{counters = maps:update_with(Counter, fun(K) -> K + N end, N, Cs)}, H).

fresh_topics(H) ->
    S = #ros{topics = {Old, At}} = toroco_live_bridge:state(H),
    Now = erlang:monotonic_time(millisecond),
    case At >= 0 andalso Now - At < ?TOPICS_MS of
        true -> H;
        false ->
            Topics = try toroco_ros_topics:topics()
                     catch _:_ -> Old
                     end,
            set(S#ros{topics = {Topics, Now}}, H)
    end.

deliver({Topic, Type, Msg}, H) ->
    case toroco_live_bridge:subscribed(Topic, H) of
        false -> H;
        true -> deliver_msg(Topic, Type, Msg, H)
    end.

%% Encoded once for every subscriber of the topic.
deliver_msg(Topic, Type, Msg, H) ->
    Json = iolist_to_binary(jiffy:encode(Msg)),
    lists:foldl(fun(C, Acc) -> send_to(C, {rosbridge, message, Topic, Type, Json, Msg}, Acc) end,
                H, toroco_live_bridge:subscribers(Topic, H)).

unadvertise_all(Conn, Topics, H) ->
    S = #ros{relayed = R} = toroco_live_bridge:state(H),
    R1 = lists:foldl(fun(T, Acc) ->
                             case Acc of
                                 #{T := {Ty, Conns}} ->
                                     case Conns -- [Conn] of
                                         [] -> maps:remove(T, Acc);
                                         L -> Acc#{T := {Ty, L}}
                                     end;
                                 #{} -> Acc
                             end
                     end, R, Topics),
    set(S#ros{relayed = R1}, H).

send_to(C, Msg, H) ->
    case toroco_live_bridge:send(C, Msg, H) of
        {dropped, H1} -> bump(dropped, H1);
        {sent, H1} -> bump(messages, H1);
        {gone, H1} -> H1
    end.
