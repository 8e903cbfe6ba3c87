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

-export([child_spec/1, port/0]).
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
              conns = #{} :: #{pid() => reference()},
              subs = #{} :: #{pos_integer() => [pid()]},
              dropped = #{} :: #{pid() => pos_integer()},
              %% taken while clients are connected; when the runtime
              %% restarts, the hub subscribes again
              tap = toroco_live_tap:new(#{buffer => ?TAP_BUFFER, retry_ms => ?REFRESH_MS,
                                           world => true, who => <<"Foxglove bridge">>})
                  :: toroco_live_tap:tap()}).

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
    gen_server:start_link({local, ?MODULE}, ?MODULE, Opts, []).

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
handle_call({join, Conn}, _From, H0) ->
    H = tap_on(H0),
    H1 = (refresh(H, true))#hub{conns = (H#hub.conns)#{Conn => monitor(process, Conn)}},
    {reply, {ok, channels(H1, all_keys(H1)), toroco_live_channels:graph(H1#hub.wiring)}, H1};
handle_call(_, _From, H) ->
    {reply, {error, unknown_call}, H}.

-spec handle_cast(term(), #hub{}) -> {noreply, #hub{}}.
handle_cast({subscribe, Conn, Ids}, H = #hub{subs = Subs}) ->
    {noreply, H#hub{subs = lists:foldl(fun(Id, S) -> maps:update_with(Id, fun(L) -> lists:usort([Conn | L]) end, [Conn], S) end,
                                       Subs, Ids)}};
handle_cast({unsubscribe, Conn, Ids}, H) ->
    {noreply, unsubscribe_all(Conn, Ids, H)};
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
handle_info({'DOWN', _, process, Conn, _}, H = #hub{conns = Conns, subs = Subs})
  when is_map_key(Conn, Conns) ->
    H1 = unsubscribe_all(Conn, maps:keys(Subs),
                         H#hub{conns = maps:remove(Conn, Conns),
                               dropped = maps:remove(Conn, H#hub.dropped)}),
    {noreply, tap_off(H1)};
handle_info({'EXIT', L, Why}, H = #hub{listener = L}) ->
    {stop, {listener, Why}, H};
handle_info(Info, H = #hub{tap = Tap, conns = Conns}) ->
    case toroco_live_tap:handle(Info, Tap) of
        {event, Event} -> {noreply, event(Event, H)};
        {down, Tap1} -> {noreply, H#hub{tap = Tap1}};
        {retry, Tap1} when map_size(Conns) > 0 -> {noreply, refresh(tap_on(H#hub{tap = Tap1}))};
        {retry, Tap1} -> {noreply, H#hub{tap = Tap1}};
        _ -> {noreply, H}
    end.

-spec terminate(term(), #hub{}) -> ok.
terminate(_, #hub{listener = L, tap = Tap}) ->
    _ = toroco_live_tap:off(Tap),
    toroco_live_listener:stop(L).

%%====================================================================
%% Inside
%%====================================================================

tap_on(H = #hub{tap = Tap}) ->
    H#hub{tap = toroco_live_tap:ensure_on(Tap)}.

tap_off(H = #hub{tap = Tap, conns = Conns}) when map_size(Conns) =:= 0 ->
    H#hub{tap = toroco_live_tap:off(Tap), subs = #{}};
tap_off(H) -> H.

event(Event = {lifecycle, _, _, _}, H) ->
    send_event(Event, refresh(H));
event({dropped, N}, H = #hub{conns = Conns}) ->
    _ = [C ! {fox, dropped, N} || C <- maps:keys(Conns)],
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
            case maps:get(maps:get(Key, H1#hub.ids, none), H1#hub.subs, []) of
                [] -> H1;
                _ -> deliver(toroco_live_channels:of_event(Event), H1)
            end
    end.

deliver({Key, T, Json}, H = #hub{ids = Ids, subs = Subs}) ->
    case Ids of
        #{Key := Id} ->
            lists:foldl(fun(C, Acc) -> send_to(C, {fox, message, Id, T, Json}, Acc) end,
                        H, maps:get(Id, Subs, []));
        #{} -> H
    end.

%% A connection behind by more than ?CONN_QUEUE messages misses this one;
%% it hears how many it missed once it has caught up.
send_to(C, Msg, H = #hub{dropped = D}) ->
    {_, D1} = toroco_live_ws_conn:offer(C, Msg, fun(N) -> {fox, dropped, N} end, ?CONN_QUEUE, D),
    H#hub{dropped = D1}.

refresh(H) ->
    refresh(H, false).

%% Nobody to tell: the wiring is read when the next client joins.
refresh(H = #hub{conns = Conns}, false) when map_size(Conns) =:= 0 ->
    H;
refresh(H = #hub{wiring = Old, conns = Conns}, _) ->
    New = try toroco_live_channels:from_wiring()
          catch _:_ -> Old
          end,
    #{keys := OldKeys} = Old,
    #{keys := NewKeys} = New,
    Gone = OldKeys -- NewKeys,
    Added = NewKeys -- OldKeys,
    H1 = advertise(H#hub{wiring = New}, Added),
    GoneIds = [maps:get(K, H1#hub.ids) || K <- Gone],
    _ = [C ! {fox, unadvertise, GoneIds} || GoneIds =/= [], C <- maps:keys(Conns)],
    New =:= Old orelse
        [C ! {fox, graph, toroco_live_channels:graph(New)} || C <- maps:keys(Conns)],
    H1#hub{subs = maps:without(GoneIds, H1#hub.subs)}.

advertise(H, []) -> H;
advertise(H0 = #hub{conns = Conns}, Keys) ->
    H = lists:foldl(fun(K, Acc = #hub{ids = Ids, next_id = N}) ->
                            case Ids of
                                #{K := _} -> Acc;
                                #{} -> Acc#hub{ids = Ids#{K => N}, next_id = N + 1}
                            end
                    end, H0, Keys),
    Channels = channels(H, Keys),
    _ = [C ! {fox, advertise, Channels} || C <- maps:keys(Conns)],
    H.

all_keys(#hub{wiring = #{keys := Keys}, world = World}) -> Keys ++ World.

channels(#hub{ids = Ids}, Keys) ->
    [begin
         {Name, Schema} = toroco_live_channels:schema(K),
         #{id => maps:get(K, Ids), key => K, topic => toroco_live_channels:topic(K),
           schema_name => Name, schema => Schema}
     end || K <- Keys, maps:is_key(K, Ids)].

unsubscribe_all(Conn, Ids, H = #hub{subs = Subs}) ->
    Subs1 = lists:foldl(fun(Id, S) ->
                                case maps:get(Id, S, []) -- [Conn] of
                                    [] -> maps:remove(Id, S);
                                    L -> S#{Id => L}
                                end
                        end, Subs, Ids),
    H#hub{subs = Subs1}.
