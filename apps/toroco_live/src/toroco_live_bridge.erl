%% @doc The bridges (API, a behaviour): a WebSocket server beside the
%% dashboard that shows the robot to another kind of client, on a port of
%% its own chosen by an option of `toroco_live:start/1'. `toroco_live''s
%% own is the Foxglove bridge (`toroco_live_foxglove', option `foxglove',
%% SPEC §12); `toroco_ros' adds the rosbridge server (`toroco_ros_server',
%% option `rosbridge', SPEC §15). This module is what they share, written
%% once: the hub process, and its place in the tree.
%%
%% <b>The tree.</b> A bridge's hub is a static child of its own
%% application's supervisor ({@link child_spec/2}), registered under its
%% callback module's name: it runs while the dashboard runs and its option
%% is a port, and is a child with no process otherwise ({@link
%% start_link/2} answers `ignore'). `toroco_live:start/1' sets the
%% configuration and restarts each bridge's child ({@link open/1}) so that
%% it reads it; `toroco_live:stop/0' terminates them ({@link close/1}). A
%% bridge of another application is added with
%% `toroco_live_extensions:add(bridge, Option, #{supervisor => Sup, id =>
%% Module, listener => Listener})' once that supervisor runs.
%%
%% <b>The hub</b> (a `gen_server' run by this module) owns the listener
%% (`toroco_live_listener', the dashboard's bounds), the clients, their
%% subscriptions and per-client bounds, and the observer tap taken while
%% someone is connected (`toroco_live_clients'), and the world's
%% notifications. The callback module says what the clients are shown.
%%
%% Messages between a connection and any hub, built and matched only here:
%% | from | to  | message                     | when                        | answer |
%% |------|-----|-----------------------------|-----------------------------|--------|
%% | conn | hub | `{join, Conn}' (call)        | after the handshake         | `Module:handle_join/2''s (it is a client after) |
%% | conn | hub | `{subscribe, Conn, [Key]}'   | the client subscribed       | none |
%% | conn | hub | `{unsubscribe, Conn, [Key]}' | the client unsubscribed     | none |
%% | any  | hub | `port', `stats' (calls)      | `toroco_live:info/0', `/metrics' | the port, the counters |
%% The hub's own messages to its connections are the callback module's
%% (its protocol table); {@link send/3} bounds them per connection: one
%% whose mailbox holds more than the module's `conn_queue' gets no more
%% until it drains, and hears how many it missed (`Module:dropped/1').
%%
%% Callbacks: `init/1' (what to listen with, the tap's options, the
%% module's state), `handle_join/2', `handle_event/2' (each tap event,
%% `{dropped, N}' among them, and `retapped'), `handle_world/2',
%% `handle_down/2', `handle_call/3', `handle_cast/2', `handle_info/2',
%% `stats/1', `dropped/1'. Each takes and returns the hub (`hub()'), whose
%% parts the functions below read and change.
-module(toroco_live_bridge).
-behaviour(gen_server).

-export([child_spec/2, start_link/2, bridges/0, open/1, close/1]).
-export([port/1, stats/1, join/1, subscribe/3, unsubscribe/3]).
-export([state/1, set_state/2, clients/1, set_clients/2, subscribed/2, subscribers/2, send/3,
         broadcast/2]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([bridge/0, hub/0, spec/0]).

-type bridge() :: #{supervisor := atom(), id := module(), listener := atom()}.
%% What a hub listens with: its listener's name, the mochiweb loop of a
%% connection, the tap's options (`toroco_rec_tap:new/1'), the most
%% messages a connection may have waiting.
-type spec() :: #{listener := atom(), serve := fun((term()) -> term()),
                  tap := toroco_rec_tap:opts(), conn_queue := pos_integer()}.

-record(hub, {module :: module(),
              listener :: pid(),
              port :: inet:port_number(),
              conn_queue :: pos_integer(),
              clients :: toroco_live_clients:clients(),
              state :: term()}).
-opaque hub() :: #hub{}.

-callback init(Config :: map()) -> {ok, spec(), State :: term()}.
-callback handle_join(Conn :: pid(), hub()) -> {Reply :: term(), hub()}.
-callback handle_event(Event :: tuple() | retapped, hub()) -> hub().
-callback handle_world(Snapshot :: map() | none, hub()) -> hub().
-callback handle_down(Conn :: pid(), hub()) -> hub().
-callback handle_call(Request :: term(), gen_server:from(), hub()) -> {reply, term(), hub()}.
-callback handle_cast(Msg :: term(), hub()) -> hub().
-callback handle_info(Info :: term(), hub()) -> hub().
-callback stats(hub()) -> map().
-callback dropped(N :: pos_integer()) -> term().

