%% The benchmark's recording section (`make bench'): the internal test's
%% chain (source → relay → sink, toroco_bench) with and without an MCAP
%% recording of every event, in the same run: closed-loop latency and
%% rate, open-loop throughput with a bounded window, the thesis' 10 ms
%% pacing (dropped events), and the MCAP bytes per recorded event.
%% `toroco_live' (and so its flight recorder) runs only in the recording
%% rows; the rows without it are the reference.
-module(toroco_bench_live).
-export([main/1]).

main([Dir]) ->
    Quick = toroco_bench:setup(Dir),
    N = case Quick of true -> 2000; false -> 10000 end,
    Paced = case Quick of true -> 300; false -> 3000 end,
    Window = case Quick of true -> 50000; false -> 300000 end,
    File = filename:join(Dir, "recording.mcap"),
    Closed = [closed(Rec, N, Dir, File) || Rec <- [false, true, false, true]],
    Flight = closed(flight, N, Dir, File),
    toroco_bench:table("Recording: closed loop, not recording and recording every event "
                       "(alternating, same run), " ++ integer_to_list(N) ++ " events",
                       [R || {R, _} <- Closed ++ [Flight]], Dir, "recording_closed"),
    Pace = [paced(Rec, Paced, Dir, File) || Rec <- [false, true]],
    toroco_bench:table("Recording at the thesis' 10 ms pacing, " ++ integer_to_list(Paced) ++ " events",
                       [R || {R, _} <- Pace], Dir, "recording_paced"),
    Tput = [window(Rec, Window, File) || Rec <- [false, true]],
    io:format("~n### Recording: open-loop throughput (window 1000), ~b events~n~n"
              "| recording | events/s | CPU % | lost |~n|---|---:|---:|---:|~n", [Window]),
    [io:format("| ~ts | ~w | ~w | ~w |~n", [L, Rate, round(Cpu), Lost])
     || {#{label := L, rate := Rate, cpu := Cpu, lost := Lost}, _} <- Tput],
    Files = [F || {_, F = #{}} <- Closed ++ Pace ++ Tput],
    io:format("~n### MCAP recordings~n~n| run | messages | dropped | bytes | bytes per message |~n"
              "|---|---:|---:|---:|---:|~n"),
    [io:format("| ~ts | ~w | ~w | ~w | ~.1f |~n", [L, M, D, B, B / max(1, M)])
     || #{label := L, messages := M, dropped := D, bytes := B} <- Files],
    [Off1, On1, Off2, On2] = [R || {R, _} <- Closed],
    Ratio = fun(K) -> (maps:get(K, On1) + maps:get(K, On2)) / max(1.0e-9, maps:get(K, Off1) + maps:get(K, Off2)) end,
    io:format("~nRecording against not: closed-loop mean latency x~.2f (target <= 1.5), "
              "rate x~.2f (target >= 0.5)~n", [Ratio(avg), Ratio(rate)]),
    halt(0).

closed(Rec, N, Dir, File) ->
    toroco_bench:chain(closed, N),
    with_recording(Rec, File, label(Rec, "closed"),
                   fun() -> toroco_bench:row(label(Rec, "closed"), toroco_bench:run(closed, N, N * 20 + 10000),
                                             Dir, "recording_closed_" ++ atom_to_list(Rec)) end).

paced(Rec, N, Dir, File) ->
    toroco_bench:chain(none, N),
    with_recording(Rec, File, label(Rec, "10 ms"),
                   fun() -> toroco_bench:row(label(Rec, "10 ms"), toroco_bench:run({paced, 10}, N, N * 20 + 10000),
                                             Dir, "recording_paced_" ++ atom_to_list(Rec)) end).

window(Rec, N, File) ->
    toroco_bench:chain({window, 100}, N),
    with_recording(Rec, File, label(Rec, "window"),
                   fun() ->
                           R = #{wall_ns := Ns} = toroco_bench:run({window, 1000}, N, 120000),
                           #{label => label(Rec, "window"), rate => round(N / (Ns / 1.0e9)),
                             cpu => maps:get(cpu, R), lost => maps:get(lost, R, 0)}
                   end).

label(false, What) -> What ++ ", not recording";
label(flight, What) -> What ++ ", flight recorder only";
label(true, What) -> What ++ ", recording".

with_recording(false, _File, _Label, Run) ->
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {Run(), none};
with_recording(flight, _File, _Label, Run) ->
    start_live(),
    Row = Run(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {Row, none};
with_recording(true, File, Label, Run) ->
    start_live(),
    ok = toroco_live:record(File, #{}),
    Row = Run(),
    {ok, #{messages := M, dropped := D}} = toroco_live:stop_recording(),
    _ = application:stop(toroco_live),
    _ = application:stop(toroco_rec),
    {Row#{lost => maps:get(lost, Row) + D},
     #{label => Label, messages => M, dropped => D, bytes => filelib:file_size(File)}}.

%% The recorders only: no dashboard or bridge listening.
start_live() ->
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_live).
