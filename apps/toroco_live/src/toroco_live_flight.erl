%% @doc The recorders' process: the flight recorder (SPEC §12), always on,
%% and the recording when one is asked for (`toroco_live_recorder').
%%
%% The flight recorder keeps the last `flight_seconds' (app env, default
%% 30) of the robot's events in memory and writes them as MCAP on demand
%% (`toroco_live:dump/1') and by itself, into the log directory, when a
%% layer is taken out (the lifecycle event `{layer_removed, L}'): the log
%% line names the file. Events are kept as they came; their JSON is made
%% only for a dump.
%%
%% One tap subscription (SPEC §10) serves the flight recorder and the
%% recording, and the process runs at low priority: the robot first. Memory
%% is bounded by time (older events go as new ones come), by count
%% (`flight_max_events', default 200000) and by size (`flight_max_bytes',
%% default 32 MiB, the events' terms as `erlang:external_size/1' counts
%% them, binaries included), the oldest
%% going first, and by the
%% tap's buffer for what waits in the mailbox; what the tap drops is
%% counted, said in a dump's log line and in a recording's result.
%%
%% The log directory is the app env `log_dir' of `toroco_live', else `log'
%% in the node's working directory (the release's log directory when run
%% from a release root).
-module(toroco_live_flight).
-behaviour(gen_server).

