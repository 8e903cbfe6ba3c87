%% @doc The dashboard's hub: the one subscriber of the observer tap (SPEC
%% §10) on behalf of every page, and the one place the pages' state is
%% built. Each WebSocket client's sender process joins it.
%%
%% It counts the tap's events per source (emitted) and per input
%% (delivered) for the events-per-second of each wire and for `/metrics'.
%% While a client is connected it keeps a reading of the runtime
%% (`toroco_live_state:readings/0'), taken at most once a second for what
%% the tap's events do not carry (the wiring's shape, mailboxes, states,
%% device counters), and brought up to date between readings by the events
%% themselves (`toroco_live_state:patch/2': winners, holds, latches, last
%% values, status, restarts). At most every 50 ms, when something changed
%% (and each second, so hold times count down), it encodes the page's
%% state once and pushes the same binary to every client. With no client
%% it reads nothing.
%%
%% A slow browser never slows the robot: each client has at most one frame
%% in flight (pushed, not yet acknowledged by its sender with {@link
%% ack/1}); what comes meanwhile is coalesced (the client gets the latest
%% state when it acknowledges) and counted as skipped. The tap itself
%% drops past its buffer and says how many; those are counted too.
%%
%% Messages (the sender side is `toroco_live_ws'):
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th></tr>
%% <tr><td>{@link join/1} (call)</td><td>sender → hub</td>
%%     <td>a client connected; `{ok, Hello}' or `{error, too_many_clients}'</td></tr>
%% <tr><td>`{toroco_live_hub, frames, [Json]}'</td><td>hub → sender</td>
%%     <td>new state for its client; one at a time</td></tr>
%% <tr><td>{@link ack/1} (cast)</td><td>sender → hub</td>
%%     <td>the frames went out on the socket</td></tr>
%% </table>
-module(toroco_live_hub).
-behaviour(gen_server).

-export([start_link/1, join/1, ack/1, stats/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-define(TICK_MS, 50).
-define(RATE_MS, 1000).
%% The runtime is read at most this often.
-define(READ_MS, 1000).
%% The arena is redrawn at most this often (its frame carries the trajectories).
-define(WORLD_MS, 100).
-define(TAP_BUFFER, 10000).

-record(client, {mref :: reference(), busy = false :: boolean(),
                 seen = {0, 0} :: {non_neg_integer(), non_neg_integer()},
                 pending = false :: boolean(), skipped = 0 :: non_neg_integer()}).

-record(h, {max_clients :: pos_integer(),
            clients = #{} :: #{pid() => #client{}},
            %% when the runtime restarts, the hub subscribes again
            tap :: toroco_rec_tap:tap(),
            emits = #{} :: #{{atom(), atom()} => non_neg_integer()},
            delivers = #{} :: #{{atom(), atom()} => non_neg_integer()},
            window = {#{}, #{}} :: {map(), map()},
            rates = #{emits => #{}, delivers => #{}} :: toroco_live_state:rates(),
            last_rate :: integer(),
            %% the runtime as last read, kept up to date by the events, and
            %% when it was read (monotonic ms)
            reading = none :: toroco_live_state:reading() | none,
            %% the events since the page was last built: the latest per
            %% input, delivery and output, every lifecycle event (newest
            %% first)
            latest = #{} :: #{term() => tuple()},
            lifecycle = [] :: [tuple()],
            read_error = not_running :: term(),
            read_at = 0 :: integer(),
            dirty = true :: boolean(),
            world_dirty = false :: boolean(),
            state = none :: binary() | none,
            world = none :: binary() | none,
            %% How many state and world frames were built: a client is sent
            %% only what it has not seen.
            versions = {0, 0} :: {non_neg_integer(), non_neg_integer()},
            last_world :: integer(),
            tap_dropped = 0 :: non_neg_integer(),
            skipped = 0 :: non_neg_integer(),
            pushed = 0 :: non_neg_integer()}).

%%====================================================================
%% API
%%====================================================================

-spec start_link(map()) -> {ok, pid()} | {error, term()}.
start_link(Config) ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, Config, []).

%% @doc The calling process becomes a client: it will get `{toroco_live_hub,
%% frames, [Json]}' and must {@link ack/1} each. `Hello' is the first frame
%% to send. Refused past `max_clients'.
-spec join(pid()) -> {ok, binary()} | {error, too_many_clients | not_running}.
join(Pid) ->
    try gen_server:call(?MODULE, {join, Pid})
    catch exit:{noproc, _} -> {error, not_running}
    end.

%% @doc The frames pushed to `Pid' went out.
-spec ack(pid()) -> ok.
ack(Pid) ->
    gen_server:cast(?MODULE, {ack, Pid}).

%% @doc Counters for `/metrics': events per source and per input since the
%% dashboard started, clients, frames pushed and skipped, tap drops.
-spec stats() -> map().
stats() ->
    try gen_server:call(?MODULE, stats)
    catch exit:{noproc, _} -> #{}
    end.

%%====================================================================
%% gen_server
%%====================================================================

-spec init(map()) -> {ok, #h{}}.
init(Config) ->
    %% The robot first: under load the hub waits (the tap drops, and counts).
    process_flag(priority, low),
    ok = toroco_live_world:subscribe(),
    erlang:send_after(?TICK_MS, self(), tick),
    Now = erlang:monotonic_time(millisecond),
    {_, Tap} = toroco_rec_tap:on(toroco_rec_tap:new(#{buffer => ?TAP_BUFFER, retry_ms => ?TICK_MS})),
    {ok, #h{max_clients = maps:get(max_clients, Config, 64), tap = Tap,
            last_rate = Now, last_world = Now - ?WORLD_MS}}.

-spec handle_call(term(), gen_server:from(), #h{}) -> {reply, term(), #h{}}.
handle_call({join, Pid}, _From, H = #h{clients = Cs, max_clients = Max}) ->
    case map_size(Cs) >= Max of
        true ->
            {reply, {error, too_many_clients}, H};
        false ->
            C = #client{mref = monitor(process, Pid)},
            Hello = toroco_rec_json:encode(#{<<"type">> => <<"hello">>,
                                              <<"node">> => toroco_rec_json:value(node()),
                                              <<"clients">> => map_size(Cs) + 1}),
            %% The newcomer gets the latest state at once, not at the next change.
            H1 = H#h{clients = Cs#{Pid => C}, dirty = true, world_dirty = true},
            {reply, {ok, Hello}, H1}
    end;
handle_call(stats, _From, H) ->
    {reply, #{emits => H#h.emits, delivers => H#h.delivers, clients => map_size(H#h.clients),
              skipped => H#h.skipped + lists:sum([C#client.skipped || C <- maps:values(H#h.clients)]),
              pushed => H#h.pushed, tap_dropped => H#h.tap_dropped,
              tap => toroco_rec_tap:subscribed(H#h.tap)}, H};
handle_call(_Request, _From, H) ->
    {reply, {error, unknown_call}, H}.

-spec handle_cast(term(), #h{}) -> {noreply, #h{}}.
handle_cast({ack, Pid}, H = #h{clients = Cs}) ->
    case Cs of
        #{Pid := C = #client{pending = true}} ->
            {noreply, send(Pid, C#client{pending = false}, H)};
        #{Pid := C} ->
            {noreply, H#h{clients = Cs#{Pid := C#client{busy = false}}}};
        #{} ->
            {noreply, H}
    end;
handle_cast(_Msg, H) ->
    {noreply, H}.

-spec handle_info(term(), #h{}) -> {noreply, #h{}}.
handle_info({toroco_live_world, changed}, H) ->
    {noreply, H#h{world_dirty = true}};
handle_info(tick, H) ->
    erlang:send_after(?TICK_MS, self(), tick),
    {noreply, tick(H)};
handle_info({'DOWN', MRef, process, Pid, _} = Down, H = #h{clients = Cs}) ->
    case Cs of
        #{Pid := #client{mref = MRef, skipped = S}} ->
            {noreply, H#h{clients = maps:remove(Pid, Cs), skipped = H#h.skipped + S}};
        #{} ->
            handle_info_tap(Down, H)
    end;
handle_info(Info, H) ->
    handle_info_tap(Info, H).

handle_info_tap(Info, H = #h{tap = Tap}) ->
    case toroco_rec_tap:handle(Info, Tap) of
        {events, Events} -> {noreply, lists:foldl(fun event/2, H, Events)};
        {down, Tap1} -> {noreply, H#h{tap = Tap1, dirty = true}};
        {retry, Tap1} -> {_, Tap2} = toroco_rec_tap:on(Tap1), {noreply, H#h{tap = Tap2}};
        _ -> {noreply, H}
    end.

-spec terminate(term(), #h{}) -> ok.
terminate(_Reason, #h{tap = Tap}) ->
    _ = toroco_rec_tap:off(Tap),
    ok.

%%====================================================================
%% The tap
%%====================================================================

event({dropped, N}, H = #h{tap_dropped = D}) ->
    H#h{tap_dropped = D + N, dirty = true};
event(Event = {lifecycle, _, _, _}, H = #h{lifecycle = L}) ->
    H#h{lifecycle = [Event | L], dirty = true};
event(Event = {Kind, _T, Key, _}, H = #h{latest = M}) ->
    count(Event, H#h{latest = M#{{Kind, Key} => Event}, dirty = true});
event(Event = {emit, _T, Src, _, _}, H = #h{latest = M}) ->
    count(Event, H#h{latest = M#{{emit, Src} => Event}, dirty = true});
event(_Event, H) ->
    H.

count({emit, _T, Src, _Kind, _V}, H = #h{emits = E}) ->
    H#h{emits = bump(Src, E)};
count({deliver, _T, In, _V}, H = #h{delivers = D}) ->
    H#h{delivers = bump(In, D)};
count(_Router_or_lifecycle, H) ->
    H.

bump(Key, Map) ->
    maps:update_with(Key, fun(N) -> N + 1 end, 1, Map).

%%====================================================================
%% Pushing
%%====================================================================

tick(H0) ->
    H = rates(H0),
    case map_size(H#h.clients) of
        0 ->
            %% No page: nothing kept; the next one starts from a reading.
            H#h{reading = none, latest = #{}, lifecycle = []};
        _ ->
            {Vs, Vw} = H#h.versions,
            H1 = case H#h.dirty orelse not toroco_rec_tap:subscribed(H#h.tap) of
                     true ->
                         Hr = patched(read(H)),
                         Hr#h{state = state_frame(Hr), dirty = false, versions = {Vs + 1, Vw}};
                     false -> H
                 end,
            Now = erlang:monotonic_time(millisecond),
            H2 = case H1#h.world_dirty andalso Now - H1#h.last_world >= ?WORLD_MS of
                     true -> H1#h{world = world_frame(), world_dirty = false, last_world = Now,
                                  versions = {element(1, H1#h.versions), Vw + 1}};
                     false -> H1
                 end,
            case H2#h.versions =/= H#h.versions of
                true -> push_all(H2);
                false -> H2
            end
    end.

%% Events per second over the last whole second; each second the page is
%% redrawn, so hold times count down even when nothing else happens.
rates(H = #h{last_rate = Last, emits = E, delivers = D, window = {E0, D0}}) ->
    Now = erlang:monotonic_time(millisecond),
    case Now - Last >= ?RATE_MS of
        true ->
            Secs = (Now - Last) / 1000,
            Rate = fun(Counts, Before) ->
                           maps:map(fun(K, N) -> round((N - maps:get(K, Before, 0)) / Secs) end,
                                    Counts)
                   end,
            H#h{last_rate = Now, window = {E, D}, dirty = true,
                rates = #{emits => Rate(E, E0), delivers => Rate(D, D0)}};
        false ->
            H
    end.

%% The events since the last page brought into the reading.
patched(H = #h{reading = none}) ->
    H#h{latest = #{}, lifecycle = []};
patched(H = #h{reading = R, latest = M, lifecycle = L}) ->
    Patch = fun toroco_live_state:patch/2,
    R1 = lists:foldl(Patch, lists:foldl(Patch, R, lists:reverse(L)), maps:values(M)),
    H#h{reading = R1, latest = #{}, lifecycle = []}.

%% The runtime read again if the reading is a second old (or there is none,
%% or no tap keeps it up to date); the events kept so far are in it.
read(H = #h{reading = R, read_at = At, tap = Tap}) ->
    Now = erlang:monotonic_time(millisecond),
    case R =:= none orelse Now - At >= ?READ_MS orelse not toroco_rec_tap:subscribed(Tap) of
        true ->
            try toroco_live_state:readings() of
                R1 -> H#h{reading = R1, read_at = Now, latest = #{}, lifecycle = []}
            catch
                exit:Why -> H#h{reading = none, read_error = Why}
            end;
        false ->
            H
    end.

state_frame(#h{reading = none, read_error = Why}) ->
    not_running(Why);
state_frame(#h{rates = Rates, clients = Cs, skipped = S, tap_dropped = Dropped, tap = Tap,
               reading = R}) ->
    try toroco_live_state:page(Rates, R) of
        Page ->
            Skipped = S + lists:sum([C#client.skipped || C <- maps:values(Cs)]),
            toroco_rec_json:encode(Page#{<<"dashboard">> =>
                                              #{<<"clients">> => map_size(Cs),
                                                <<"skipped">> => Skipped,
                                                <<"tap">> => toroco_rec_tap:subscribed(Tap),
                                                <<"tap_dropped">> => Dropped}})
    catch
        exit:Why -> not_running(Why)
    end.

%% The runtime is not running (or restarting): say so.
not_running(Why) ->
    toroco_rec_json:encode(#{<<"type">> => <<"state">>, <<"nodes">> => [], <<"layers">> => [],
                              <<"error">> => toroco_rec_json:term_text(Why)}).

world_frame() ->
    case toroco_live_world:latest() of
        none -> none;
        Snapshot -> toroco_rec_json:encode(toroco_live_world_json:frame(Snapshot))
    end.

push_all(H = #h{clients = Cs}) ->
    maps:fold(fun(Pid, C = #client{busy = true, skipped = S}, Acc) ->
                      Acc#h{clients = (Acc#h.clients)#{Pid := C#client{pending = true,
                                                                        skipped = S + 1}}};
                 (Pid, C, Acc) ->
                      send(Pid, C, Acc)
              end, H, Cs).

send(Pid, C = #client{seen = {Ss, Sw}}, H = #h{versions = {Vs, Vw} = V, clients = Cs,
                                                 pushed = P}) ->
    Frames = [F || {F, New} <- [{H#h.state, Vs > Ss}, {H#h.world, Vw > Sw}], New, F =/= none],
    case Frames of
        [] ->
            H#h{clients = Cs#{Pid => C#client{busy = false, seen = V}}};
        _ ->
            Pid ! {?MODULE, frames, Frames},
            H#h{clients = Cs#{Pid => C#client{busy = true, seen = V}}, pushed = P + 1}
    end.
