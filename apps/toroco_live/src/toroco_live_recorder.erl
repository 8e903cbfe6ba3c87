%% @doc Recording (SPEC §12): `toroco_live:record/2' and
%% `stop_recording/0' write the bridge's channels and schemas to an MCAP
%% file, so a recording opens in Foxglove like a live robot.
%%
%% One process under `toroco_live_sup', idle (no tap subscription) when
%% nothing is recorded. While recording it is a tap subscriber (SPEC §10)
%% with a bounded buffer: when the disk is slower than the robot the tap
%% drops events for it and counts them (`dropped' in the result); the robot
%% never waits for the file. A path that cannot be opened is refused; a
%% write that fails (a full disk) ends the recording with a logged error
%% naming the file, and `stop_recording/0' then returns that error.
%%
%% {@link log_new/0}, {@link log_event/3} and {@link log_end/1} turn
%% events into MCAP bytes (channels and schemas added as they first
%% appear); the flight recorder writes its dumps with them too.
-module(toroco_live_recorder).
-behaviour(gen_server).

-export([start_link/0, record/2, stop_recording/0]).
-export([log_new/0, log_event/3, log_end/1, log_messages/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([log/0]).

-define(BUFFER, 20000).
-define(KINDS, [emit, deliver, router, lifecycle]).
%% Stopping waits for the tap to be quiet this long, and at most the next.
-define(QUIET_MS, 30).
-define(MAX_DRAIN_MS, 2000).

-record(log, {writer :: toroco_live_mcap:writer(),
              channels = #{} :: #{toroco_live_channels:key() => non_neg_integer()},
              schemas = #{} :: #{binary() => pos_integer()},
              seq = 0 :: non_neg_integer()}).
-opaque log() :: #log{}.

-record(rec, {path :: file:filename_all(),
              fd :: file:io_device(),
              tap :: reference(),
              log :: log(),
              dropped = 0 :: non_neg_integer()}).

-type state() :: idle | #rec{} | {failed, file:filename_all(), term()}.

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Starts recording the events of `kinds' (default all) about `names'
%% (default all) to `Path'.
-spec record(file:filename_all(), #{kinds => [atom()], names => all | [atom()]}) ->
          ok | {error, term()}.
record(Path, Opts) when is_map(Opts) ->
    gen_server:call(?MODULE, {record, Path, Opts}, 30000);
record(_Path, Opts) ->
    {error, {bad_option, Opts}}.

%% @doc Ends the recording: the file is complete (summary, footer) and
%% readable by any MCAP reader.
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer()}} | {error, term()}.
stop_recording() ->
    gen_server:call(?MODULE, stop_recording, 60000).

%%====================================================================
%% Events to MCAP bytes
%%====================================================================

%% @doc A new file's log and its first bytes.
-spec log_new() -> {iodata(), log()}.
log_new() ->
    {Head, W} = toroco_live_mcap:new(#{}),
    {Head, #log{writer = W}}.

%% @doc The bytes of one message on channel `Key' at `T' (ns), with the
%% channel's and its schema's records the first time they appear.
-spec log_event(toroco_live_channels:key(), {integer(), binary()}, log()) -> {iodata(), log()}.
log_event(Key, {T, Json}, L0) ->
    {Decl, L = #log{writer = W, channels = Chs, seq = Seq}} = declare(Key, L0),
    {Bytes, W1} = toroco_live_mcap:add_message(W, maps:get(Key, Chs), Seq, max(T, 0), Json),
    {[Decl, Bytes], L#log{writer = W1, seq = Seq + 1}}.

%% @doc The last bytes of the file.
-spec log_end(log()) -> iodata().
log_end(#log{writer = W}) ->
    toroco_live_mcap:finish(W).

%% @doc Messages logged so far.
-spec log_messages(log()) -> non_neg_integer().
log_messages(#log{writer = W}) ->
    toroco_live_mcap:message_count(W).

declare(Key, L = #log{channels = Chs}) when is_map_key(Key, Chs) ->
    {[], L};
declare(Key, L = #log{writer = W, channels = Chs, schemas = Ss}) ->
    {Name, Schema} = toroco_live_channels:schema(Key),
    {SBytes, W1, Ss1, SId} =
        case Ss of
            #{Name := Id} -> {[], W, Ss, Id};
            #{} ->
                Id = map_size(Ss) + 1,
                {B, W0} = toroco_live_mcap:add_schema(W, Id, Name, Schema),
                {B, W0, Ss#{Name => Id}, Id}
        end,
    CId = map_size(Chs) + 1,
    {CBytes, W2} = toroco_live_mcap:add_channel(W1, CId, SId, toroco_live_channels:topic(Key), #{}),
    {[SBytes, CBytes], L#log{writer = W2, channels = Chs#{Key => CId}, schemas = Ss1}}.

%%====================================================================
%% gen_server
%%====================================================================

-spec init([]) -> {ok, state()}.
init([]) ->
    process_flag(trap_exit, true),
    {ok, idle}.

-spec handle_call(term(), gen_server:from(), state()) -> {reply, term(), state()}.
handle_call({record, Path, _}, _From, R = #rec{path = Recording}) ->
    {reply, {error, {already_recording, Recording, Path}}, R};
handle_call({record, Path, Opts}, _From, _Idle) ->
    case start(Path, Opts) of
        {ok, R} -> {reply, ok, R};
        Err -> {reply, Err, idle}
    end;
handle_call(stop_recording, _From, R = #rec{}) ->
    {reply, finish(R), idle};
handle_call(stop_recording, _From, {failed, Path, Why}) ->
    {reply, {error, {write_failed, Path, Why}}, idle};
handle_call(stop_recording, _From, idle) ->
    {reply, {error, not_recording}, idle};
handle_call(_, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), state()) -> {noreply, state()}.
handle_cast(_, S) ->
    {noreply, S}.

-spec handle_info(term(), state()) -> {noreply, state()}.
handle_info({toroco_event, Tap, {dropped, N}}, R = #rec{tap = Tap, dropped = D}) ->
    {noreply, R#rec{dropped = D + N}};
handle_info({toroco_event, Tap, Event}, R = #rec{tap = Tap}) ->
    case toroco_live_channels:of_event(Event) of
        none -> {noreply, R};
        {Key, T, Json} -> {noreply, write(R, Key, T, Json)}
    end;
handle_info({toroco_live_world, changed}, R = #rec{}) ->
    Msgs = toroco_live_channels:world(toroco_live_world:latest(), erlang:system_time(nanosecond)),
    {noreply, lists:foldl(fun({K, T1, J}, Acc = #rec{}) -> write(Acc, K, T1, J);
                             (_, Acc) -> Acc
                          end, R, Msgs)};
handle_info(_, S) ->
    {noreply, S}.

-spec terminate(term(), state()) -> ok.
terminate(_, R = #rec{}) ->
    _ = finish(R),
    ok;
terminate(_, _) ->
    ok.

%%====================================================================
%% Inside
%%====================================================================

start(Path, Opts) ->
    Kinds = maps:get(kinds, Opts, ?KINDS),
    Names = maps:get(names, Opts, all),
    case maps:keys(maps:without([kinds, names], Opts)) of
        [Bad | _] -> {error, {bad_option, Bad}};
        [] when not is_list(Kinds) -> {error, {bad_option, {kinds, Kinds}}};
        [] ->
            case Kinds -- ?KINDS of
                [] ->
                    case file:open(Path, [write, raw, binary]) of
                        {ok, Fd} -> start(Path, Fd, Kinds, Names);
                        {error, Why} -> {error, {cannot_write, Path, Why}}
                    end;
                Unknown -> {error, {bad_option, {kinds, Unknown}}}
            end
    end.

start(Path, Fd, Kinds, Names) ->
    {Head, Log} = log_new(),
    case file:write(Fd, Head) of
        ok ->
            case toroco:subscribe_events(#{kinds => Kinds, names => Names, buffer => ?BUFFER}) of
                {ok, Tap} ->
                    world(subscribe),
                    {ok, #rec{path = Path, fd = Fd, tap = Tap, log = Log}};
                Err -> _ = file:close(Fd), Err
            end;
        {error, Why} ->
            _ = file:close(Fd),
            {error, {cannot_write, Path, Why}}
    end.

write(R = #rec{fd = Fd, log = L}, Key, T, Json) ->
    {Bytes, L1} = log_event(Key, {T, Json}, L),
    case iolist_size(Bytes) of
        0 -> R#rec{log = L1};
        _ ->
            case file:write(Fd, Bytes) of
                ok -> R#rec{log = L1};
                {error, Why} -> fail(R, Why)
            end
    end.

fail(#rec{path = Path, fd = Fd, tap = Tap}, Why) ->
    toroco:unsubscribe_events(Tap),
    world(unsubscribe),
    _ = file:close(Fd),
    logger:error("recording to ~ts stopped: ~0p", [Path, Why], #{domain => [toroco, live]}),
    {failed, Path, Why}.

finish(R0 = #rec{path = Path, fd = Fd, tap = Tap, log = L, dropped = D}) ->
    %% Events on their way (the tap's relay forwards them a little later)
    %% belong to the recording: take them until the tap is quiet, then
    %% what is left in the mailbox once unsubscribed.
    R = drain(R0, ?QUIET_MS, erlang:monotonic_time(millisecond) + ?MAX_DRAIN_MS),
    toroco:unsubscribe_events(Tap),
    world(unsubscribe),
    R1 = case R of
             #rec{} -> drain(R, 0, 0);
             Failed -> Failed
         end,
    case R1 of
        #rec{log = L1, dropped = D1} ->
            case file:write(Fd, log_end(L1)) of
                ok ->
                    _ = file:close(Fd),
                    {ok, #{path => Path, messages => log_messages(L1), dropped => D1}};
                {error, Why} ->
                    _ = file:close(Fd),
                    {error, {write_failed, Path, Why}}
            end;
        {failed, _, Why} ->
            _ = {L, D},
            {error, {write_failed, Path, Why}}
    end.

drain(R = #rec{tap = Tap}, Quiet, Until) ->
    Wait = min(Quiet, max(0, Until - erlang:monotonic_time(millisecond))),
    receive
        {toroco_event, Tap, {dropped, N}} -> drain(R#rec{dropped = R#rec.dropped + N}, Quiet, Until);
        {toroco_event, Tap, Event} ->
            case toroco_live_channels:of_event(Event) of
                none -> drain(R, Quiet, Until);
                {Key, T, Json} ->
                    case write(R, Key, T, Json) of
                        R1 = #rec{} -> drain(R1, Quiet, Until);
                        Failed -> Failed
                    end
            end
    after Wait -> R
    end.

%% The simulated world's snapshots (`toroco_live_world'), while recording.
world(How) ->
    case whereis(toroco_live_world) of
        undefined -> ok;
        _ -> catch toroco_live_world:How()
    end.
