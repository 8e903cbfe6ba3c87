%% @doc What `make chaos' prints and writes (SPEC §17): the table, and
%% under the output folder `report.md' (pass rate overall, per fault kind
%% and per world; the failing seeds with the clause they violate and
%% when; the shrunk schedules), `runs.csv' (one line per run) and
%% `pass_rate.svg' (pass rate against fault rate when the rates sweep).
%% Pure but for the writing: the reports come from `torobot_chaos:explore/1'.
-module(torobot_chaos_report).

-export([write/2, table/1, pass_rate/1]).

-type reports() :: [{number() | none, torobot_chaos:report()}].

%% @doc The fraction of runs that held the property.
-spec pass_rate(torobot_chaos:report()) -> float().
pass_rate(#{runs := 0}) -> 0.0;
pass_rate(#{runs := N, passed := P}) -> P / N.

%% @doc The table `make chaos' prints: one line per fault rate.
-spec table(reports()) -> iolist().
table(Reports) ->
    [io_lib:format("~-8s ~6s ~6s ~6s ~9s ~8s~n", ["rate", "runs", "passed", "failed",
                                                  "pass rate", "wall s"]),
     [io_lib:format("~-8s ~6b ~6b ~6b ~8.1f% ~8.1f~n",
                    [rate(Rate), N, P, length(F), 100 * pass_rate(R), W / 1000])
      || {Rate, R = #{runs := N, passed := P, failed := F, wall_ms := W}} <- Reports],
     [shrunk_lines(R) || {_, R} <- Reports],
     [io_lib:format("NONDETERMINISTIC seeds: ~w~n", [ND])
      || {_, #{nondeterministic := ND}} <- Reports, ND =/= []],
     [io_lib:format("~b run(s) could not run, the first (seed ~b): ~0tp~n", [length(E), S, Why])
      || {_, #{errors := E = [#{seed := S, error := Why} | _]}} <- Reports]].

rate(none) -> "-";
rate(R) -> io_lib:format("~p", [R]).

shrunk_lines(#{failed := Failed}) ->
    [[io_lib:format("seed ~b (~ts): ~0tp at ~.3f s; shrunk to ~b fault(s), ~ts:~n",
                    [Seed, World, Clause, At / 1000, length(Lines), Path]),
      [["  ", L, "\n"] || L <- Lines],
      io_lib:format("  violates ~0tp at ~.3f s~n", [C2, A2 / 1000])]
     || #{seed := Seed, world := World, violation := {Clause, At},
          shrunk := #{lines := Lines, replay := Path, violation := {C2, A2}}} <- Failed].

%% @doc Writes `report.md', `runs.csv' and `pass_rate.svg' under `dir'.
-spec write(reports(), map()) -> ok.
write(Reports, Info = #{dir := Dir}) ->
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    ok = file:write_file(filename:join(Dir, "report.md"), markdown(Reports, Info)),
    ok = file:write_file(filename:join(Dir, "runs.csv"), csv(Reports)),
    ok = file:write_file(filename:join(Dir, "pass_rate.svg"), svg(Reports)).

markdown(Reports, Info) ->
    ["# Robustness report\n\n",
     io_lib:format("Wiring `~ts`, world `~ts`, faults `~ts`, property `~ts`.~n~n",
                   [maps:get(wiring, Info), maps:get(world, Info), maps:get(faults, Info),
                    maps:get(property, Info)]),
     "| fault rate (/s) | runs | passed | pass rate | nondeterministic |\n|---|---|---|---|---|\n",
     [io_lib:format("| ~s | ~b | ~b | ~.1f % | ~b |~n",
                    [rate(Rate), N, P, 100 * pass_rate(R), length(ND)])
      || {Rate, R = #{runs := N, passed := P, nondeterministic := ND}} <- Reports],
     [section(Rate, R) || {Rate, R} <- Reports]].

section(Rate, R = #{rows := Rows, failed := Failed}) ->
    [io_lib:format("~n## Fault rate ~s~n~n### Pass rate per fault kind~n~n"
                   "| kind | runs with it | passed | pass rate |~n|---|---|---|---|~n", [rate(Rate)]),
     [io_lib:format("| ~s | ~b | ~b | ~.1f % |~n", [K, N, P, 100 * P / max(N, 1)])
      || {K, N, P} <- per(fun(Row) -> kinds(Row) end, Rows)],
     "\n### Pass rate per world\n\n| world | runs | passed | pass rate |\n|---|---|---|---|\n",
     [io_lib:format("| ~ts | ~b | ~b | ~.1f % |~n", [W, N, P, 100 * P / max(N, 1)])
      || {W, N, P} <- per(fun(#{world := W}) -> [W] end, Rows)],
     "\n### Failing seeds\n\n| seed | world | violated | at (s) | faults |\n|---|---|---|---|---|\n",
     [io_lib:format("| ~b | ~ts | `~0tp` | ~.3f | ~b |~n",
                    [S, W, C, At / 1000, length(Fs)])
      || #{seed := S, world := W, violation := {C, At}, faults := Fs} <- Failed],
     [["\n### Shrunk: seed ", integer_to_list(S), "\n\n```\n", [[L, "\n"] || L <- Lines],
       io_lib:format("```~nviolates `~0tp` at ~.3f s; replay: `make run REPLAY=~ts`~n",
                     [C, At / 1000, P])]
      || #{seed := S, shrunk := #{lines := Lines, violation := {C, At}, replay := P}} <- Failed],
     case maps:get(nondeterministic, R) of
         [] -> "";
         ND -> io_lib:format("~n**Nondeterministic seeds: ~w**~n", [ND])
     end,
     [io_lib:format("~n**Runs that could not run:** seed ~b: `~0tp`~n", [S, Why])
      || #{seed := S, error := Why} <- maps:get(errors, R, [])]].

kinds(#{faults := Fs}) ->
    lists:usort([atom_to_list(element(1, F)) ++ case F of
                                                     {kill, router, _} -> " router";
                                                     {camera, K, _, _} -> " " ++ atom_to_list(K);
                                                     _ -> ""
                                                 end || {at, _, F} <- Fs]).

per(Keys, Rows) ->
    Counts = lists:foldl(fun(Row = #{violation := V}, Acc) ->
                                 Pass = case V of none -> 1; _ -> 0 end,
                                 lists:foldl(fun(K, A) ->
                                                     {N, P} = maps:get(K, A, {0, 0}),
                                                     A#{K => {N + 1, P + Pass}}
                                             end, Acc, Keys(Row))
                         end, #{}, Rows),
    [{K, N, P} || {K, {N, P}} <- lists:sort(maps:to_list(Counts))].

csv(Reports) ->
    ["rate,seed,world,passed,violation,at_ms,faults,sha256\n",
     [[io_lib:format("~s,~b,~ts,~s,\"~0tp\",~s,~b,~ts~n",
                     [rate(Rate), S, W, case V of none -> "true"; _ -> "false" end,
                      case V of none -> none; {C, _} -> C end,
                      case V of none -> ""; {_, At} -> integer_to_list(At) end,
                      length(Fs), Sha])
       || #{seed := S, world := W, violation := V, faults := Fs, sha256 := Sha} <- Rows]
      || {Rate, #{rows := Rows}} <- Reports]].

%% Pass rate (0..100 %) against fault rate, one point per rate.
svg(Reports) ->
    Pts = [{Rate, 100 * pass_rate(R)} || {Rate, R} <- Reports, is_number(Rate)],
    MaxR = lists:max([1 | [R || {R, _} <- Pts]]),
    X = fun(R) -> 60 + 400 * R / MaxR end,
    Y = fun(P) -> 260.0 - 2 * P end,
    ["<svg xmlns='http://www.w3.org/2000/svg' width='500' height='300' font-family='sans-serif' font-size='12'>\n",
     "<rect width='500' height='300' fill='white'/>\n",
     "<line x1='60' y1='260' x2='470' y2='260' stroke='black'/><line x1='60' y1='60' x2='60' y2='260' stroke='black'/>\n",
     "<text x='200' y='290'>faults per simulated second</text>\n",
     "<text x='5' y='55'>pass rate (%)</text>\n",
     [io_lib:format("<text x='30' y='~.1f'>~b</text>~n", [Y(P) + 4, P]) || P <- [0, 50, 100]],
     [io_lib:format("<text x='~.1f' y='275'>~p</text>~n", [X(R) - 8, R]) || {R, _} <- Pts],
     case Pts of
         [] -> "";
         _ -> ["<polyline fill='none' stroke='steelblue' stroke-width='2' points='",
               [io_lib:format("~.1f,~.1f ", [X(R), Y(P)]) || {R, P} <- Pts], "'/>\n"]
     end,
     [io_lib:format("<circle cx='~.1f' cy='~.1f' r='4' fill='steelblue'/>~n", [X(R), Y(P)])
      || {R, P} <- Pts],
     "</svg>\n"].
