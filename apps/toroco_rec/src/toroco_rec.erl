%% @doc The public API of `toroco_rec' (SPEC §12): recordings of the
%% robot's events. `toroco_live:record/2', `stop_recording/0', `dump/1' and
%% `replay/2', the names SPEC §12 gives, call these.
%%
%% {@link record/2}, {@link stop_recording/0}: an MCAP file with the
%% Foxglove bridge's channels and schemas (`toroco_rec_recorder'), or in
%% a profile another application added ({@link add_profile/2}: `ros2',
%% `toroco_ros'). {@link dump/1}: the flight recorder's last seconds
%% (`toroco_rec_flight', always on while the application runs).
%% {@link replay/2}: a recording's sensors re-emitted into the running
%% wiring, the actuators' deliveries compared (`toroco_rec_replay').
%%
%% <b>Built on it</b> (documented as API, for `toroco_live' and
%% `toroco_ros'): `toroco_rec_json' (terms as JSON, SPEC §11),
%% `toroco_rec_channels' (the channels of SPEC §12), `toroco_rec_tap' (the
%% observer tap's client), `toroco_rec_mcap' (the file format),
%% `toroco_rec_profile' (a recording profile, a behaviour) and
%% `toroco_rec_world' (where the simulated world's snapshots come from).
-module(toroco_rec).

-export([record/2, stop_recording/0, dump/1, replay/2, window/0]).
-export([add_profile/2, remove_profile/1]).

%% @doc Records the events of `kinds' (default all) about `names' (default
%% all) to an MCAP file. `profile' `foxglove' (the default): the Foxglove
%% bridge's channels and JSON Schemas; another (`ros2', SPEC §15) is the
%% module added under that name ({@link add_profile/2}). Writing never
%% holds up the robot: past a bounded buffer events are dropped and
%% counted. `{error, {bad_option, {profile, V}}}' for a profile nobody
%% added; `{error, {already_recording, Path, NewPath}}' while one runs.
-spec record(file:filename_all(), #{kinds => [emit | deliver | router | lifecycle],
                                    names => all | [atom()],
                                    profile => atom()}) -> ok | {error, term()}.
record(Path, Opts) ->
    toroco_rec_flight:record(Path, Opts).

%% @doc Ends the recording and completes the file.
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer(),
                                 unencodable => non_neg_integer()}} | {error, term()}.
stop_recording() ->
    toroco_rec_flight:stop_recording().

%% @doc Writes the flight recorder's last `flight_seconds' to `Path'.
-spec dump(file:filename_all()) ->
          {ok, #{messages := non_neg_integer(), path := file:filename_all()}} | {error, term()}.
dump(Path) ->
    toroco_rec_flight:dump(Path).

%% @doc Re-emits a recording's events of `sources' into the running wiring
%% at their recorded pace and compares the actuators' deliveries.
-spec replay(file:filename_all(), #{sources := [atom()]}) ->
          {ok, #{replayed := non_neg_integer(), matched := non_neg_integer(),
                 differed := [map()]}} | {error, term()}.
replay(Path, Opts) ->
    toroco_rec_replay:replay(Path, Opts).

%% @doc What the flight recorder holds now (`toroco_rec_flight:window/0').
-spec window() -> #{events := non_neg_integer(), bytes := non_neg_integer(),
                    segments := non_neg_integer(), dropped := non_neg_integer()}.
window() ->
    toroco_rec_flight:window().

%% @doc Adds (or replaces) the recording profile `Name', a module of the
%% `toroco_rec_profile' behaviour; an application adds its own as it starts.
-spec add_profile(atom(), module()) -> ok.
add_profile(Name, Module) ->
    toroco_rec_profile:add(Name, Module).

%% @doc Takes profile `Name' away; `ok' also when there is none.
-spec remove_profile(atom()) -> ok.
remove_profile(Name) ->
    toroco_rec_profile:remove(Name).