%% How long a connection's join may wait for a busy hub.
-define(JOIN_MS, 15000).

%%====================================================================
%% The tree
%%====================================================================

%% @doc The static child of bridge `Module' for option `Option'.
-spec child_spec(atom(), module()) -> supervisor:child_spec().
child_spec(Option, Module) ->
    #{id => Module, start => {?MODULE, start_link, [Option, Module]}, restart => permanent}.

%% @doc Starts the hub when the dashboard runs, the bridge was added and
%% its option is a port; `ignore' otherwise.
-spec start_link(atom(), module()) -> {ok, pid()} | ignore | {error, term()}.
start_link(Option, Module) ->
    case {toroco_live_config:current(), lists:keymember(Option, 1, bridges())} of
        {#{Option := Port} = Config, true} when is_integer(Port) ->
            %% No secret in a start argument (nor in a crash report). Behind
            %% a busy CPU its heap grows with the events it holds; the old
            %% heap is swept often so that it shrinks back.
            Args = {Module, Port, maps:without([token, session_key], Config)},
            gen_server:start_link({local, Module}, ?MODULE, Args,
                                  [{spawn_opt, [{fullsweep_after, 10}]}]);
        _ ->
            ignore
    end.

%% @doc Every bridge, by option: the Foxglove bridge and those added.
-spec bridges() -> [{atom(), bridge()}].
bridges() ->
    [{foxglove, #{supervisor => toroco_live_sup, id => toroco_live_foxglove,
                  listener => toroco_live_foxglove_listener}}
     | toroco_live_extensions:all(bridge)].

%% @doc (Re)starts the bridge of `Option' with the configuration now: the
%% port it listens on, `off' when it does not run.
-spec open(atom()) -> {ok, inet:port_number() | off} | {error, term()}.
open(Option) ->
    case lists:keyfind(Option, 1, bridges()) of
        {_, #{supervisor := Sup, id := Id} = Bridge} ->
            ok = close(Bridge),
            try supervisor:restart_child(Sup, Id) of
                {ok, _} -> {ok, port(Id)};
                {ok, _, _} -> {ok, port(Id)};
                %% the supervisor adds the child: the reason is enough
                {error, {Reason, Child}} when element(1, Child) =:= child -> {error, Reason};
                {error, Reason} -> {error, Reason}
            catch
                %% its application went without taking it away: not running
                exit:{noproc, _} -> {ok, off}
            end;
        false ->
            {ok, off}
    end.

%% @doc Stops a bridge's hub (its child stays, without a process).
-spec close(bridge()) -> ok.
close(#{supervisor := Sup, id := Id}) ->
    try supervisor:terminate_child(Sup, Id) of
        _ -> ok
    catch exit:_ -> ok
    end.

%%====================================================================
%% Asking a hub
%%====================================================================

%% @doc The port hub `Name' listens on, `off' when it does not run.
-spec port(module()) -> inet:port_number() | off.
port(Name) ->
    try gen_server:call(Name, port)
    catch exit:_ -> off
    end.

%% @doc Hub `Name''s counters (`/metrics'): `clients' and `subscriptions'
%% now, and its module's; empty when it does not run.
-spec stats(module()) -> map().
stats(Name) ->
    try gen_server:call(Name, stats, 10000)
    catch exit:_ -> #{}
    end.

%% @doc The calling connection joins hub `Name'.
-spec join(module()) -> term() | {error, bridge_down}.
join(Name) ->
    try gen_server:call(Name, {join, self()}, ?JOIN_MS)
    catch exit:_ -> {error, bridge_down}
    end.

-spec subscribe(module(), pid(), [term()]) -> ok.
subscribe(Name, Conn, Keys) -> gen_server:cast(Name, {subscribe, Conn, Keys}).

-spec unsubscribe(module(), pid(), [term()]) -> ok.
unsubscribe(Name, Conn, Keys) -> gen_server:cast(Name, {unsubscribe, Conn, Keys}).

%%====================================================================
%% The hub's parts, for its callbacks
%%====================================================================

