%% @doc The rosbridge v2 server (SPEC §15): a WebSocket server speaking
%% the rosbridge protocol with JSON (RobotWebTools `ROSBRIDGE_PROTOCOL.md'),
%% so `roslib' clients and Foxglove's Rosbridge connection see the robot as
%% ROS 2 topics (`toroco_live_ros') and may drive it through `/cmd_vel'.
%%
%% This process is the server's hub, a child of `toroco_live_sup' like the
%% Foxglove bridge. It owns the listener (`toroco_live_listener', registered
%% as `toroco_live_rosbridge_listener', the same bounds as the dashboard's
%% port), the observer tap subscription (SPEC §10; taken only while a client
%% is connected), the world subscription (for `/odom'), who subscribed to
%% which topic, the robot's topics (read again at most every `?TOPICS_MS'
%% and on lifecycle events) and the counters `/metrics' shows. Each client
%% is its own process (`toroco_live_rosbridge_conn', the mochiweb
%% connection process that took the upgrade), so a slow or hostile client
%% stalls only itself. A message is made (`toroco_live_ros') and encoded
%% once, here, and only when someone subscribed to its topic.
%%
%% Messages between the hub and a connection, built and matched only here:
%% | from | to   | message                              | when                    | answer |
%% |------|------|--------------------------------------|-------------------------|--------|
%% | conn | hub  | `{join, Conn}' (call)                | after the handshake     | `ok' |
%% | conn | hub  | `topics' (call)                      | a subscribe, a service  | `[topic()]' |
%% | conn | hub  | `{subscribe, Conn, Topic}'           | first subscription to a topic | none |
%% | conn | hub  | `{unsubscribe, Conn, Topic}'         | its last one went       | none |
%% | conn | hub  | `{count, Counter}'                   | a fault, a publish, ... | none |
%% | conn | hub  | `{advertise, Conn, Topic, Type}' (call) | a client advertised a topic the robot does not have | `ok' or `{error, Why}' |
%% | conn | hub  | `{unadvertise, Conn, Topic}'         | it unadvertised it      | none |
%% | conn | hub  | `{relay, Topic, Type, Msg}'          | a publish on a relayed topic or on an inbound one | none |
%% | hub  | conn | `{rosbridge, message, Topic, Type, Json, Msg}' | a message on a subscribed topic (its JSON, and the map for CBOR) | none |
%% | hub  | conn | `{rosbridge, dropped, N}'            | N messages were not sent to it | none |
%% A connection whose mailbox holds more than `?CONN_QUEUE' messages gets no
%% more until it drains; the hub counts what it skipped and tells it.
%%
%% <b>Relaying</b>, as a rosbridge server in a ROS graph does: a topic a
%% client advertises that the robot does not have (another robot in client
%% mode, `toroco_live_rosclient', advertising its own) is listed among the
%% topics while an advertiser is connected, and what is published on it goes
%% to the clients subscribed to it; a publish on an inbound topic
%% (`/cmd_vel') goes to its subscribers too, besides the `ros' device.
-module(toroco_live_rosbridge).
-behaviour(gen_server).

-export([child_spec/1, port/0, stats/0]).
-export([join/0, topics/0, subscribe/2, unsubscribe/2, count/1, receive_hub/1]).
-export([advertise/3, unadvertise/2, relay/3]).
-export([start_link/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-define(LISTENER, toroco_live_rosbridge_listener).
-define(CONN_QUEUE, 1000).
-define(TAP_BUFFER, 1000).
-define(TOPICS_MS, 1000).
-define(RETAP_MS, 2000).

-record(hub, {listener :: pid(),
              port :: inet:port_number(),
              topics = {[], -1} :: {[toroco_live_ros:topic()], integer()},
              %% topics clients advertised: type and advertisers
              relayed = #{} :: #{binary() => {binary(), [pid()]}},
              %% subscribed to topic names; the tap taken while clients
              %% are connected
              clients = toroco_live_clients:new(#{kinds => [emit, lifecycle], buffer => ?TAP_BUFFER,
                                                  retry_ms => ?RETAP_MS, world => true,
                                                  who => <<"rosbridge">>}) :: toroco_live_clients:clients(),
              counters = #{} :: #{atom() => non_neg_integer()}}).

%%====================================================================
%% API
%%====================================================================

%% @doc The server as a child of `toroco_live_sup', for
%% `toroco_live:start/1' (`ip', and `rosbridge', the port, 0 for any free
%% one; the listener's bounds as the dashboard's).
-spec child_spec(#{rosbridge := inet:port_number(), atom() => term()}) -> supervisor:child_spec().
child_spec(Config) ->
    #{id => ?MODULE, start => {?MODULE, start_link, [Config]}, restart => permanent}.

%% @doc The port the server listens on, `off' when it does not run.
-spec port() -> inet:port_number() | off.
port() ->
    try gen_server:call(?MODULE, port)
    catch exit:_ -> off
    end.

%% @doc The counters (`/metrics'): `clients' and `subscriptions' (of
%% clients to topics) now, and totals: `connections',
%% `messages' sent to clients, `dropped' (not sent to a client behind),
%% `tap_dropped' (events the hub itself fell behind on, SPEC §10),
%% `published' (handed to the `ros' device), `refused_unauthorized',
%% `faults' (status errors for bad input), `disconnected' (clients closed
%% for misbehaving), `fragments_expired'. Empty when the server does not run.
-spec stats() -> #{atom() => non_neg_integer()}.
stats() ->
    try gen_server:call(?MODULE, stats, 10000)
    catch exit:_ -> #{}
    end.

%%====================================================================
%% The connections' side
%%====================================================================

-spec join() -> ok | {error, server_down}.
join() ->
    try gen_server:call(?MODULE, {join, self()}, 15000)
    catch exit:_ -> {error, server_down}
    end.

%% @doc The robot's topics now (cached for `?TOPICS_MS').
-spec topics() -> [toroco_live_ros:topic()].
topics() ->
    try gen_server:call(?MODULE, topics, 15000)
    catch exit:_ -> []
    end.

-spec subscribe(pid(), binary()) -> ok.
subscribe(Conn, Topic) -> gen_server:cast(?MODULE, {subscribe, Conn, Topic}).

-spec unsubscribe(pid(), binary()) -> ok.
unsubscribe(Conn, Topic) -> gen_server:cast(?MODULE, {unsubscribe, Conn, Topic}).

%% @doc A client advertises `Topic' of `Type', a topic the robot does not
%% have: `{error, robot_topic}' if it does, `{error, {type, Other}}' if
%% another client advertised it as `Other'.
-spec advertise(pid(), binary(), binary()) -> ok | {error, robot_topic | {type, binary()} | server_down}.
advertise(Conn, Topic, Type) ->
    try gen_server:call(?MODULE, {advertise, Conn, Topic, Type}, 15000)
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
          {ok, {message, binary(), {binary(), binary(), toroco_live_ros:message()}}
               | {dropped, pos_integer()}} | error.
receive_hub({rosbridge, message, Topic, Type, Json, Msg}) -> {ok, {message, Topic, {Type, Json, Msg}}};
receive_hub({rosbridge, dropped, N}) -> {ok, {dropped, N}};
receive_hub(_) -> error.

%%====================================================================
%% gen_server
%%====================================================================

-spec start_link(map()) -> {ok, pid()} | {error, term()}.
start_link(Opts) ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, Opts, []).

-spec init(map()) -> {ok, #hub{}} | {stop, term()}.
init(Opts) ->
    process_flag(trap_exit, true),
    ConnOpts = maps:with([max_message], Opts),
    Loop = fun(Req) -> toroco_live_rosbridge_conn:serve(Req, ConnOpts) end,
    case toroco_live_listener:start_link(?LISTENER, Opts, maps:get(rosbridge, Opts), Loop) of
        {ok, Listener} ->
            {ok, #hub{listener = Listener, port = toroco_live_listener:port(Listener)}};
        {error, Why} ->
            {stop, {listen, Why}}
    end.

-spec handle_call(term(), gen_server:from(), #hub{}) -> {reply, term(), #hub{}}.
handle_call(port, _From, H) ->
    {reply, H#hub.port, H};
handle_call(stats, _From, H = #hub{clients = Cl, counters = Cs}) ->
    {reply, Cs#{clients => toroco_live_clients:size(Cl),
                subscriptions => toroco_live_clients:subscriptions(Cl)}, H};
handle_call({join, Conn}, _From, H) ->
    {reply, ok, bump(connections, H#hub{clients = toroco_live_clients:join(Conn, H#hub.clients)})};
handle_call(topics, _From, H0) ->
    H = fresh_topics(H0),
    {Topics, _} = H#hub.topics,
    Robot = [T || #{topic := T} <- Topics],
    Relayed = [#{topic => T, type => Ty, dir => out}
               || {T, {Ty, _}} <- lists:sort(maps:to_list(H#hub.relayed)), not lists:member(T, Robot)],
    {reply, Topics ++ Relayed, H};
handle_call({advertise, Conn, Topic, Type}, _From, H0) ->
    case toroco_live_clients:member(Conn, H0#hub.clients) of
        true ->
            H = #hub{relayed = R, topics = {Topics, _}} = fresh_topics(H0),
            case {lists:any(fun(#{topic := T}) -> T =:= Topic end, Topics), R} of
                {true, _} -> {reply, {error, robot_topic}, H};
                {false, #{Topic := {Type, Conns}}} ->
                    {reply, ok, H#hub{relayed = R#{Topic := {Type, lists:usort([Conn | Conns])}}}};
                {false, #{Topic := {Other, _}}} -> {reply, {error, {type, Other}}, H};
                {false, #{}} -> {reply, ok, H#hub{relayed = R#{Topic => {Type, [Conn]}}}}
            end;
        false ->
            {reply, {error, unknown_call}, H0}
    end;
handle_call(_, _From, H) ->
    {reply, {error, unknown_call}, H}.

-spec handle_cast(term(), #hub{}) -> {noreply, #hub{}}.
handle_cast({subscribe, Conn, Topic}, H = #hub{clients = Cl}) ->
    case toroco_live_clients:member(Conn, Cl) of
        true -> {noreply, H#hub{clients = toroco_live_clients:subscribe(Conn, [Topic], Cl)}};
        false -> {noreply, H}
    end;
handle_cast({unsubscribe, Conn, Topic}, H = #hub{clients = Cl}) ->
    {noreply, H#hub{clients = toroco_live_clients:unsubscribe(Conn, [Topic], Cl)}};
handle_cast({count, Counter}, H) when is_atom(Counter) ->
    {noreply, bump(Counter, H)};
handle_cast({unadvertise, Conn, Topic}, H) ->
    {noreply, unadvertise_all(Conn, [Topic], H)};
handle_cast({relay, Topic, Type, Msg}, H) ->
    {noreply, deliver_msg(Topic, Type, Msg, H)};
handle_cast(_, H) ->
    {noreply, H}.

-spec handle_info(term(), #hub{}) -> {noreply, #hub{}} | {stop, term(), #hub{}}.
handle_info({toroco_live_world, changed}, H) ->
    %% Reading re-arms the notification: read even with nobody on /odom.
    Snapshot = toroco_live_world:latest(),
    case toroco_live_clients:subscribed(<<"/odom">>, H#hub.clients) of
        true -> {noreply, lists:foldl(fun deliver/2, H, toroco_live_ros:of_world(Snapshot))};
        false -> {noreply, H}
    end;
handle_info({'EXIT', L, Why}, H = #hub{listener = L}) ->
    {stop, {listener, Why}, H};
handle_info(Info, H = #hub{clients = Cl}) ->
    case toroco_live_clients:handle(Info, Cl) of
        {events, Events} -> {noreply, lists:foldl(fun event/2, H, Events)};
        {down, Conn, Cl1} ->
            {noreply, unadvertise_all(Conn, maps:keys(H#hub.relayed), H#hub{clients = Cl1})};
        {_, Cl1} -> {noreply, H#hub{clients = Cl1}};
        ignore -> {noreply, H}
    end.

-spec terminate(term(), #hub{}) -> ok.
terminate(_, H = #hub{listener = L, clients = Cl}) ->
    %% What was emitted before the stop goes to the clients first.
    _ = (catch lists:foldl(fun event/2, H, toroco_live_clients:stop(Cl))),
    toroco_live_listener:stop(L).

%%====================================================================
%% Inside
%%====================================================================

bump(Counter, H) ->
    bump(Counter, 1, H).

bump(Counter, N, H = #hub{counters = Cs}) ->
    H#hub{counters = maps:update_with(Counter, fun(K) -> K + N end, N, Cs)}.

fresh_topics(H = #hub{topics = {_, At}}) ->
    Now = erlang:monotonic_time(millisecond),
    case At >= 0 andalso Now - At < ?TOPICS_MS of
        true -> H;
        false ->
            Topics = try toroco_live_ros:topics()
                     catch _:_ -> element(1, H#hub.topics)
                     end,
            H#hub{topics = {Topics, Now}}
    end.

event({lifecycle, _, _, _}, H = #hub{topics = {Topics, _}}) ->
    %% The wiring may have changed: read the topics again when next asked.
    H#hub{topics = {Topics, -1}};
event({dropped, N}, H) ->
    ok = toroco_live_clients:broadcast({rosbridge, dropped, N}, H#hub.clients),
    bump(tap_dropped, N, H);
event(Event, H) ->
    case toroco_live_ros:event_topic(Event) of
        none -> H;
        Topic ->
            case toroco_live_clients:subscribed(Topic, H#hub.clients) of
                true -> lists:foldl(fun deliver/2, H, toroco_live_ros:of_event(Event));
                false -> H
            end
    end.

deliver({Topic, Type, Msg}, H) ->
    case toroco_live_clients:subscribed(Topic, H#hub.clients) of
        false -> H;
        true -> deliver_msg(Topic, Type, Msg, H)
    end.

%% Encoded once for every subscriber of the topic.
deliver_msg(Topic, Type, Msg, H) ->
    Json = iolist_to_binary(jiffy:encode(Msg)),
    lists:foldl(fun(C, Acc) -> send_to(C, {rosbridge, message, Topic, Type, Json, Msg}, Acc) end,
                H, toroco_live_clients:subscribers(Topic, H#hub.clients)).

unadvertise_all(Conn, Topics, H = #hub{relayed = R}) ->
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
    H#hub{relayed = R1}.

%% A connection behind by more than ?CONN_QUEUE messages misses this one;
%% it hears how many it missed once it has caught up.
send_to(C, Msg, H) ->
    case toroco_live_clients:offer(C, Msg, fun(N) -> {rosbridge, dropped, N} end, ?CONN_QUEUE, H#hub.clients) of
        {dropped, Cl} -> bump(dropped, H#hub{clients = Cl});
        {sent, Cl} -> bump(messages, H#hub{clients = Cl});
        {gone, _} -> H
    end.
