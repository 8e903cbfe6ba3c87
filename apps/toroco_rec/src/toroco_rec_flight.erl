%% @doc The recorders' process: the flight recorder (SPEC §12), always on,
%% and the recording when one is asked for (`toroco_rec_recorder').
%%
%% The flight recorder keeps the last `flight_seconds' (app env, default
%% 30) of the robot's events in memory and writes them as MCAP on demand
%% (`toroco_rec:dump/1', `toroco_live:dump/1') and by itself, into the log
%% directory, when a layer is taken out (the lifecycle event `{layer_removed, L}'): the log
%% line names the file. Events are kept as they came, their JSON made only
%% for a dump: the newest in a small open batch, the rest as segments, a
%% batch of about a second sealed into one binary
%% (`term_to_binary(Batch, [{compressed, 1}])'), off the process's heap and
%% decoded only for a dump. The process hibernates after sealing a
%% segment, so its heap holds about one batch.
%%
%% One tap subscription (SPEC §10) serves the flight recorder and the
%% recording, and the process runs at low priority: the robot first. Memory
%% is bounded by time (segments older than the window go as new events
%% come), by count (`flight_max_events', default 200000, the oldest event
%% first) and by size (`flight_max_bytes', default 32 MiB: the segments'
%% compressed bytes and the open batch's terms as `erlang:external_size/1'
%% counts them, the oldest segment first), and by the tap's buffer for what
%% waits in the mailbox; what the tap drops is counted, said in a dump's
%% log line and in a recording's result. {@link window/0} says what is
%% kept.
%%
%% The simulated world's snapshots come from `toroco_rec_world''s source
%% (`toroco_live_world' while `toroco_live' runs), to which it subscribes
%% when it starts and whenever a source is set.
%%
%% The app env keys (`flight_seconds', `flight_max_events',
%% `flight_max_bytes', `log_dir') are read from `toroco_rec', else from
%% `toroco_live' (SPEC §12 names `flight_seconds' there), else the
%% defaults; the log directory's default is `log' in the node's working
%% directory (the release's log directory when run from a release root).
-module(toroco_rec_flight).
-behaviour(gen_server).

-export([start_link/0, dump/1, record/2, stop_recording/0, window/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-define(MAX_EVENTS, 200000).
-define(MAX_BYTES, 32 * 1024 * 1024).
-define(BUFFER, 20000).
%% The open batch is sealed into a compressed segment when it spans this
%% long (event time), holds this many events, or holds this share of
%% `flight_max_bytes' (so the bytes bound drops a slice at a time).
-define(SEGMENT_NS, 1000000000).
-define(SEGMENT_EVENTS, 1000).
-define(SEGMENTS_IN_BYTES, 16).
%% zlib's fastest level: on 1000 of the chain's events 3.4 times faster
%% than the default level (6) for 9 % more bytes (0.9 against 3.0 ms a
%% segment here), the recorder's largest cost per event at level 6.
-define(SEGMENT_ZLIB, 1).
%% How soon to subscribe again when the runtime's tap went away.
-define(RESUBSCRIBE_MS, 500).

-type item() :: {event, tuple()} | {message, toroco_rec_channels:key(), binary()}.

-record(flight, {%% when the runtime restarts, this process subscribes again
                 tap :: toroco_rec_tap:tap(),
                 %% The window: sealed segments, oldest first, each
                 %% {FirstT, LastT, Count, Bin} where Bin is the batch's
                 %% [{T, item()}] compressed and Count its last events
                 %% still kept; then the open batch, newest first, with
                 %% each event's uncompressed size.
                 segments = queue:new() :: queue:queue({integer(), integer(), pos_integer(), binary()}),
                 batch = [] :: [{integer(), non_neg_integer(), item()}],
                 batch_n = 0 :: non_neg_integer(),
                 batch_first = 0 :: integer(),
                 batch_bytes = 0 :: non_neg_integer(),
                 newest = 0 :: integer(),
                 hibernate = false :: boolean(),
                 %% Events kept, and bytes: the segments' compressed
                 %% bytes and the batch's uncompressed ones.
                 count = 0 :: non_neg_integer(),
                 bytes = 0 :: non_neg_integer(),
                 max_bytes :: pos_integer(),
                 dropped = 0 :: non_neg_integer(),
                 window_ns :: pos_integer(),
                 max :: pos_integer(),
                 recording = none :: none | toroco_rec_recorder:recording(),
                 %% the world's snapshots' source (toroco_rec_world)
                 world = none :: module() | none,
                 scene = none :: toroco_rec_channels:scene_sent()}).

%% Every garbage collection a full sweep: the heap holds the state and the
%% open batch, and what an event leaves behind is not kept in an old heap
%% until the next seal (with the Torobot, about 150 kB on average instead
%% of 400).
-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], [{spawn_opt, [{fullsweep_after, 0}]}]).

%% @doc Writes the last seconds to `Path' as MCAP.
-spec dump(file:filename_all()) -> {ok, #{messages := non_neg_integer(), path := file:filename_all()}}
                                       | {error, term()}.
dump(Path) ->
    gen_server:call(?MODULE, {dump, Path}, 60000).

%% @doc Starts a recording (see `toroco_rec:record/2').
-spec record(file:filename_all(), map()) -> ok | {error, term()}.
record(Path, Opts) ->
    gen_server:call(?MODULE, {record, Path, Opts}, 30000).

%% @doc Ends the recording (see `toroco_rec:stop_recording/0').
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer(),
                                 unencodable => non_neg_integer()}} | {error, term()}.
stop_recording() ->
    gen_server:call(?MODULE, stop_recording, 60000).

%% @doc What the flight recorder holds now: events kept, their bytes
%% (compressed for sealed segments), the segments, what the tap dropped.
-spec window() -> #{events := non_neg_integer(), bytes := non_neg_integer(),
                    segments := non_neg_integer(), dropped := non_neg_integer()}.
window() ->
    gen_server:call(?MODULE, window).

-spec init([]) -> {ok, #flight{}}.
init([]) ->
    process_flag(trap_exit, true),
    process_flag(priority, low),
    %% Events waiting in the mailbox stay out of the heap: a burst the tap
    %% lets through is not copied by each garbage collection.
    process_flag(message_queue_data, off_heap),
    Seconds = env(flight_seconds, 30),
    Max = env(flight_max_events, ?MAX_EVENTS),
    MaxBytes = env(flight_max_bytes, ?MAX_BYTES),
    World = toroco_rec_world:subscribe(subscribe_all),
    {_, Tap} = toroco_rec_tap:on(toroco_rec_tap:new(#{buffer => ?BUFFER,
                                                      retry_ms => ?RESUBSCRIBE_MS})),
    {ok, #flight{tap = Tap, window_ns = Seconds * 1000000000, max = Max, max_bytes = MaxBytes,
                 world = World}}.

env(Key, Default) ->
    case application:get_env(toroco_rec, Key) of
        {ok, Value} -> Value;
        undefined -> application:get_env(toroco_live, Key, Default)
    end.

-spec handle_call(term(), gen_server:from(), #flight{}) -> {reply, term(), #flight{}}.
handle_call({dump, Path}, _From, F0) ->
    F = drain(F0),
    {reply, write(Path, F), F};
handle_call({record, Path, _}, _From, F = #flight{recording = R}) when R =/= none ->
    {reply, {error, {already_recording, toroco_rec_recorder:path(R), Path}}, F};
handle_call({record, Path, Opts}, _From, F = #flight{tap = Tap}) ->
    case toroco_rec_tap:subscribed(Tap) of
        true -> record(Path, Opts, F);
        false -> {reply, {error, no_events}, F}
    end;
handle_call(stop_recording, _From, F = #flight{recording = none}) ->
    {reply, {error, not_recording}, F};
handle_call(stop_recording, _From, F0) ->
    F = #flight{recording = R} = drain(F0),
    {reply, toroco_rec_recorder:close(R), F#flight{recording = none}};
handle_call(window, _From, F = #flight{count = N, bytes = B, segments = Q, dropped = D}) ->
    {reply, #{events => N, bytes => B, segments => queue:len(Q), dropped => D}, F};
handle_call(_, _From, F) ->
    {reply, {error, unknown_call}, F}.

-spec handle_cast(term(), #flight{}) -> {noreply, #flight{}}.
handle_cast({world_source, _}, F) ->
    {noreply, F#flight{world = toroco_rec_world:subscribe(subscribe_all)}};
handle_cast(_, F) ->
    {noreply, F}.

-spec handle_info(term(), #flight{}) -> {noreply, #flight{}} | {noreply, #flight{}, hibernate}.
handle_info({World, changed}, F = #flight{world = World}) when World =/= none ->
    noreply(world(latest(World), erlang:system_time(nanosecond), F));
%% A world in lockstep: every tick's snapshot, stamped with its simulated
%% time as the tap's events are (SPEC §14).
handle_info({World, at, Snapshot = #{t_ms := Ms}}, F = #flight{world = World}) when World =/= none ->
    noreply(world(Snapshot, Ms * 1000000, F));
handle_info(Info, F = #flight{tap = Tap}) ->
    case toroco_rec_tap:handle(Info, Tap) of
        {events, Events} -> noreply(lists:foldl(fun event/2, F, Events));
        {down, Tap1} -> {noreply, F#flight{tap = Tap1}};
        {retry, Tap1} -> {_, Tap2} = toroco_rec_tap:on(Tap1), {noreply, F#flight{tap = Tap2}};
        _ -> {noreply, F}
    end.

%% The source may have gone since it wrote (toroco_live stopped).
latest(World) ->
    try World:latest() catch exit:_ -> none end.

world(Snapshot, Now, F = #flight{recording = R}) ->
    {Msgs, Scene} = toroco_rec_channels:world(Snapshot, Now, F#flight.scene),
    R1 = case R of
             none -> none;
             _ -> toroco_rec_recorder:world(Snapshot, Now, Msgs, R)
         end,
    lists:foldl(fun({K, T, J}, Acc) -> keep({T, {message, K, J}}, Acc) end,
                F#flight{scene = Scene, recording = R1}, Msgs).

-spec terminate(term(), #flight{}) -> ok.
terminate(_, #flight{recording = none}) ->
    ok;
terminate(_, #flight{recording = R}) ->
    _ = toroco_rec_recorder:close(R),
    ok.

%%====================================================================
%% Inside
%%====================================================================

record(Path, Opts, F) ->
    case toroco_rec_recorder:open(Path, Opts) of
        {ok, R} -> {reply, ok, F#flight{recording = R}};
        Err -> {reply, Err, F}
    end.

event({dropped, N}, F = #flight{dropped = D, recording = R}) ->
    F#flight{dropped = D + N, recording = case R of
                                             none -> none;
                                             _ -> toroco_rec_recorder:dropped(N, R)
                                         end};
event(Event, F0 = #flight{recording = R}) ->
    F = case R of
            none -> F0;
            _ -> F0#flight{recording = toroco_rec_recorder:event(Event, R)}
        end,
    F1 = case toroco_rec_channels:event_time(Event) of
             none -> F;
             T -> trim(T, keep({T, {event, Event}}, F))
         end,
    case Event of
        {lifecycle, _, _, {layer_removed, L}} -> layer_removed(L, F1);
        _ -> ok
    end,
    F1.

%% A dump, and stopping a recording, take every event emitted before the
%% call (toroco_rec_tap:flush/1).
drain(F = #flight{tap = T}) ->
    lists:foldl(fun event/2, F, toroco_rec_tap:flush(T)).

%% An event joins the open batch; the batch is sealed into a segment when
%% it spans a second, holds ?SEGMENT_EVENTS events or a slice of the bytes
%% bound. The oldest go first when the count or the bytes would pass their
%% bound: one event at a time for the count, a whole segment for the bytes
%% (its compressed bytes are freed only with it).
keep({T, Item}, F) ->
    Size = erlang:external_size({T, Item}),
    F1 = #flight{batch = B, batch_n = BN, batch_bytes = BB, count = N, bytes = Bytes}
        = make_room(Size, F),
    First = case B of
                [] -> T;
                _ -> F1#flight.batch_first
            end,
    seal_if_full(T, F1#flight{batch = [{T, Size, Item} | B], batch_n = BN + 1, batch_first = First,
                              batch_bytes = BB + Size, count = N + 1, bytes = Bytes + Size,
                              newest = max(T, F1#flight.newest)}).

make_room(Size, F = #flight{count = N, max = Max}) when N > 0, N >= Max ->
    make_room(Size, drop_oldest(F));
make_room(Size, F = #flight{count = N, bytes = B, max_bytes = MaxB}) when N > 0, B + Size > MaxB ->
    make_room(Size, drop_oldest_segment(F));
make_room(_, F) ->
    F.

%% One event: a sealed segment keeps its bytes and counts one event fewer
%% (the first ones of its batch are skipped when it is read).
drop_oldest(F = #flight{segments = Q, count = N, bytes = B}) ->
    case queue:out(Q) of
        {{value, {_, _, 1, Bin}}, Q1} ->
            F#flight{segments = Q1, count = N - 1, bytes = B - byte_size(Bin)};
        {{value, {First, Last, C, Bin}}, Q1} ->
            F#flight{segments = queue:in_r({First, Last, C - 1, Bin}, Q1), count = N - 1};
        {empty, _} ->
            drop_oldest_in_batch(F)
    end.

drop_oldest_segment(F = #flight{segments = Q, count = N, bytes = B}) ->
    case queue:out(Q) of
        {{value, {_, _, C, Bin}}, Q1} ->
            F#flight{segments = Q1, count = N - C, bytes = B - byte_size(Bin)};
        {empty, _} ->
            drop_oldest_in_batch(F)
    end.

drop_oldest_in_batch(F = #flight{batch = B, batch_n = BN, batch_bytes = BB,
                                 count = N, bytes = Bytes}) ->
    [{_, Size, _} | Newer] = lists:reverse(B),
    F#flight{batch = lists:reverse(Newer), batch_n = BN - 1, batch_bytes = BB - Size,
             count = N - 1, bytes = Bytes - Size}.

seal_if_full(T, F = #flight{batch_first = First, batch_n = BN, batch_bytes = BB, max_bytes = MaxB}) ->
    case BN >= ?SEGMENT_EVENTS orelse BB >= MaxB div ?SEGMENTS_IN_BYTES
        orelse T - First >= ?SEGMENT_NS of
        true -> seal(F);
        false -> F
    end.

%% The open batch becomes one compressed binary, off the process's heap;
%% the heap that held the batch is given back by hibernating
%% (`hibernate' in the state, handled by noreply/1).
seal(F = #flight{batch = B, batch_n = BN, batch_bytes = BB, segments = Q, bytes = Bytes,
                 max_bytes = MaxB}) ->
    Batch = lists:reverse([{T, Item} || {T, _, Item} <- B]),
    Bin = term_to_binary(Batch, [{compressed, ?SEGMENT_ZLIB}]),
    [{First, _} | _] = Batch,
    Last = lists:max([T || {T, _} <- Batch]),
    F1 = F#flight{batch = [], batch_n = 0, batch_bytes = 0, hibernate = true,
                  segments = queue:in({First, Last, BN, Bin}, Q),
                  bytes = Bytes - BB + byte_size(Bin)},
    %% The compressed list may be a few bytes more than its events alone.
    case F1#flight.bytes > MaxB of
        true -> make_room(0, F1);
        false -> F1
    end.

%% Whole segments older than the window go; the events of the oldest
%% segment left that are older than the window are skipped when read.
trim(Now, F = #flight{segments = Q, count = N, bytes = B, window_ns = W}) ->
    case queue:peek(Q) of
        {value, {_, Last, C, Bin}} when Last < Now - W ->
            trim(Now, F#flight{segments = queue:drop(Q), count = N - C, bytes = B - byte_size(Bin)});
        _ -> F
    end.

noreply(F = #flight{hibernate = true}) -> {noreply, F#flight{hibernate = false}, hibernate};
noreply(F) -> {noreply, F}.

%% Folds Fun over the window's events, oldest first, as {T, Item}: each
%% segment decoded in turn, its skipped events left out, then those older
%% than the window at the front left out (as the events were trimmed
%% before segments).
fold_window(Fun, Acc0, #flight{segments = Q, batch = B, newest = Newest, window_ns = W}) ->
    Cut = Newest - W,
    Step = fun({T, _}, {true, Acc}) when T < Cut -> {true, Acc};
              (Item, {_, Acc}) -> {false, Fun(Item, Acc)}
           end,
    Segments = fun({_, _, C, Bin}, Acc) ->
                       Batch = binary_to_term(Bin),
                       lists:foldl(Step, Acc, lists:nthtail(length(Batch) - C, Batch))
               end,
    Acc1 = lists:foldl(Segments, {true, Acc0}, queue:to_list(Q)),
    {_, Acc} = lists:foldl(Step, Acc1, lists:reverse([{T, Item} || {T, _, Item} <- B])),
    Acc.

layer_removed(L, F = #flight{dropped = D}) ->
    Dir = env(log_dir, "log"),
    Stamp = calendar:system_time_to_rfc3339(erlang:system_time(second), [{offset, "Z"}]),
    Name = lists:flatten(io_lib:format("flight-~ts-layer~b.mcap", [[C || C <- Stamp, C =/= $:], L])),
    Path = filename:join(Dir, Name),
    _ = filelib:ensure_dir(Path),
    case write(Path, F) of
        {ok, #{messages := N}} ->
            logger:error("layer ~b taken out: the flight recorder wrote its last ~b events to ~ts"
                         " (~b dropped before)", [L, N, Path, D], #{domain => [toroco, rec]});
        {error, Why} ->
            logger:error("layer ~b taken out: the flight recorder could not write ~ts: ~0p",
                         [L, Path, Why], #{domain => [toroco, rec]})
    end.

write(Path, F) ->
    {Head, L0} = toroco_rec_recorder:log_new(),
    {Body, L} = fold_window(fun(Item, {Acc, L1}) ->
                                    case message(Item) of
                                        {K, T, J} ->
                                            {B, L2} = toroco_rec_recorder:log_event(K, {T, J}, L1),
                                            {[Acc, B], L2};
                                        none -> {Acc, L1}
                                    end
                            end, {[], L0}, F),
    case file:write_file(Path, [Head, Body, toroco_rec_recorder:log_end(L)]) of
        ok -> {ok, #{messages => toroco_rec_recorder:log_messages(L), path => Path}};
        {error, Why} -> {error, {cannot_write, Path, Why}}
    end.

message({_, {event, Event}}) -> toroco_rec_channels:of_event(Event);
message({T, {message, K, J}}) -> {K, T, J}.