-export([start_link/0, dump/1, record/2, stop_recording/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-define(MAX_EVENTS, 200000).
-define(MAX_BYTES, 32 * 1024 * 1024).
-define(BUFFER, 20000).
%% A dump, and stopping a recording, take the events still on their way (the tap's
%% relay forwards them a little later) until the tap is quiet this long,
%% and waits at most the next.
-define(QUIET_MS, 30).
-define(MAX_DRAIN_MS, 2000).
%% How soon to subscribe again when the runtime's tap went away.
-define(RESUBSCRIBE_MS, 500).

-type item() :: {event, tuple()} | {message, toroco_live_channels:key(), binary()}.

-record(flight, {tap :: reference() | none,
                 %% The tap server: when it goes (the runtime restarts), so
                 %% does the subscription, and this process subscribes again.
                 tap_monitor = none :: reference() | none,
                 events = queue:new() :: queue:queue({integer(), non_neg_integer(), item()}),
                 count = 0 :: non_neg_integer(),
                 bytes = 0 :: non_neg_integer(),
                 max_bytes :: pos_integer(),
                 dropped = 0 :: non_neg_integer(),
                 window_ns :: pos_integer(),
                 max :: pos_integer(),
                 recording = none :: none | toroco_live_recorder:recording(),
                 scene = none :: toroco_live_channels:scene_sent()}).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Writes the last seconds to `Path' as MCAP.
-spec dump(file:filename_all()) -> {ok, #{messages := non_neg_integer(), path := file:filename_all()}}
                                       | {error, term()}.
dump(Path) ->
    gen_server:call(?MODULE, {dump, Path}, 60000).

%% @doc Starts a recording (see `toroco_live:record/2').
-spec record(file:filename_all(), map()) -> ok | {error, term()}.
record(Path, Opts) ->
    gen_server:call(?MODULE, {record, Path, Opts}, 30000).

%% @doc Ends the recording (see `toroco_live:stop_recording/0').
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer()}} | {error, term()}.
stop_recording() ->
    gen_server:call(?MODULE, stop_recording, 60000).

-spec init([]) -> {ok, #flight{}}.
init([]) ->
    process_flag(trap_exit, true),
    process_flag(priority, low),
    Seconds = application:get_env(toroco_live, flight_seconds, 30),
    Max = application:get_env(toroco_live, flight_max_events, ?MAX_EVENTS),
    MaxBytes = application:get_env(toroco_live, flight_max_bytes, ?MAX_BYTES),
    %% toroco_live_world starts before this process (toroco_live_sup).
    _ = (catch toroco_live_world:subscribe()),
    {ok, subscribe(#flight{tap = none, window_ns = Seconds * 1000000000, max = Max,
                             max_bytes = MaxBytes})}.

-spec handle_call(term(), gen_server:from(), #flight{}) -> {reply, term(), #flight{}}.
handle_call({dump, Path}, _From, F0) ->
    F = drain(F0, erlang:monotonic_time(millisecond) + ?MAX_DRAIN_MS),
    {reply, write(Path, F), F};
handle_call({record, Path, _}, _From, F = #flight{recording = R}) when R =/= none ->
    {reply, {error, {already_recording, toroco_live_recorder:path(R), Path}}, F};
handle_call({record, _, _}, _From, F = #flight{tap = none}) ->
    {reply, {error, no_events}, F};
handle_call({record, Path, Opts}, _From, F) ->
    case toroco_live_recorder:open(Path, Opts) of
        {ok, R} -> {reply, ok, F#flight{recording = R}};
        Err -> {reply, Err, F}
    end;
handle_call(stop_recording, _From, F = #flight{recording = none}) ->
    {reply, {error, not_recording}, F};
handle_call(stop_recording, _From, F0) ->
    F = #flight{recording = R} = drain(F0, erlang:monotonic_time(millisecond) + ?MAX_DRAIN_MS),
    {reply, toroco_live_recorder:close(R), F#flight{recording = none}};
handle_call(_, _From, F) ->
    {reply, {error, unknown_call}, F}.

-spec handle_cast(term(), #flight{}) -> {noreply, #flight{}}.
handle_cast(_, F) ->
    {noreply, F}.

-spec handle_info(term(), #flight{}) -> {noreply, #flight{}}.
handle_info({toroco_event, Tap, Event}, F = #flight{tap = Tap}) ->
    {noreply, event(Event, F)};
handle_info({'DOWN', M, process, _, _}, F = #flight{tap_monitor = M}) ->
    erlang:send_after(?RESUBSCRIBE_MS, self(), subscribe),
    {noreply, F#flight{tap = none, tap_monitor = none}};
handle_info(subscribe, F = #flight{tap = none}) ->
    {noreply, subscribe(F)};
handle_info({toroco_live_world, changed}, F) ->
    {Msgs, Scene} = toroco_live_channels:world(toroco_live_world:latest(),
                                               erlang:system_time(nanosecond), F#flight.scene),
    {noreply, lists:foldl(fun({K, T, J}, Acc = #flight{recording = R}) ->
                                  keep({T, {message, K, J}},
                                       Acc#flight{recording = record_message(K, T, J, R)})
                          end, F#flight{scene = Scene}, Msgs)};
handle_info(_, F) ->
    {noreply, F}.

-spec terminate(term(), #flight{}) -> ok.
terminate(_, #flight{recording = none}) ->
    ok;
terminate(_, #flight{recording = R}) ->
    _ = toroco_live_recorder:close(R),
    ok.

%%====================================================================
%% Inside
%%====================================================================

subscribe(F) ->
    try toroco:subscribe_events(#{buffer => ?BUFFER}) of
        {ok, Ref} -> F#flight{tap = Ref, tap_monitor = monitor(process, toroco_tap)};
        {error, _} -> retry(F)
    catch exit:_ -> retry(F)
    end.

retry(F) ->
    erlang:send_after(?RESUBSCRIBE_MS, self(), subscribe),
    F.

event({dropped, N}, F = #flight{dropped = D, recording = R}) ->
    F#flight{dropped = D + N, recording = case R of
                                             none -> none;
                                             _ -> toroco_live_recorder:dropped(N, R)
                                         end};
event(Event, F0 = #flight{recording = R}) ->
    F = case R of
            none -> F0;
            _ -> F0#flight{recording = toroco_live_recorder:event(Event, R)}
        end,
    F1 = case toroco_live_channels:event_time(Event) of
             none -> F;
             T -> trim(T, keep({T, {event, Event}}, F))
         end,
    case Event of
        {lifecycle, _, _, {layer_removed, L}} -> layer_removed(L, F1);
        _ -> ok
    end,
    F1.

record_message(_, _, _, none) -> none;
record_message(K, T, J, R) -> toroco_live_recorder:message(K, T, J, R).

drain(F = #flight{tap = Tap}, Until) ->
    Wait = min(?QUIET_MS, max(0, Until - erlang:monotonic_time(millisecond))),
    receive
        {toroco_event, Tap, Event} -> drain(event(Event, F), Until)
    after Wait -> F
    end.

%% The oldest go first when the count or the bytes would pass their bound.
keep({T, Item}, F) ->
    Size = erlang:external_size(Item),
    F1 = #flight{events = Q, count = N, bytes = B} = make_room(Size, F),
    F1#flight{events = queue:in({T, Size, Item}, Q), count = N + 1, bytes = B + Size}.

make_room(Size, F = #flight{count = N, max = Max, bytes = B, max_bytes = MaxB})
  when N > 0, (N >= Max orelse B + Size > MaxB) ->
    make_room(Size, drop_oldest(F));
make_room(_, F) ->
    F.

drop_oldest(F = #flight{events = Q, count = N, bytes = B}) ->
    {{value, {_, Size, _}}, Q1} = queue:out(Q),
    F#flight{events = Q1, count = N - 1, bytes = B - Size}.

trim(Now, F = #flight{events = Q, window_ns = W}) ->
    case queue:peek(Q) of
        {value, {T, _, _}} when T < Now - W -> trim(Now, drop_oldest(F));
        _ -> F
    end.

layer_removed(L, F = #flight{dropped = D}) ->
    Dir = application:get_env(toroco_live, log_dir, "log"),
    Stamp = calendar:system_time_to_rfc3339(erlang:system_time(second), [{offset, "Z"}]),
    Name = lists:flatten(io_lib:format("flight-~ts-layer~b.mcap", [[C || C <- Stamp, C =/= $:], L])),
    Path = filename:join(Dir, Name),
    _ = filelib:ensure_dir(Path),
    case write(Path, F) of
        {ok, #{messages := N}} ->
            logger:error("layer ~b taken out: the flight recorder wrote its last ~b events to ~ts"
                         " (~b dropped before)", [L, N, Path, D], #{domain => [toroco, live]});
        {error, Why} ->
            logger:error("layer ~b taken out: the flight recorder could not write ~ts: ~0p",
                         [L, Path, Why], #{domain => [toroco, live]})
    end.

write(Path, #flight{events = Q}) ->
    {Head, L0} = toroco_live_recorder:log_new(),
    {Body, L} = lists:foldl(fun(Item, {Acc, L1}) ->
                                    case message(Item) of
                                        {K, T, J} ->
                                            {B, L2} = toroco_live_recorder:log_event(K, {T, J}, L1),
                                            {[Acc, B], L2};
                                        none -> {Acc, L1}
                                    end
                            end, {[], L0}, queue:to_list(Q)),
    case file:write_file(Path, [Head, Body, toroco_live_recorder:log_end(L)]) of
        ok -> {ok, #{messages => toroco_live_recorder:log_messages(L), path => Path}};
        {error, Why} -> {error, {cannot_write, Path, Why}}
    end.

message({_, _, {event, Event}}) -> toroco_live_channels:of_event(Event);
message({T, _, {message, K, J}}) -> {K, T, J}.
