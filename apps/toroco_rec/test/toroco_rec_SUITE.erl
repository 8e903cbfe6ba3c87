%% Recording, the flight recorder and replay (SPEC §12, the application
%% toroco_rec), through the names SPEC §12 gives them (toroco_live's), read
%% back with the format's reference reader (@mcap/core's indexed reader, in
%% Node).
-module(toroco_rec_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

all() ->
    [recording_reads_back, recording_filters, unwritable_path_refused, full_disk_refused,
     flight_recorder_dump, stop_takes_in_every_emission, dump_takes_in_every_emission,
     flight_recorder_bounded, flight_recorder_across_segments,
     flight_recorder_bounded_by_count, flight_recorder_window_by_time,
     flight_recorder_on_layer_removed,
     flight_recorder_after_restart,
     foreign_files_refused,
     simulated_run_replays,
     recording_in_lockstep_has_simulated_time, lockstep_run_recorded_every_tick,
     other_profiles_refused, runs_with_the_dashboard].

suite() -> [{timetrap, {seconds, 90}}].

init_per_suite(Config) ->
    LogDir = filename:join(?config(priv_dir, Config), "log"),
    [{log_dir, LogDir}, {env, tl_live:start(#{log_dir => LogDir})} | Config].

end_per_suite(Config) ->
    tl_live:stop(?config(env, Config)).

init_per_testcase(C, Config) when C =:= simulated_run_replays;
                                  C =:= lockstep_run_recorded_every_tick ->
    Config;
init_per_testcase(_Case, Config) ->
    tl_live:fake_robot(),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = toroco_live:stop_recording(),
    _ = toroco_clock:realtime(),
    toroco_test_lib:clear().

%%====================================================================
%% Cases
%%====================================================================

runs_with_the_dashboard() ->
    [{doc, "Starting toroco_live starts toroco_rec first (its flight recorder runs), and "
      "toroco_live_world is the source of the world's snapshots it reads"}].
runs_with_the_dashboard(_Config) ->
    Apps = [A || {A, _, _} <- application:which_applications()],
    ?assert(lists:member(toroco_rec, Apps)),
    ?assert(is_pid(whereis(toroco_rec_flight))),
    ?assertEqual(toroco_live_world, toroco_rec_world:source()),
    #{events := _, dropped := 0} = toroco_rec:window().

recording_in_lockstep_has_simulated_time() ->
    [{doc, "A recording made while a world is the clock (lockstep, SPEC §14) stamps its "
      "messages with simulated time: an emission at 1.5 s is logged at 1.5e9 ns."}].
recording_in_lockstep_has_simulated_time(Config) ->
    ok = toroco_clock:lockstep(#{}),
    Path = path(Config, "lockstep.mcap"),
    ok = toroco_live:record(Path, #{kinds => [emit], names => [s]}),
    {ok, _} = toroco_clock:tick(1500, []),
    ok = toroco:inject({s, dist}, far),
    ok = toroco_clock:settle(),
    {ok, #{messages := 1}} = toroco_live:stop_recording(),
    {ok, Bin} = file:read_file(Path),
    {ok, #{messages := [#{log_time := T}]}} = toroco_rec_mcap:read(Bin),
    1500000000 = T.

lockstep_run_recorded_every_tick() ->
    [{doc, "A recording of a simulated run in lockstep has the robot's pose at every tick "
      "of the world (/toroco/sim/pose), stamped with its simulated time, so a replayed or "
      "recorded failure of the robustness lab can be watched in Foxglove."}].
lockstep_run_recorded_every_tick(Config) ->
    World = filename:join(?config(data_dir, Config), "short.world"),
    {ok, [W]} = torobot_world:load_all(World),
    Path = path(Config, "lockstep_sim.mcap"),
    ok = toroco_live:record(Path, #{}),
    {ok, #{red_touched_ms := Red}} = torobot_sim:run(World, #{wiring => tl_live:wiring_file(),
                                                             time => lockstep}),
    {ok, #{dropped := 0}} = toroco_live:stop_recording(),
    Ticks = case Red of
                none -> torobot_world:duration_ms(W);
                _ -> Red
            end div torobot_world:tick_ms(W),
    {ok, Bin} = file:read_file(Path),
    {ok, #{messages := Msgs, channels := Channels}} = toroco_rec_mcap:read(Bin),
    [Pose] = [Id || {Id, #{topic := <<"/toroco/sim/pose">>}} <- maps:to_list(Channels)],
    Times = [T || #{channel := C, log_time := T} <- Msgs, C =:= Pose],
    ct:log("~b poses for ~b ticks, first at ~p ns", [length(Times), Ticks, hd(lists:sort(Times))]),
    %% simulated time: one pose a tick, stamped with the tick's end, from the
    %% first tick to the run's last, none past the world's end
    Tick = torobot_world:tick_ms(W) * 1000000,
    ?assertEqual([K * Tick || K <- lists:seq(1, Ticks)], lists:sort(Times)),
    ?assert(lists:max(Times) =< torobot_world:duration_ms(W) * 1000000).

recording_reads_back() ->
    [{doc, "A recording validates with @mcap/core's indexed reader: the channels and schemas "
      "are there, the message count equals what stop_recording/0 reports, and it holds "
      "exactly one emission and one delivery per value, some 100 bytes a message"}].
recording_reads_back(Config) ->
    Path = path(Config, "values.mcap"),
    ok = toroco_live:record(Path, #{}),
    {error, {already_recording, _, _}} = toroco_live:record(path(Config, "other.mcap"), #{}),
    N = 3000,
    [ok = toroco:inject({s, dist}, {I, near}) || I <- lists:seq(1, N)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 10000),
    {ok, #{path := Path, messages := Messages, dropped := 0}} = toroco_live:stop_recording(),
    {error, not_recording} = toroco_live:stop_recording(),
    R = read(Path),
    ct:log("~p", [maps:without([<<"first">>], R)]),
    #{<<"ok">> := true, <<"messages">> := Messages, <<"statistics">> := Messages,
      <<"ordered">> := true, <<"perTopic">> := PerTopic, <<"first">> := First} = R,
    true = maps:get(<<"chunks">>, R) > 1,
    %% each value once as s's emission and once as a's delivery; momentary
    %% events change no winner, hold or latch of a's router: no router topic
    ?assertEqual(#{<<"/toroco/out/s/dist">> => N, <<"/toroco/in/a/d">> => N}, PerTopic),
    ?assertEqual(2 * N, Messages),
    Topics = [T || #{<<"topic">> := T} <- maps:get(<<"channels">>, R)],
    [] = [<<"/toroco/out/s/dist">>, <<"/toroco/in/a/d">>] -- Topics,
    [true] = lists:usort([V || #{<<"valid">> := V} <- maps:get(<<"schemas">>, R)]),
    [#{<<"kind">> := <<"send">>, <<"term">> := <<"{1,near}">>, <<"value">> := [1, <<"near">>]} | _] =
        maps:get(<<"/toroco/out/s/dist">>, First),
    Size = filelib:file_size(Path),
    ct:log("~b messages in ~b bytes: ~.1f bytes per message", [Messages, Size, Size / Messages]),
    %% compact: some 100 bytes a message (chunks, index and schemas included)
    ?assert(Size < 200 * Messages, {Size, Messages}).

recording_filters() ->
    [{doc, "kinds and names narrow a recording to those events"}].
recording_filters(Config) ->
    Path = path(Config, "filtered.mcap"),
    ok = toroco_live:record(Path, #{kinds => [emit], names => [s]}),
    [ok = toroco:inject({s, dist}, I) || I <- lists:seq(1, 10)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 10 end, 5000),
    {ok, #{messages := 10}} = toroco_live:stop_recording(),
    #{<<"ok">> := true, <<"perTopic">> := #{<<"/toroco/out/s/dist">> := 10} = P} = read(Path),
    1 = map_size(P),
    {error, {bad_option, {kinds, [sideways]}}} = toroco_live:record(Path, #{kinds => [sideways]}),
    ok.

unwritable_path_refused() ->
    [{doc, "A path that cannot be written is refused with a reason and the robot runs on"}].
unwritable_path_refused(Config) ->
    Path = filename:join([?config(priv_dir, Config), "no", "such", "dir", "x.mcap"]),
    {error, {cannot_write, Path, enoent}} = toroco_live:record(Path, #{}),
    ok = toroco:inject({s, dist}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    {error, not_recording} = toroco_live:stop_recording(),
    ok.

full_disk_refused() ->
    [{doc, "A full disk (/dev/full) is an error, not a crash, and the robot runs on"}].
full_disk_refused(_Config) ->
    {error, {cannot_write, "/dev/full", enospc}} = toroco_live:record("/dev/full", #{}),
    ok = toroco:inject({s, dist}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    ok.

flight_recorder_dump() ->
    [{doc, "The flight recorder, always on, dumps the last seconds as MCAP on demand"}].
flight_recorder_dump(Config) ->
    [ok = toroco:inject({s, dist}, {flight, I}) || I <- lists:seq(1, 20)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 20 end, 5000),
    Path = path(Config, "flight.mcap"),
    {ok, #{messages := N}} = toroco_live:dump(Path),
    #{<<"ok">> := true, <<"messages">> := N, <<"last">> := Last} = read(Path),
    Terms = [T || #{<<"term">> := T} <- maps:get(<<"/toroco/out/s/dist">>, Last)],
    true = lists:member(<<"{flight,20}">>, Terms),
    ok.

stop_takes_in_every_emission() ->
    [{doc, "stop_recording/0 right after 200 emissions has them all: those still in their "
      "producer's batch or the tap's feeder are taken in before the file is closed."}].
stop_takes_in_every_emission(Config) ->
    Path = path(Config, "right_after.mcap"),
    ok = toroco_live:record(Path, #{kinds => [emit], names => [s]}),
    [ok = toroco:inject({s, dist}, I) || I <- lists:seq(1, 200)],
    {ok, #{messages := 200, dropped := 0}} = toroco_live:stop_recording(),
    #{<<"ok">> := true, <<"perTopic">> := #{<<"/toroco/out/s/dist">> := 200}} = read(Path).

dump_takes_in_every_emission() ->
    [{doc, "A dump right after an emission has it, though it was still on its way."}].
dump_takes_in_every_emission(Config) ->
    Path = path(Config, "dump_right_after.mcap"),
    [ok = toroco:inject({s, dist}, {right_after, I}) || I <- lists:seq(1, 5)],
    {ok, _} = toroco_live:dump(Path),
    #{<<"ok">> := true, <<"last">> := Last} = read(Path),
    Terms = [T || #{<<"term">> := T} <- maps:get(<<"/toroco/out/s/dist">>, Last)],
    true = lists:member(<<"{right_after,5}">>, Terms).

flight_recorder_bounded() ->
    [{doc, "The flight recorder keeps at most flight_max_bytes of events, counted compressed, "
      "the newest, oldest segments going first"}].
flight_recorder_bounded(Config) ->
    MaxBytes = 200000,
    with_flight_env(flight_max_bytes, MaxBytes, fun() ->
        %% 1 kB that does not compress, one per value: emitted and
        %% delivered, the two events share it in their segment.
        N = 2000,
        [ok = toroco:inject({s, dist}, {I, rand:bytes(1000)}) || I <- lists:seq(1, N)],
        ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 10000),
        #{bytes := Bytes, segments := Segments} = W = toroco_rec:window(),
        ct:log("window ~p", [W]),
        true = Bytes =< MaxBytes,
        %% Whole segments go: the window is the bound less at most a segment.
        true = Bytes > MaxBytes div 2 andalso Segments > 4,
        Path = path(Config, "bounded.mcap"),
        {ok, #{messages := M}} = toroco_live:dump(Path),
        Kept = [I || {I, _} <- terms(Path, <<"/toroco/out/s/dist">>)],
        Delivered = [I || {I, _} <- terms(Path, <<"/toroco/in/a/d">>)],
        ct:log("~b values of 1 kB, ~b messages: the last ~b emitted, the last ~b delivered",
               [N, M, length(Kept), length(Delivered)]),
        %% 200 kB hold some 200 values' kB: 200 events when the
        %% emitter's all came before the actuator's, up to 400 when a
        %% value's two events sit side by side and compress as one. The
        %% newest, in order, none missing.
        true = M > 150 andalso M < 450,
        Kept = lists:seq(N - length(Kept) + 1, N),
        Delivered = lists:seq(N - length(Delivered) + 1, N),
        true = Delivered =/= [],
        #{<<"ok">> := true, <<"messages">> := M} = read(Path)
    end).

flight_recorder_across_segments() ->
    [{doc, "A dump holds every event of the window in order across the segments it is kept in"}].
flight_recorder_across_segments(Config) ->
    with_flight_env(flight_seconds, 30, fun() ->
        N = 3000,
        [ok = toroco:inject({s, dist}, {I, near}) || I <- lists:seq(1, N)],
        ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 10000),
        %% Each value is emitted and delivered: more than five segments
        %% once the last events, batched by their producers, are in.
        W = window_until(fun(#{segments := Segments}) -> Segments > 5 end, 5000),
        ct:log("window ~p", [W]),
        Path = path(Config, "segments.mcap"),
        {ok, #{messages := M}} = toroco_live:dump(Path),
        All = [{I, near} || I <- lists:seq(1, N)],
        All = terms(Path, <<"/toroco/out/s/dist">>),
        #{<<"ok">> := true, <<"messages">> := M, <<"ordered">> := true,
          <<"perTopic">> := #{<<"/toroco/in/a/d">> := N}} = read(Path)
    end).

flight_recorder_bounded_by_count() ->
    [{doc, "The flight recorder keeps at most flight_max_events events, the newest"}].
flight_recorder_bounded_by_count(Config) ->
    Max = 1500,
    with_flight_env(flight_max_events, Max, fun() ->
        N = 2000,
        [ok = toroco:inject({s, dist}, {I, near}) || I <- lists:seq(1, N)],
        ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= N end, 10000),
        #{events := Max} = toroco_rec:window(),
        Path = path(Config, "count.mcap"),
        {ok, #{messages := M}} = toroco_live:dump(Path),
        Kept = [I || {I, near} <- terms(Path, <<"/toroco/out/s/dist">>)],
        ct:log("~b values, ~b messages and the last ~b values kept", [N, M, length(Kept)]),
        true = M =< Max andalso M > Max - 10,
        Kept = lists:seq(N - length(Kept) + 1, N)
    end).

flight_recorder_window_by_time() ->
    [{doc, "A dump holds the last flight_seconds only, also when older events share "
      "a segment with newer ones"}].
flight_recorder_window_by_time(Config) ->
    with_flight_env(flight_seconds, 1, fun() ->
        [ok = toroco:inject({s, dist}, {old, I}) || I <- lists:seq(1, 10)],
        ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 10 end, 5000),
        %% The window's length must pass: nothing to wait on but the clock.
        toroco_test_lib:quiet(1200),
        [ok = toroco:inject({s, dist}, {new, I}) || I <- lists:seq(1, 10)],
        ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 20 end, 5000),
        Path = path(Config, "time.mcap"),
        {ok, #{messages := M}} = toroco_live:dump(Path),
        New = [{new, I} || I <- lists:seq(1, 10)],
        New = terms(Path, <<"/toroco/out/s/dist">>),
        #{<<"ok">> := true, <<"messages">> := M} = read(Path)
    end).

%% The flight recorder's window once Pred holds of it (or fails).
window_until(Pred, Timeout) ->
    ok = toroco_test_lib:wait_until(fun() -> Pred(toroco_rec:window()) end, Timeout,
                                    flight_window),
    W = toroco_rec:window(),
    true = Pred(W),
    W.

%% Runs Fun with a fresh flight recorder under app env Key = Value, the
%% key put back as it was after.
with_flight_env(Key, Value, Fun) ->
    Was = application:get_env(toroco_live, Key),
    ok = application:set_env(toroco_live, Key, Value),
    try
        restart_flight(),
        Fun()
    after
        toroco_test_lib:restore_env(toroco_live, Key, Was),
        restart_flight()
    end.

%% The terms of a dump's messages on Topic, in the file's order.
terms(Path, Topic) ->
    {ok, Bin} = file:read_file(Path),
    {ok, #{channels := Channels, messages := Messages}} = toroco_rec_mcap:read(Bin),
    Ids = [Id || {Id, #{topic := T}} <- maps:to_list(Channels), T =:= Topic],
    [begin
         #{<<"term">> := Text} = jiffy:decode(Data, [return_maps]),
         {ok, Term} = toroco_rec_json:parse_term(Text),
         Term
     end || #{channel := C, data := Data} <- Messages, lists:member(C, Ids)].

restart_flight() ->
    ok = supervisor:terminate_child(toroco_rec_sup, toroco_rec_flight),
    {ok, _} = supervisor:restart_child(toroco_rec_sup, toroco_rec_flight).

flight_recorder_on_layer_removed() ->
    [{doc, "When a layer is taken out the flight recorder dumps into the log directory "
      "by itself, and the log line names the file"}].
flight_recorder_on_layer_removed(Config) ->
    ok = logger:add_handler(flight_capture, ?MODULE, #{config => self()}),
    try
        ok = toroco:add_behavior(crasher, tl_crasher, #{layer => 3, params => #{after_ms => 20}}),
        Line = receive {flight_log, L} -> L after 20000 -> ct:fail(no_log_line) end,
        ct:log("~ts", [Line]),
        [File] = filelib:wildcard(filename:join(?config(log_dir, Config), "flight-*-layer3.mcap")),
        true = nomatch =/= string:find(Line, File),
        #{<<"ok">> := true, <<"perTopic">> := P} = read(File),
        true = maps:get(<<"/toroco/lifecycle">>, P) > 0
    after
        logger:remove_handler(flight_capture)
    end.

flight_recorder_after_restart() ->
    [{doc, "The flight recorder stays on when the runtime restarts under it"}].
flight_recorder_after_restart(Config) ->
    ok = application:stop(toroco_hw),
    ok = application:stop(toroco),
    {ok, _} = application:ensure_all_started(toroco_hw),
    tl_live:fake_robot(),
    Path = path(Config, "after_restart.mcap"),
    Dumped = fun() ->
                     ok = toroco:inject({s, dist}, after_restart),
                     {ok, _} = toroco_live:dump(Path),
                     #{<<"last">> := Last} = read(Path),
                     lists:member(#{<<"kind">> => <<"send">>, <<"value">> => <<"after_restart">>,
                                    <<"term">> => <<"after_restart">>},
                                  maps:get(<<"/toroco/out/s/dist">>, Last, []))
             end,
    ok = toroco_test_lib:poll(Dumped, 10000, 200),
    ok.

%% logger handler: sends the flight recorder's line to the test.
log(#{msg := {Fmt, Args}, meta := #{domain := [toroco, rec]}}, #{config := Pid}) ->
    Line = lists:flatten(io_lib:format(Fmt, Args)),
    case string:find(Line, "flight recorder wrote") of
        nomatch -> ok;
        _ -> Pid ! {flight_log, Line}
    end;
log(_, _) -> ok.

foreign_files_refused() ->
    [{doc, "replay/2 refuses, with a reason and no crash, a truncated recording, random "
      "bytes, and a valid MCAP file another program wrote"}].
foreign_files_refused(Config) ->
    Path = path(Config, "whole.mcap"),
    ok = toroco_live:record(Path, #{}),
    [ok = toroco:inject({s, dist}, I) || I <- lists:seq(1, 200)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 200 end, 5000),
    {ok, _} = toroco_live:stop_recording(),
    {ok, Bin} = file:read_file(Path),
    Truncated = path(Config, "truncated.mcap"),
    ok = file:write_file(Truncated, binary:part(Bin, 0, byte_size(Bin) * 2 div 3)),
    {error, {not_mcap, truncated}} = toroco_live:replay(Truncated, #{sources => [s]}),
    Random = path(Config, "random.mcap"),
    ok = file:write_file(Random, crypto:strong_rand_bytes(4096)),
    {error, {not_mcap, no_magic}} = toroco_live:replay(Random, #{sources => [s]}),
    Flipped = path(Config, "flipped.mcap"),
    <<Head:100/binary, B, Rest/binary>> = Bin,
    ok = file:write_file(Flipped, <<Head/binary, (B bxor 1), Rest/binary>>),
    {error, {not_mcap, _}} = toroco_live:replay(Flipped, #{sources => [s]}),
    Foreign = path(Config, "foreign.mcap"),
    #{<<"ok">> := true} = toroco_live_js:run("mcap_write_foreign.js", [Foreign]),
    {error, {not_a_toroco_recording, <<"someone else">>}} =
        toroco_live:replay(Foreign, #{sources => [s]}),
    {error, {cannot_read, _, enoent}} = toroco_live:replay(path(Config, "none.mcap"), #{sources => [s]}),
    ok.

simulated_run_replays() ->
    [{doc, "A recording of a short simulated run has the robot's pose and arena, and "
      "replays onto the same wiring with fake sensors and motors, the motors' deliveries "
      "matching the recording"}].
simulated_run_replays(Config) ->
    World = filename:join(?config(data_dir, Config), "short.world"),
    WiringFile = tl_live:wiring_file(),
    Path = path(Config, "sim.mcap"),
    ok = toroco_live:record(Path, #{}),
    {ok, Summary} = torobot_sim:run(World, #{wiring => WiringFile}),
    ok = tl_live:settle_robot(),
    {ok, #{messages := M, dropped := 0}} = toroco_live:stop_recording(),
    ct:log("run ~p, ~b messages, ~b bytes", [Summary, M, filelib:file_size(Path)]),
    #{<<"ok">> := true, <<"messages">> := M, <<"perTopic">> := P} = read(Path),
    true = maps:get(<<"/toroco/in/motors/setvel">>, P) > 0,
    %% The world's snapshots, for the 3D panel.
    true = maps:get(<<"/toroco/sim/pose">>, P, 0) > 0,
    true = maps:get(<<"/toroco/sim/scene">>, P, 0) > 0,
    tl_live:replays_on_fakes(Path, WiringFile).

other_profiles_refused() ->
    [{doc, "A profile nobody added (ros1; ros2 while toroco_ros does not run) is refused, naming it, "
      "and nothing is recorded"}].
other_profiles_refused(Config) ->
    Path = path(Config, "ros1.mcap"),
    {error, {bad_option, {profile, ros1}}} = toroco_live:record(Path, #{profile => ros1}),
    {error, {bad_option, {profile, "ros2"}}} = toroco_live:record(Path, #{profile => "ros2"}),
    {error, {bad_option, {profile, ros2}}} = toroco_live:record(Path, #{profile => ros2}),
    false = filelib:is_file(Path),
    {error, not_recording} = toroco_live:stop_recording(),
    %% the default profile, named, is today's file
    ok = toroco_live:record(Path, #{profile => foxglove}),
    ok = toroco:inject({s, dist}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) =:= 1 end, 5000),
    {ok, #{messages := N}} = toroco_live:stop_recording(),
    #{<<"ok">> := true, <<"messages">> := N, <<"header">> := #{<<"profile">> := <<>>}} = read(Path),
    ok.

%%====================================================================
%% Helpers
%%====================================================================

path(Config, Name) -> filename:join(?config(priv_dir, Config), Name).

read(Path) -> toroco_live_js:run("mcap_read.js", [Path]).

root() ->
    toroco_test_lib:root().
