%% @doc Recording (SPEC §12): an MCAP file with the bridge's channels and
%% schemas, so a recording opens in Foxglove like a live robot.
%%
%% A recording is data, not a process: the flight recorder's process
%% (`toroco_rec_flight'), already a subscriber of the observer tap for
%% everything, feeds the open recording each event that passes its `kinds'
%% and `names'. One subscription serves both, so recording adds no second
%% relay to the robot's event path, and the process runs at low priority:
%% when the disk or the CPU is slower than the robot, the tap drops events
%% for it and counts them (`dropped'); the robot never waits for the file.
%% A path that cannot be opened is refused; a failed write (a full disk)
%% ends the recording with a logged error naming the file, and
%% `stop_recording/0' returns that error.
%%
%% <b>Profiles.</b> `profile => foxglove' (the default) writes the
%% bridge's JSON channels. Any other profile is a module of the
%% `toroco_rec_profile' behaviour another application added (`ros2',
%% added by `toroco_ros', SPEC §15): the header's profile is the module's,
%% an emission becomes the messages the module makes of it, each with its
%% type's schema and encoding; the events that are not an output's
%% emission (deliveries, routers, lifecycle) go on their §12 topics
%% wrapped by the module (`std_msgs/msg/String' carrying the same JSON),
%% so the file holds what the default one does, typed where a type fits.
%% A message its type does not take (a field missing) is left out, counted
%% in `unencodable' and logged once per topic.
%%
%% Files: {@link open/2}, {@link event/2}, {@link world/4},
%% {@link message/4}, {@link dropped/2}, {@link close/1}. Bytes:
%% {@link log_new/0}, {@link log_event/3}, {@link log_end/1} turn messages
%% into MCAP (channels and schemas added as they first appear); flight
%% dumps use them too.
-module(toroco_rec_recorder).

-export([open/2, event/2, world/4, message/4, dropped/2, close/1, path/1]).
-export([log_new/0, log_event/3, log_end/1, log_messages/1]).

-export_type([log/0, recording/0]).

-define(KINDS, [emit, deliver, router, lifecycle]).

%% A channel: a key of the bridge's channels (profile foxglove) or a
%% topic with its type (another profile, its module).
-record(log, {writer :: toroco_rec_mcap:writer(),
              profile = foxglove :: foxglove | module(),
              channels = #{} :: #{toroco_rec_channels:key() | {binary(), binary()}
                                      => non_neg_integer()},
              schemas = #{} :: #{binary() => pos_integer()},
              seq = 0 :: non_neg_integer()}).
-opaque log() :: #log{}.

-record(rec, {path :: file:filename_all(),
              fd :: file:io_device(),
              kinds :: [atom()],
              names :: all | [atom()],
              profile :: foxglove | module(),
              %% another profile: messages their type did not take, and the topics
              %% already logged for it
              unencodable = 0 :: non_neg_integer(),
              warned = [] :: [binary()],
              log :: log(),
              %% when it started, on the runtime's clock then (events
              %% stamped before are not in it; SPEC §14: in lockstep the
              %% stamps are simulated time)
              since :: {realtime | lockstep, integer()},
              dropped = 0 :: non_neg_integer()}).
-opaque recording() :: #rec{} | {failed, file:filename_all(), term()}.

%%====================================================================
%% Recordings
%%====================================================================

%% @doc A recording of the events of `kinds' (default all) about `names'
%% (default all) into `Path', in the `profile' `foxglove' (default) or
%% one added as a `toroco_rec_profile' (`ros2').
-spec open(file:filename_all(), map()) -> {ok, recording()} | {error, term()}.
open(Path, Opts) when is_map(Opts) ->
    Kinds = maps:get(kinds, Opts, ?KINDS),
    Names = maps:get(names, Opts, all),
    Profile = maps:get(profile, Opts, foxglove),
    case maps:keys(maps:without([kinds, names, profile], Opts)) of
        [Bad | _] -> {error, {bad_option, Bad}};
        [] when not is_list(Kinds) -> {error, {bad_option, {kinds, Kinds}}};
        [] when Names =/= all, not is_list(Names) -> {error, {bad_option, {names, Names}}};
        [] ->
            case {Kinds -- ?KINDS, profile(Profile)} of
                {[], {ok, Module}} -> open(Path, Kinds, Names, Module);
                {[], error} -> {error, {bad_option, {profile, Profile}}};
                {Unknown, _} -> {error, {bad_option, {kinds, Unknown}}}
            end
    end;
open(_Path, Opts) ->
    {error, {bad_option, Opts}}.

profile(foxglove) -> {ok, foxglove};
profile(Name) when is_atom(Name) -> toroco_rec_profile:find(Name);
profile(_) -> error.

open(Path, Kinds, Names, Profile) ->
    case file:open(Path, [write, raw, binary]) of
        {ok, Fd} ->
            {Head, Log} = log_new(Profile),
            case file:write(Fd, Head) of
                ok -> {ok, #rec{path = Path, fd = Fd, kinds = Kinds, names = Names, log = Log,
                                profile = Profile,
                                since = {toroco_clock:mode(), toroco_clock:timestamp_ns()}}};
                {error, Why} ->
                    _ = file:close(Fd),
                    {error, {cannot_write, Path, Why}}
            end;
        {error, Why} ->
            {error, {cannot_write, Path, Why}}
    end.

