%% @doc The API of `toroco_live' (SPEC §11, §12): what a person looks at.
%%
%% <b>Recordings</b> (SPEC §12): {@link record/2}, {@link stop_recording/0}
%% (MCAP files, `toroco_live_recorder'), {@link dump/1} (the flight
%% recorder, `toroco_live_flight'), {@link replay/2}
%% (`toroco_live_replay'). The Foxglove bridge is `toroco_live_foxglove'.
-module(toroco_live).

-export([record/2, stop_recording/0, dump/1, replay/2]).

%%====================================================================
%% Recordings
%%====================================================================

%% @doc Records the events of `kinds' (default all) about `names' (default
%% all) to an MCAP file with the Foxglove bridge's channels and schemas.
%% Writing never holds up the robot: past a bounded buffer events are
%% dropped and counted.
-spec record(file:filename_all(), #{kinds => [emit | deliver | router | lifecycle],
                                    names => all | [atom()]}) -> ok | {error, term()}.
record(Path, Opts) ->
    toroco_live_recorder:record(Path, Opts).

%% @doc Ends the recording and completes the file.
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer()}} | {error, term()}.
stop_recording() ->
    toroco_live_recorder:stop_recording().

%% @doc Writes the flight recorder's last `flight_seconds' to `Path'.
-spec dump(file:filename_all()) -> {ok, #{messages := non_neg_integer(), path := file:filename_all()}}
                                       | {error, term()}.
dump(Path) ->
    toroco_live_flight:dump(Path).

%% @doc Re-emits a recording's events of `sources' into the running wiring
%% at their recorded pace and compares the actuators' deliveries.
-spec replay(file:filename_all(), #{sources := [atom()]}) ->
          {ok, #{replayed := non_neg_integer(), matched := non_neg_integer(),
                 differed := [map()]}} | {error, term()}.
replay(Path, Opts) ->
    toroco_live_replay:replay(Path, Opts).