-spec state(hub()) -> term().
state(#hub{state = S}) -> S.

-spec set_state(term(), hub()) -> hub().
set_state(S, H) -> H#hub{state = S}.

-spec clients(hub()) -> toroco_live_clients:clients().
clients(#hub{clients = Cl}) -> Cl.

-spec set_clients(toroco_live_clients:clients(), hub()) -> hub().
set_clients(Cl, H) -> H#hub{clients = Cl}.

-spec subscribed(term(), hub()) -> boolean().
subscribed(Key, #hub{clients = Cl}) -> toroco_live_clients:subscribed(Key, Cl).

-spec subscribers(term(), hub()) -> [pid()].
subscribers(Key, #hub{clients = Cl}) -> toroco_live_clients:subscribers(Key, Cl).

%% @doc `Msg' to connection `Conn', bounded: `dropped' when it is behind by
%% more than `conn_queue' messages (it hears how many it missed once it
%% has caught up), `gone' when it is no more.
-spec send(pid(), term(), hub()) -> {sent | dropped | gone, hub()}.
send(Conn, Msg, H = #hub{module = M, conn_queue = Max, clients = Cl}) ->
    {What, Cl1} = toroco_live_clients:offer(Conn, Msg, fun M:dropped/1, Max, Cl),
    {What, H#hub{clients = Cl1}}.

%% @doc `Msg' to every connection, unbounded: for the rare messages.
-spec broadcast(term(), hub()) -> ok.
broadcast(Msg, #hub{clients = Cl}) -> toroco_live_clients:broadcast(Msg, Cl).

%%====================================================================
%% gen_server
%%====================================================================

-spec init({module(), inet:port_number(), map()}) -> {ok, hub()} | {stop, term()}.
init({Module, Port, Config}) ->
    process_flag(trap_exit, true),
    {ok, #{listener := Name, serve := Serve, tap := Tap, conn_queue := Max}, State} =
        Module:init(Config),
    case toroco_live_listener:start_link(Name, Config, Port, Serve) of
        {ok, Listener} ->
            {ok, #hub{module = Module, listener = Listener, conn_queue = Max, state = State,
                      port = toroco_live_listener:port(Listener),
                      clients = toroco_live_clients:new(Tap)}};
        {error, Why} ->
            {stop, {listen, Why}}
    end.

-spec handle_call(term(), gen_server:from(), hub()) -> {reply, term(), hub()}.
handle_call(port, _From, H) ->
    {reply, H#hub.port, H};
handle_call(stats, _From, H = #hub{module = M, clients = Cl}) ->
    {reply, (M:stats(H))#{clients => toroco_live_clients:size(Cl),
                          subscriptions => toroco_live_clients:subscriptions(Cl)}, H};
handle_call({join, Conn}, _From, H = #hub{module = M}) ->
    %% its reply first (read before it joins), then it is a client
    {Reply, H1 = #hub{clients = Cl}} = M:handle_join(Conn, H),
    {reply, Reply, H1#hub{clients = toroco_live_clients:join(Conn, Cl)}};
handle_call(Request, From, H = #hub{module = M}) ->
    M:handle_call(Request, From, H).

-spec handle_cast(term(), hub()) -> {noreply, hub()}.
handle_cast({subscribe, Conn, Keys}, H = #hub{clients = Cl}) ->
    case toroco_live_clients:member(Conn, Cl) of
        true -> {noreply, H#hub{clients = toroco_live_clients:subscribe(Conn, Keys, Cl)}};
        false -> {noreply, H}
    end;
handle_cast({unsubscribe, Conn, Keys}, H = #hub{clients = Cl}) ->
    {noreply, H#hub{clients = toroco_live_clients:unsubscribe(Conn, Keys, Cl)}};
handle_cast(Msg, H = #hub{module = M}) ->
    {noreply, M:handle_cast(Msg, H)}.

-spec handle_info(term(), hub()) -> {noreply, hub()} | {stop, term(), hub()}.
handle_info({toroco_live_world, changed}, H = #hub{module = M}) ->
    %% Reading re-arms the notification: read even with nobody watching.
    {noreply, M:handle_world(toroco_live_world:latest(), H)};
handle_info({'EXIT', L, Why}, H = #hub{listener = L}) ->
    {stop, {listener, Why}, H};
handle_info(Info, H = #hub{module = M, clients = Cl}) ->
    case toroco_live_clients:handle(Info, Cl) of
        {events, Events} -> {noreply, lists:foldl(fun M:handle_event/2, H, Events)};
        {retapped, Cl1} -> {noreply, M:handle_event(retapped, H#hub{clients = Cl1})};
        {down, Conn, Cl1} -> {noreply, M:handle_down(Conn, H#hub{clients = Cl1})};
        {ok, Cl1} -> {noreply, H#hub{clients = Cl1}};
        ignore -> {noreply, M:handle_info(Info, H)}
    end.

-spec terminate(term(), hub()) -> ok.
terminate(_, H = #hub{module = M, listener = L, clients = Cl}) ->
    %% What was emitted before the stop goes to the clients first.
    _ = (catch lists:foldl(fun M:handle_event/2, H, toroco_live_clients:stop(Cl))),
    toroco_live_listener:stop(L).