%% @doc One tap event, written if it passes the recording's filters and
%% happened after the recording started.
-spec event(tuple(), recording()) -> recording().
event(Event, R = #rec{kinds = Kinds, names = Names, since = Since}) ->
    Wanted = after_start(toroco_rec_channels:event_time(Event), Since) andalso
        lists:member(element(1, Event), Kinds) andalso
        (Names =:= all orelse
         lists:any(fun(N) -> lists:member(N, Names) end, toroco_rec_channels:event_names(Event))),
    case Wanted of
        false -> R;
        true when R#rec.profile =/= foxglove -> typed_event(Event, R);
        true ->
            case toroco_rec_channels:of_event(Event) of
                {Key, T, Json} -> message(Key, T, Json, R);
                none -> R
            end
    end;
event(_, Failed) ->
    Failed.

%% An emission is the profile's messages; any other event its §12 JSON,
%% wrapped by the profile, on its §12 topic.
typed_event(Event, R = #rec{profile = Module}) ->
    case element(1, Event) of
        emit ->
            T = toroco_rec_channels:event_time(Event),
            typed_messages(Module:of_event(Event), T, R);
        _ ->
            case toroco_rec_channels:of_event(Event) of
                {Key, T, Json} ->
                    typed_message(toroco_rec_channels:topic(Key), Module:text_type(), T,
                                  Module:text(Json), R);
                none -> R
            end
    end.

typed_messages(Messages, T, R) ->
    lists:foldl(fun({Topic, Type, Msg}, Acc) -> typed_message(Topic, Type, T, Msg, Acc) end,
                R, Messages).

typed_message(Topic, Type, T, Msg, R = #rec{profile = Module, unencodable = U, warned = Warned}) ->
    case Module:encode(Type, Msg) of
        {ok, Cdr} -> write(log_event({Topic, Type}, {T, Cdr}, R#rec.log), R);
        {error, Why} ->
            lists:member(Topic, Warned) orelse
                logger:warning("recording to ~ts: a message on ~ts is not a ~ts (~0p), left out",
                               [R#rec.path, Topic, Type, Why], #{domain => [toroco, rec]}),
            R#rec{unencodable = U + 1, warned = lists:usort([Topic | Warned])}
    end.

%% @doc A world snapshot at `T' (ns): the profile's messages of it (ROS 2's
%% `/odom'), or in the profile foxglove `Msgs', the bridge's world
%% messages made of it.
-spec world(map() | none, integer(), [{toroco_rec_channels:key(), integer(), binary()}],
            recording()) -> recording().
world(Snapshot, T, _Msgs, R = #rec{profile = Module}) when Module =/= foxglove ->
    typed_messages(Module:of_world(Snapshot, T), T, R);
world(_Snapshot, _T, Msgs, R = #rec{}) ->
    lists:foldl(fun({K, T, J}, Acc) -> message(K, T, J, Acc) end, R, Msgs);
world(_, _, _, Failed) ->
    Failed.

%% A recording that outlives a change of the clock (the flight recorder
%% across a lockstep run) takes every event of the other clock.
after_start(T, {Mode, Since}) ->
    T >= Since orelse toroco_clock:mode() =/= Mode.

%% @doc A message made elsewhere (the world's channels).
-spec message(toroco_rec_channels:key(), integer(), binary(), recording()) -> recording().
message(Key, T, Json, R = #rec{profile = foxglove, log = L}) ->
    write(log_event(Key, {T, Json}, L), R);
message(_, _, _, R = #rec{}) ->
    R;
message(_, _, _, Failed) ->
    Failed.

write({Bytes, L1}, R = #rec{fd = Fd}) ->
    case iolist_size(Bytes) of
        0 -> R#rec{log = L1};
        _ ->
            case file:write(Fd, Bytes) of
                ok -> R#rec{log = L1};
                {error, Why} -> fail(R, Why)
            end
    end.

%% @doc Events the tap dropped while this recording ran.
-spec dropped(non_neg_integer(), recording()) -> recording().
dropped(N, R = #rec{dropped = D}) -> R#rec{dropped = D + N};
dropped(_, Failed) -> Failed.

%% @doc The recording's file.
-spec path(recording()) -> file:filename_all().
path(#rec{path = P}) -> P;
path({failed, P, _}) -> P.

%% @doc Ends the recording: the file is complete (summary, footer) and
%% readable by any MCAP reader. A recording in a typed profile (`ros2')
%% also says how many messages their type did not take (`unencodable').
-spec close(recording()) -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                   dropped := non_neg_integer(),
                                   unencodable => non_neg_integer()}} | {error, term()}.
close(#rec{path = Path, fd = Fd, log = L, dropped = D, profile = Profile, unencodable = U}) ->
    Result = file:write(Fd, log_end(L)),
    _ = file:close(Fd),
    Counts = #{path => Path, messages => log_messages(L), dropped => D},
    case Result of
        ok when Profile =/= foxglove -> {ok, Counts#{unencodable => U}};
        ok -> {ok, Counts};
        {error, Why} -> {error, {write_failed, Path, Why}}
    end;
close({failed, Path, Why}) ->
    {error, {write_failed, Path, Why}}.

fail(#rec{path = Path, fd = Fd}, Why) ->
    _ = file:close(Fd),
    logger:error("recording to ~ts stopped: ~0p", [Path, Why], #{domain => [toroco, rec]}),
    {failed, Path, Why}.

%%====================================================================
%% Messages to MCAP bytes
%%====================================================================

%% @doc A new file's log and its first bytes.
-spec log_new() -> {iodata(), log()}.
log_new() ->
    log_new(foxglove).

log_new(foxglove) ->
    {Head, W} = toroco_rec_mcap:new(#{}),
    {Head, #log{writer = W}};
log_new(Module) ->
    {Head, W} = toroco_rec_mcap:new(#{profile => Module:mcap_profile()}),
    {Head, #log{writer = W, profile = Module}}.

%% @doc The bytes of one message on channel `Key' at `T' (ns), with the
%% channel's and its schema's records the first time they appear. `Key'
%% is one of the bridge's channels (JSON), or `{Topic, Type}' with a type
%% of the log's profile for its bytes (ROS 2's CDR).
-spec log_event(toroco_rec_channels:key() | {binary(), binary()}, {integer(), binary()}, log()) ->
          {iodata(), log()}.
log_event(Key, {T, Json}, L0) ->
    {Decl, L = #log{writer = W, channels = Chs, seq = Seq}} = declare(Key, L0),
    {Bytes, W1} = toroco_rec_mcap:add_message(W, maps:get(Key, Chs), Seq, max(T, 0), Json),
    {[Decl, Bytes], L#log{writer = W1, seq = Seq + 1}}.

%% @doc The last bytes of the file.
-spec log_end(log()) -> iodata().
log_end(#log{writer = W}) ->
    toroco_rec_mcap:finish(W).

%% @doc Messages logged so far.
-spec log_messages(log()) -> non_neg_integer().
log_messages(#log{writer = W}) ->
    toroco_rec_mcap:message_count(W).

declare(Key, L = #log{channels = Chs}) when is_map_key(Key, Chs) ->
    {[], L};
declare(Key, L = #log{writer = W, channels = Chs, schemas = Ss}) ->
    {Name, SchemaEnc, Schema, Topic, MsgEnc} = channel(Key, L#log.profile),
    {SBytes, W1, Ss1, SId} =
        case Ss of
            #{Name := Id} -> {[], W, Ss, Id};
            #{} ->
                Id = map_size(Ss) + 1,
                {B, W0} = toroco_rec_mcap:add_schema(W, Id, Name, SchemaEnc, Schema),
                {B, W0, Ss#{Name => Id}, Id}
        end,
    CId = map_size(Chs) + 1,
    {CBytes, W2} = toroco_rec_mcap:add_channel(W1, CId, SId, Topic, MsgEnc, #{}),
    {[SBytes, CBytes], L#log{writer = W2, channels = Chs#{Key => CId}, schemas = Ss1}}.

channel({Topic, Type}, Module) when is_binary(Topic) ->
    {ok, {SchemaEnc, Schema, MsgEnc}} = Module:schema(Type),
    {Type, SchemaEnc, Schema, Topic, MsgEnc};
channel(Key, foxglove) ->
    {Name, Schema} = toroco_rec_channels:schema(Key),
    {Name, <<"jsonschema">>, Schema, toroco_rec_channels:topic(Key), <<"json">>}.
