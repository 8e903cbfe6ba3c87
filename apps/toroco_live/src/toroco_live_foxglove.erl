%% @doc The Foxglove bridge (SPEC §12): a WebSocket server speaking the
%% Foxglove protocol (`foxglove.websocket.v1', JSON encoding, a JSON Schema
%% per channel), so Foxglove and Lichtblick show the running robot.
%%
%% This process is the bridge's hub, a child of `toroco_live_sup'. It owns
%% the listener (`toroco_live_listener', registered as
%% `toroco_live_foxglove_listener': the same bounds as the dashboard's
%% port, its closes in `/metrics'), the channel table (ids never reused for another
%% topic), the observer tap subscription (SPEC §10; taken only while a
%% client is connected, so a bridge nobody watches costs the robot nothing)
%% and who subscribed to what. Each client is its own process
%% (`toroco_live_foxglove_conn', the mochiweb connection process that took
%% the upgrade), so a slow or hostile client stalls only itself.
%%
%% Channels follow the running wiring: they are re-read
%% (`toroco_live_channels:from_wiring/0') on every lifecycle event, when
%% an event names a channel not yet known, and every
%% `?REFRESH_MS' (wiring changes make no event of their own), and the
%% difference is advertised and unadvertised to every client.
%%
%% Messages between the hub and a connection, built and matched only here:
%% | from | to  | message                         | when                           | answer |
%% |------|-----|---------------------------------|--------------------------------|--------|
%% | conn | hub | `join' (call)                   | after the handshake            | `{ok, Channels, Graph}' |
%% | conn | hub | `{subscribe, Conn, [Id]}'       | the client subscribed          | none |
%% | conn | hub | `{unsubscribe, Conn, [Id]}'     | the client unsubscribed        | none |
%% | hub  | conn| `{fox, advertise, Channels}'    | channels appeared              | none |
%% | hub  | conn| `{fox, unadvertise, [Id]}'      | channels went                  | none |
%% | hub  | conn| `{fox, graph, Graph}'           | the wiring changed             | none |
%% | hub  | conn| `{fox, message, Id, T, Json}'   | an event on a subscribed channel | none |
%% | hub  | conn| `{fox, dropped, N}'             | N messages were not sent to it | none |
%% The world's snapshots come from `toroco_live_world' (its protocol) while
%% a client is connected, and become the `/toroco/sim/...' channels.
%% A connection whose mailbox holds more than `?CONN_QUEUE' messages gets
%% no more until it drains; the hub counts what it skipped and tells it.
-module(toroco_live_foxglove).
-behaviour(gen_server).

-export([child_spec/1, port/0, stats/0]).
-export([start_link/1, join/0, subscribe/2, unsubscribe/2, receive_fox/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([channel/0, fox/0]).

-define(SUBPROTOCOL, <<"foxglove.websocket.v1">>).
-define(REFRESH_MS, 2000).
-define(LISTENER, toroco_live_foxglove_listener).
-define(CONN_QUEUE, 2000).
%% A live view needs no long backlog: past this many pending events the
%% tap drops (and counts) rather than let clients, joins among them, wait.
-define(TAP_BUFFER, 1000).

-type channel() :: #{id := pos_integer(), key := toroco_live_channels:key(), topic := binary(),
                     schema_name := binary(), schema := binary()}.
-type fox() :: {advertise, [channel()]} | {unadvertise, [pos_integer()]}
             | {graph, {list(), list()}} | {message, pos_integer(), integer(), binary()}
             | {dropped, pos_integer()}.

-record(hub, {listener :: pid(),
              port :: inet:port_number(),
              ids = #{} :: #{toroco_live_channels:key() => pos_integer()},
              next_id = 1 :: pos_integer(),
              wiring = #{keys => [], receivers => #{}} :: toroco_live_channels:wiring(),
              world = [] :: [toroco_live_channels:key()],
              scene = none :: toroco_live_channels:scene_sent(),
              %% subscribed to channel ids; the tap taken while clients
              %% are connected, and again when the runtime restarts
              clients = toroco_live_clients:new(#{buffer => ?TAP_BUFFER, retry_ms => ?REFRESH_MS,
                                                  world => true, who => <<"Foxglove bridge">>})
                  :: toroco_live_clients:clients()}).

%%====================================================================
%% API
%%====================================================================

%% @doc The bridge as a child of `toroco_live_sup', for `toroco_live:start/1'
%% (SPEC §11's keys: `ip', default `{127,0,0,1}', and `foxglove', the port,
%% 0 for any free one). Whether clients may publish is the app env
%% `client_publish' (default `false').
-spec child_spec(#{foxglove := inet:port_number(), ip => inet:ip_address(), atom() => term()}) ->
          supervisor:child_spec().
child_spec(Config) ->
    #{id => ?MODULE, start => {?MODULE, start_link, [Config]}, restart => permanent}.

%% @doc The port the bridge listens on, `off' when it does not run.
-spec port() -> inet:port_number() | off.
port() ->
    try gen_server:call(?MODULE, port)
    catch exit:{noproc, _} -> off
    end.

%% @doc `clients' connected and their `subscriptions' to channels, now
%% (`/metrics'); empty when the bridge does not run.
-spec stats() -> #{clients => non_neg_integer(), subscriptions => non_neg_integer()}.
stats() ->
    try gen_server:call(?MODULE, stats, 10000)
    catch exit:_ -> #{}
    end.

%%====================================================================
%% The connections' side of the protocol
%%====================================================================

%% @doc A connection joins: the channels to advertise and the graph.
-spec join() -> {ok, [channel()], {list(), list()}} | {error, term()}.
join() ->
    try gen_server:call(?MODULE, {join, self()}, 15000)
    catch exit:_ -> {error, bridge_down}
    end.

-spec subscribe(pid(), [pos_integer()]) -> ok.
subscribe(Conn, Ids) -> gen_server:cast(?MODULE, {subscribe, Conn, Ids}).

-spec unsubscribe(pid(), [pos_integer()]) -> ok.
unsubscribe(Conn, Ids) -> gen_server:cast(?MODULE, {unsubscribe, Conn, Ids}).

%% @doc What a hub message says, for the connection's `handle_info'.
-spec receive_fox(term()) -> {ok, fox()} | error.
receive_fox({fox, advertise, Cs}) -> {ok, {advertise, Cs}};
receive_fox({fox, unadvertise, Ids}) -> {ok, {unadvertise, Ids}};
receive_fox({fox, graph, G}) -> {ok, {graph, G}};
receive_fox({fox, message, Id, T, Json}) -> {ok, {message, Id, T, Json}};
receive_fox({fox, dropped, N}) -> {ok, {dropped, N}};
receive_fox(_) -> error.

%%====================================================================
%% gen_server
%%====================================================================

-spec start_link(map()) -> {ok, pid()} | {error, term()}.
start_link(Opts) ->
    %% Behind a busy CPU its heap grows with the events it holds; the old
    %% heap is swept often so that it shrinks back.
    gen_server:start_link({local, ?MODULE}, ?MODULE, Opts, [{spawn_opt, [{fullsweep_after, 10}]}]).

-spec init(map()) -> {ok, #hub{}} | {stop, term()}.
init(Opts) ->
    process_flag(trap_exit, true),
    Publish = maps:get(client_publish, Opts,
                       application:get_env(toroco_live, client_publish, false)) =:= true,
    Session = integer_to_binary(erlang:system_time(millisecond)),
    Loop = fun(Req) -> toroco_live_foxglove_conn:serve(Req, ?SUBPROTOCOL,
                                                        #{client_publish => Publish,
                                                          session => Session}) end,
    case toroco_live_listener:start_link(?LISTENER, Opts, maps:get(foxglove, Opts), Loop) of
        {ok, Listener} ->
            Port = toroco_live_listener:port(Listener),
            %% The wiring is read again every ?REFRESH_MS while clients
            %% are connected (refresh/1 does nothing without them).
            erlang:send_after(?REFRESH_MS, self(), refresh),
            {ok, #hub{listener = Listener, port = Port}};
        {error, Why} ->
            {stop, {listen, Why}}
    end.

-spec handle_call(term(), gen_server:from(), #hub{}) -> {reply, term(), #hub{}}.
handle_call(port, _From, H) ->
    {reply, H#hub.port, H};
handle_call(stats, _From, H = #hub{clients = Cl}) ->
    {reply, #{clients => toroco_live_clients:size(Cl),
              subscriptions => toroco_live_clients:subscriptions(Cl)}, H};
handle_call({join, Conn}, _From, H) ->
    %% read before it joins: the reply carries every channel
    H0 = refresh(H, true),
    H1 = H0#hub{clients = toroco_live_clients:join(Conn, H0#hub.clients)},
    {reply, {ok, channels(H1, all_keys(H1)), toroco_live_channels:graph(H1#hub.wiring)}, H1};
handle_call(_, _From, H) ->
    {reply, {error, unknown_call}, H}.

-spec handle_cast(term(), #hub{}) -> {noreply, #hub{}}.
handle_cast({subscribe, Conn, Ids}, H = #hub{clients = Cl}) ->
    {noreply, H#hub{clients = toroco_live_clients:subscribe(Conn, Ids, Cl)}};
handle_cast({unsubscribe, Conn, Ids}, H = #hub{clients = Cl}) ->
    {noreply, H#hub{clients = toroco_live_clients:unsubscribe(Conn, Ids, Cl)}};
handle_cast(_, H) ->
    {noreply, H}.

-spec handle_info(term(), #hub{}) -> {noreply, #hub{}} | {stop, term(), #hub{}}.
handle_info({toroco_live_world, changed}, H) ->
    {Msgs, Scene} = toroco_live_channels:world(toroco_live_world:latest(),
                                               erlang:system_time(nanosecond), H#hub.scene),
    H1 = case H#hub.world of
             [] -> advertise(H#hub{world = [K || {K, _, _} <- Msgs]}, [K || {K, _, _} <- Msgs]);
             _ -> H
         end,
    {noreply, lists:foldl(fun deliver/2, H1#hub{scene = Scene}, Msgs)};
handle_info(refresh, H) ->
    erlang:send_after(?REFRESH_MS, self(), refresh),
    {noreply, refresh(H)};
handle_info({'EXIT', L, Why}, H = #hub{listener = L}) ->
    {stop, {listener, Why}, H};
handle_info(Info, H = #hub{clients = Cl}) ->
    case toroco_live_clients:handle(Info, Cl) of
        {events, Events} -> {noreply, lists:foldl(fun event/2, H, Events)};
        {retapped, Cl1} -> {noreply, refresh(H#hub{clients = Cl1})};
        {down, _Conn, Cl1} -> {noreply, H#hub{clients = Cl1}};
        {ok, Cl1} -> {noreply, H#hub{clients = Cl1}};
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

event(Event = {lifecycle, _, _, _}, H) ->
    send_event(Event, refresh(H));
event({dropped, N}, H) ->
    ok = toroco_live_clients:broadcast({fox, dropped, N}, H#hub.clients),
    H;
event(Event, H) ->
    send_event(Event, H).

%% An event's JSON is made only when a client subscribed to its channel.
send_event(Event, H) ->
    case toroco_live_channels:event_key(Event) of
        none -> H;
        Key ->
            H1 = case maps:is_key(Key, H#hub.ids) of
                     true -> H;
                     false -> refresh(H)
                 end,
            case toroco_live_clients:subscribed(maps:get(Key, H1#hub.ids, none), H1#hub.clients) of
                false -> H1;
                true -> deliver(toroco_live_channels:of_event(Event), H1)
            end
    end.

deliver({Key, T, Json}, H = #hub{ids = Ids, clients = Cl}) ->
    case Ids of
        #{Key := Id} ->
            lists:foldl(fun(C, Acc) -> send_to(C, {fox, message, Id, T, Json}, Acc) end,
                        H, toroco_live_clients:subscribers(Id, Cl));
        #{} -> H
    end.

%% A connection behind by more than ?CONN_QUEUE messages misses this one;
%% it hears how many it missed once it has caught up.
send_to(C, Msg, H = #hub{clients = Cl}) ->
    {_, Cl1} = toroco_live_clients:offer(C, Msg, fun(N) -> {fox, dropped, N} end, ?CONN_QUEUE, Cl),
    H#hub{clients = Cl1}.

refresh(H) ->
    refresh(H, false).

%% Nobody to tell: the wiring is read when the next client joins.
refresh(H = #hub{wiring = Old, clients = Cl}, Joining) ->
    case toroco_live_clients:pids(Cl) of
        [] when not Joining -> H;
        Conns -> refresh(H, Old, Conns)
    end.

refresh(H, Old, Conns) ->
    New = try toroco_live_channels:from_wiring()
          catch _:_ -> Old
          end,
    #{keys := OldKeys} = Old,
    #{keys := NewKeys} = New,
    Gone = OldKeys -- NewKeys,
    Added = NewKeys -- OldKeys,
    H1 = advertise(H#hub{wiring = New}, Added),
    GoneIds = [maps:get(K, H1#hub.ids) || K <- Gone],
    _ = [C ! {fox, unadvertise, GoneIds} || GoneIds =/= [], C <- Conns],
    New =:= Old orelse
        [C ! {fox, graph, toroco_live_channels:graph(New)} || C <- Conns],
    H1#hub{clients = toroco_live_clients:forget(GoneIds, H1#hub.clients)}.

advertise(H, []) -> H;
advertise(H0, Keys) ->
    H = lists:foldl(fun(K, Acc = #hub{ids = Ids, next_id = N}) ->
                            case Ids of
                                #{K := _} -> Acc;
                                #{} -> Acc#hub{ids = Ids#{K => N}, next_id = N + 1}
                            end
                    end, H0, Keys),
    Channels = channels(H, Keys),
    ok = toroco_live_clients:broadcast({fox, advertise, Channels}, H#hub.clients),
    H.

all_keys(#hub{wiring = #{keys := Keys}, world = World}) -> Keys ++ World.

channels(#hub{ids = Ids}, Keys) ->
    [begin
         {Name, Schema} = toroco_live_channels:schema(K),
         #{id => maps:get(K, Ids), key => K, topic => toroco_live_channels:topic(K),
           schema_name => Name, schema => Schema}
     end || K <- Keys, maps:is_key(K, Ids)].
