%% @doc The flight recorder (SPEC §12): always on, it keeps the last
%% `flight_seconds' (app env, default 30) of the robot's events in memory
%% and writes them as MCAP on demand (`toroco_live:dump/1') and by itself,
%% into the log directory, when a layer is taken out (the lifecycle event
%% `{layer_removed, L}'): the log line names the file.
%%
%% Memory is bounded twice: by time (older events are let go as new ones
%% come) and by count (`flight_max_events', default 200000, the oldest go
%% first). The tap's buffer bounds what waits in its mailbox; what the tap
%% drops is counted and said in the dump's log line.
%%
%% The log directory is the app env `log_dir' of `toroco_live', else
%% `log' in the node's working directory (the release's log directory when
%% run from a release root).
-module(toroco_live_flight).
-behaviour(gen_server).

-export([start_link/0, dump/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).

-define(MAX_EVENTS, 200000).

-type item() :: {event, tuple()} | {message, toroco_live_channels:key(), binary()}.

-record(flight, {tap :: reference() | none,
                 events = queue:new() :: queue:queue({integer(), item()}),
                 count = 0 :: non_neg_integer(),
                 dropped = 0 :: non_neg_integer(),
                 window_ns :: pos_integer(),
                 max :: pos_integer()}).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Writes the last seconds to `Path' as MCAP.
-spec dump(file:filename_all()) -> {ok, #{messages := non_neg_integer(), path := file:filename_all()}}
                                       | {error, term()}.
dump(Path) ->
    gen_server:call(?MODULE, {dump, Path}, 60000).

-spec init([]) -> {ok, #flight{}}.
init([]) ->
    Seconds = application:get_env(toroco_live, flight_seconds, 30),
    Max = application:get_env(toroco_live, flight_max_events, ?MAX_EVENTS),
    Tap = case toroco:subscribe_events(#{}) of
              {ok, Ref} -> Ref;
              {error, Why} ->
                  logger:warning("flight recorder off: ~0p", [Why], #{domain => [toroco, live]}),
                  none
          end,
    %% toroco_live_world starts before this process (toroco_live_sup).
    _ = (catch toroco_live_world:subscribe()),
    {ok, #flight{tap = Tap, window_ns = Seconds * 1000000000, max = Max}}.

-spec handle_call(term(), gen_server:from(), #flight{}) -> {reply, term(), #flight{}}.
handle_call({dump, Path}, _From, F) ->
    {reply, write(Path, F), F};
handle_call(_, _From, F) ->
    {reply, {error, unknown_call}, F}.

-spec handle_cast(term(), #flight{}) -> {noreply, #flight{}}.
handle_cast(_, F) ->
    {noreply, F}.

-spec handle_info(term(), #flight{}) -> {noreply, #flight{}}.
handle_info({toroco_event, Tap, {dropped, N}}, F = #flight{tap = Tap, dropped = D}) ->
    {noreply, F#flight{dropped = D + N}};
handle_info({toroco_event, Tap, Event}, F = #flight{tap = Tap}) ->
    %% Kept as it came: JSON is made only if a dump is asked for.
    F1 = case toroco_live_channels:event_time(Event) of
             none -> F;
             T -> trim(T, keep({T, {event, Event}}, F))
         end,
    case Event of
        {lifecycle, _, _, {layer_removed, L}} -> layer_removed(L, F1);
        _ -> ok
    end,
    {noreply, F1};
handle_info({toroco_live_world, changed}, F) ->
    Msgs = toroco_live_channels:world(toroco_live_world:latest(), erlang:system_time(nanosecond)),
    {noreply, lists:foldl(fun({K, T1, J}, Acc) -> keep({T1, {message, K, J}}, Acc) end, F, Msgs)};

handle_info(_, F) ->
    {noreply, F}.

keep(Msg, F = #flight{events = Q, count = N, max = Max}) when N >= Max ->
    keep(Msg, F#flight{events = queue:drop(Q), count = N - 1});
keep(Msg, F = #flight{events = Q, count = N}) ->
    F#flight{events = queue:in(Msg, Q), count = N + 1}.

trim(Now, F = #flight{events = Q, count = N, window_ns = W}) ->
    case queue:peek(Q) of
        {value, {T, _}} when T < Now - W -> trim(Now, F#flight{events = queue:drop(Q), count = N - 1});
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

message({_, {event, Event}}) -> toroco_live_channels:of_event(Event);
message({T, {message, K, J}}) -> {K, T, J}.
