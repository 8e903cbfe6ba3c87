%% @doc The Foxglove bridge (SPEC §12): a WebSocket server speaking the
%% Foxglove protocol (`foxglove.websocket.v1', JSON encoding, a JSON Schema
%% per channel), so Foxglove and Lichtblick show the running robot.
%%
%% This module is the bridge's hub, a callback module of
%% `toroco_live_bridge' (a child of `toroco_live_sup'), which owns the
%% listener (registered as `toroco_live_foxglove_listener': the same bounds
%% as the dashboard's port, its closes in `/metrics'), the observer tap
%% (SPEC §10; taken only while a client is connected, so a bridge nobody
%% watches costs the robot nothing) and who subscribed to what; this module
%% keeps the channel table (ids never reused for another topic) and what
%% the clients are shown. Each client is its own process
%% (`toroco_live_foxglove_conn', the mochiweb connection process that took
%% the upgrade), so a slow or hostile client stalls only itself.
%%
%% Channels follow the running wiring: they are re-read
%% (`toroco_rec_channels:from_wiring/0') on every lifecycle event, when
%% an event names a channel not yet known, and every
%% `?REFRESH_MS' (wiring changes make no event of their own), and the
%% difference is advertised and unadvertised to every client.
%%
%% Messages between the hub and a connection, built and matched only here
%% (and in `toroco_live_bridge', for the join and subscriptions, keys the
%% channel ids):
%% | from | to  | message                         | when                           | answer |
%% |------|-----|---------------------------------|--------------------------------|--------|
%% | conn | hub | join (`toroco_live_bridge')     | after the handshake            | `{ok, Channels, Graph}' |
%% | hub  | conn| `{fox, advertise, Channels}'    | channels appeared              | none |
%% | hub  | conn| `{fox, unadvertise, [Id]}'      | channels went                  | none |
%% | hub  | conn| `{fox, graph, Graph}'           | the wiring changed             | none |
%% | hub  | conn| `{fox, message, Id, T, Json}'   | an event on a subscribed channel | none |
%% | hub  | conn| `{fox, dropped, N}'             | N messages were not sent to it | none |
%% The world's snapshots come from `toroco_live_world' (its protocol) while
%% a client is connected, and become the `/toroco/sim/...' channels.
%% A connection whose mailbox holds more than `?CONN_QUEUE' messages gets
%% no more until it drains; it hears how many it missed.
-module(toroco_live_foxglove).
-behaviour(toroco_live_bridge).

-export([port/0, stats/0]).
-export([join/0, subscribe/2, unsubscribe/2, receive_fox/1]).
-export([init/1, handle_join/2, handle_event/2, handle_world/2, handle_down/2, handle_call/3,
         handle_cast/2, handle_info/2, stats/1, dropped/1]).

-export_type([channel/0, fox/0]).

-define(SUBPROTOCOL, <<"foxglove.websocket.v1">>).
-define(REFRESH_MS, 2000).
-define(LISTENER, toroco_live_foxglove_listener).
-define(CONN_QUEUE, 2000).
%% A live view needs no long backlog: past this many pending events the
%% tap drops (and counts) rather than let clients, joins among them, wait.
-define(TAP_BUFFER, 1000).

-type channel() :: #{id := pos_integer(), key := toroco_rec_channels:key(), topic := binary(),
                     schema_name := binary(), schema := binary()}.
-type fox() :: {advertise, [channel()]} | {unadvertise, [pos_integer()]}
             | {graph, {list(), list()}} | {message, pos_integer(), integer(), binary()}
             | {dropped, pos_integer()}.

-record(fox, {ids = #{} :: #{toroco_rec_channels:key() => pos_integer()},
              next_id = 1 :: pos_integer(),
              wiring = #{keys => [], receivers => #{}} :: toroco_rec_channels:wiring(),
              world = [] :: [toroco_rec_channels:key()],
              scene = none :: toroco_rec_channels:scene_sent()}).

%%====================================================================
%% API
%%====================================================================

%% @doc The port the bridge listens on, `off' when it does not run.
-spec port() -> inet:port_number() | off.
port() ->
    toroco_live_bridge:port(?MODULE).

%% @doc `clients' connected and their `subscriptions' to channels, now
%% (`/metrics'); empty when the bridge does not run.
-spec stats() -> #{clients => non_neg_integer(), subscriptions => non_neg_integer()}.
stats() ->
    toroco_live_bridge:stats(?MODULE).

%%====================================================================
%% The connections' side of the protocol
%%====================================================================

%% @doc A connection joins: the channels to advertise and the graph.
-spec join() -> {ok, [channel()], {list(), list()}} | {error, term()}.
join() ->
    toroco_live_bridge:join(?MODULE).

-spec subscribe(pid(), [pos_integer()]) -> ok.
subscribe(Conn, Ids) -> toroco_live_bridge:subscribe(?MODULE, Conn, Ids).

-spec unsubscribe(pid(), [pos_integer()]) -> ok.
unsubscribe(Conn, Ids) -> toroco_live_bridge:unsubscribe(?MODULE, Conn, Ids).

%% @doc What a hub message says, for the connection's `handle_info'.
-spec receive_fox(term()) -> {ok, fox()} | error.
receive_fox({fox, advertise, Cs}) -> {ok, {advertise, Cs}};
receive_fox({fox, unadvertise, Ids}) -> {ok, {unadvertise, Ids}};
receive_fox({fox, graph, G}) -> {ok, {graph, G}};
receive_fox({fox, message, Id, T, Json}) -> {ok, {message, Id, T, Json}};
receive_fox({fox, dropped, N}) -> {ok, {dropped, N}};
receive_fox(_) -> error.

%%====================================================================
%% toroco_live_bridge
%%====================================================================

%% @doc The hub, listening on `foxglove' (0 for any free port) of `Opts'
%% (SPEC §11's keys). Whether clients may publish is the app env
%% `client_publish' (default `false').
-spec init(map()) -> {ok, toroco_live_bridge:spec(), #fox{}}.
init(Opts) ->
    Publish = maps:get(client_publish, Opts,
                       application:get_env(toroco_live, client_publish, false)) =:= true,
    Session = integer_to_binary(erlang:system_time(millisecond)),
    Serve = fun(Req) -> toroco_live_foxglove_conn:serve(Req, ?SUBPROTOCOL,
                                                         #{client_publish => Publish,
                                                           session => Session}) end,
    %% The wiring is read again every ?REFRESH_MS while clients are
    %% connected (refresh/1 does nothing without them).
    erlang:send_after(?REFRESH_MS, self(), refresh),
    {ok, #{listener => ?LISTENER, serve => Serve, conn_queue => ?CONN_QUEUE,
           tap => #{buffer => ?TAP_BUFFER, retry_ms => ?REFRESH_MS, world => true,
                    who => <<"Foxglove bridge">>}}, #fox{}}.

-spec handle_join(pid(), toroco_live_bridge:hub()) -> {term(), toroco_live_bridge:hub()}.
handle_join(_Conn, H0) ->
    %% read before it joins: the reply carries every channel
    H = refresh(H0, true),
    F = toroco_live_bridge:state(H),
    {{ok, channels(F, all_keys(F)), toroco_rec_channels:graph(F#fox.wiring)}, H}.

-spec handle_world(map() | none, toroco_live_bridge:hub()) -> toroco_live_bridge:hub().
handle_world(Snapshot, H) ->
    F = toroco_live_bridge:state(H),
    {Msgs, Scene} = toroco_rec_channels:world(Snapshot, erlang:system_time(nanosecond),
                                               F#fox.scene),
    Keys = [K || {K, _, _} <- Msgs],
    H1 = case F#fox.world of
             [] -> advertise(set(F#fox{world = Keys, scene = Scene}, H), Keys);
             _ -> set(F#fox{scene = Scene}, H)
         end,
    lists:foldl(fun deliver/2, H1, Msgs).

-spec handle_event(tuple() | retapped, toroco_live_bridge:hub()) -> toroco_live_bridge:hub().
handle_event(retapped, H) ->
    refresh(H);
handle_event(Event = {lifecycle, _, _, _}, H) ->
    send_event(Event, refresh(H));
handle_event({dropped, N}, H) ->
    ok = toroco_live_bridge:broadcast(dropped(N), H),
    H;
handle_event(Event, H) ->
    send_event(Event, H).

-spec handle_down(pid(), toroco_live_bridge:hub()) -> toroco_live_bridge:hub().
handle_down(_Conn, H) -> H.

-spec handle_call(term(), gen_server:from(), toroco_live_bridge:hub()) ->
          {reply, term(), toroco_live_bridge:hub()}.
handle_call(_, _From, H) -> {reply, {error, unknown_call}, H}.

-spec handle_cast(term(), toroco_live_bridge:hub()) -> toroco_live_bridge:hub().
handle_cast(_, H) -> H.

-spec handle_info(term(), toroco_live_bridge:hub()) -> toroco_live_bridge:hub().
handle_info(refresh, H) ->
    erlang:send_after(?REFRESH_MS, self(), refresh),
    refresh(H);
handle_info(_, H) ->
    H.

-spec stats(toroco_live_bridge:hub()) -> map().
stats(_H) -> #{}.

-spec dropped(pos_integer()) -> term().
dropped(N) -> {fox, dropped, N}.

%%====================================================================
%% Inside
%%====================================================================

set(F, H) -> toroco_live_bridge:set_state(F, H).

%% An event's JSON is made only when a client subscribed to its channel.
send_event(Event, H) ->
    case toroco_rec_channels:event_key(Event) of
        none -> H;
        Key ->
            H1 = case maps:is_key(Key, (toroco_live_bridge:state(H))#fox.ids) of
                     true -> H;
                     false -> refresh(H)
                 end,
            Id = maps:get(Key, (toroco_live_bridge:state(H1))#fox.ids, none),
            case toroco_live_bridge:subscribed(Id, H1) of
                false -> H1;
                true -> deliver(toroco_rec_channels:of_event(Event), H1)
            end
    end.

deliver({Key, T, Json}, H) ->
    case toroco_live_bridge:state(H) of
        #fox{ids = #{Key := Id}} ->
            lists:foldl(fun(C, Acc) ->
                                element(2, toroco_live_bridge:send(C, {fox, message, Id, T, Json}, Acc))
                        end, H, toroco_live_bridge:subscribers(Id, H));
        #fox{} -> H
    end.

refresh(H) ->
    refresh(H, false).

%% Nobody to tell: the wiring is read when the next client joins.
refresh(H, Joining) ->
    case toroco_live_clients:pids(toroco_live_bridge:clients(H)) of
        [] when not Joining -> H;
        Conns -> refresh(H, toroco_live_bridge:state(H), Conns)
    end.

refresh(H, F = #fox{wiring = Old}, Conns) ->
    New = try toroco_rec_channels:from_wiring()
          catch _:_ -> Old
          end,
    #{keys := OldKeys} = Old,
    #{keys := NewKeys} = New,
    Gone = OldKeys -- NewKeys,
    H1 = advertise(set(F#fox{wiring = New}, H), NewKeys -- OldKeys),
    GoneIds = [maps:get(K, (toroco_live_bridge:state(H1))#fox.ids) || K <- Gone],
    _ = [C ! {fox, unadvertise, GoneIds} || GoneIds =/= [], C <- Conns],
    New =:= Old orelse
        [C ! {fox, graph, toroco_rec_channels:graph(New)} || C <- Conns],
    Cl = toroco_live_clients:forget(GoneIds, toroco_live_bridge:clients(H1)),
    toroco_live_bridge:set_clients(Cl, H1).

advertise(H, []) -> H;
advertise(H, Keys) ->
    F = lists:foldl(fun(K, Acc = #fox{ids = Ids, next_id = N}) ->
                            case Ids of
                                #{K := _} -> Acc;
                                #{} -> Acc#fox{ids = Ids#{K => N}, next_id = N + 1}
                            end
                    end, toroco_live_bridge:state(H), Keys),
    ok = toroco_live_bridge:broadcast({fox, advertise, channels(F, Keys)}, H),
    set(F, H).

all_keys(#fox{wiring = #{keys := Keys}, world = World}) -> Keys ++ World.

channels(#fox{ids = Ids}, Keys) ->
    [begin
         {Name, Schema} = toroco_rec_channels:schema(K),
         #{id => maps:get(K, Ids), key => K, topic => toroco_rec_channels:topic(K),
           schema_name => Name, schema => Schema}
     end || K <- Keys, maps:is_key(K, Ids)].
