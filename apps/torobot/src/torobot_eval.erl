%% @doc What `make eval' prints and writes: a `torobot_batch' report as a
%% Markdown table, CSV files and SVG plots.
%%
%% {@link write/2} puts in a directory (`_build/eval' for `make eval'):
%% <ul>
%% <li>`report.md': the Markdown table (also printed), one row per world
%%     and the overall row;</li>
%% <li>`worlds.csv' (the same rows) and `runs.csv' (one row per run and
%%     robot);</li>
%% <li>`time_to_red.svg': a histogram of the time to red of the runs that
%%     touched it;</li>
%% <li>`success.svg': the success rate of each world;</li>
%% <li>`trajectories.svg': a grid of every run's trajectory in its world,
%%     titled with the world and the outcome.</li>
%% </ul>
%% {@link main/1} is the Erlang side of `scripts/eval'.
-module(torobot_eval).

-export([main/1, markdown/1, write/2]).
-export([runs_csv/1, worlds_csv/1, histogram_svg/1, success_svg/1, trajectories_svg/1]).

-define(CELL_W, 200).
-define(CELL_H, 170).
-define(COLUMNS, 10).
-define(PLOT_W, 640).
-define(PLOT_H, 300).
-define(PAD, 40).

%% @doc `[N, Seed, Wiring, OutDir, Speed, Runs, Time, Nodes]', as `erl -run'
%% passes them: runs N generated worlds from Seed, prints the table, writes
%% the files, and ends the node (exit 0; 2 when refused, the culprit on
%% stderr). Time is `lockstep' or `realtime' (Speed counts only then);
%% Nodes is empty for this node alone, else node names separated by
%% commas, to which this node (distributed, by `scripts/eval') connects.
%% Without the last two: lockstep on this node.
-spec main([string()]) -> no_return().
main([N, Seed, Wiring, OutDir, Speed, Runs]) ->
    main([N, Seed, Wiring, OutDir, Speed, Runs, "lockstep", ""]);
main([N, Seed, Wiring, OutDir, Speed, Runs, Time, NodeList]) ->
    Nodes = case string:lexemes(NodeList, ", ") of
                [] -> [node()];
                Names -> [list_to_atom(Name) || Name <- Names]
            end,
    _ = [io:format(standard_error, "eval: cannot reach node ~ts (its runs fail)~n", [Node])
         || Node <- Nodes, Node =/= node(), not net_kernel:connect_node(Node)],
    Opts = #{worlds => {generated, list_to_integer(N), list_to_integer(Seed)},
             wiring => Wiring, speed => number(Speed), runs => list_to_integer(Runs),
             time => list_to_atom(Time), nodes => Nodes},
    case torobot_batch:run(Opts) of
        {ok, Report} ->
            ok = write(Report, OutDir),
            io:put_chars(markdown(Report)),
            case Nodes of
                [Here] when Here =:= node() -> ok;
                _ -> io:format("~nRuns dealt to ~ts.~n",
                               [lists:join(", ", [atom_to_list(Nd) || Nd <- Nodes])])
            end,
            io:format("~nwritten to ~ts: report.md worlds.csv runs.csv time_to_red.svg "
                      "success.svg trajectories.svg~n", [OutDir]),
            halt(0);
        {error, Reason} ->
            io:format(standard_error, "eval: refused: ~0p~n", [Reason]),
            halt(2)
    end;
main(Args) ->
    io:format(standard_error, "eval: bad arguments ~p~n", [Args]),
    halt(2).

number(S) ->
    try list_to_integer(S)
    catch error:badarg -> list_to_float(S)
    end.

%% @doc Writes every file of the report into `Dir' (created if missing).
-spec write(torobot_batch:report(), file:name_all()) -> ok | {error, term()}.
write(Report, Dir) ->
    ok = filelib:ensure_path(Dir),
    Files = [{"report.md", markdown(Report)},
             {"worlds.csv", worlds_csv(Report)},
             {"runs.csv", runs_csv(Report)},
             {"time_to_red.svg", histogram_svg(Report)},
             {"success.svg", success_svg(Report)},
             {"trajectories.svg", trajectories_svg(Report)}],
    lists:foldl(fun({Name, Data}, ok) -> file:write_file(filename:join(Dir, Name), Data);
                   (_, Error) -> Error
                end, ok, Files).

%%====================================================================
%% Tables
%%====================================================================

%% @doc The report as a Markdown table, a row per world and the overall.
-spec markdown(torobot_batch:report()) -> iodata().
markdown(#{worlds := Rows, overall := Overall, speed := Speed, wiring := Wiring,
           wall_ms := WallMs, failures := Failures} = Report) ->
    Time = case maps:get(time, Report, realtime) of
               lockstep -> "lockstep";
               realtime -> io_lib:format("real time at speed ~p", [Speed])
           end,
    [io_lib:format("Wiring ~ts, ~s, ~b runs in ~.1f s of wall time.~n~n",
                   [Wiring, Time, maps:get(runs, Overall) + maps:get(failed, Overall),
                    WallMs / 1000]),
     "| world | runs | success | red p50 (s) | red p90 (s) | wall contacts/min | "
     "blue contacts/min | distance (m) |\n",
     "|---|---:|---:|---:|---:|---:|---:|---:|\n",
     [md_row(R, "") || R <- Rows],
     md_row(Overall, "**"),
     case Failures of
         [] -> [];
         _ -> ["\nFailed runs:\n",
               [io_lib:format("- ~ts run ~b: ~0p~n", [W, I, Why]) || {W, I, Why} <- Failures]]
     end].

md_row(#{world := W, runs := N, failed := F, success_rate := S, red_p50_ms := P50,
         red_p90_ms := P90, wall_contacts_per_min := Wc, blue_contacts_per_min := Bc,
         distance_m := D}, Em) ->
    Runs = case F of
               0 -> integer_to_list(N);
               _ -> io_lib:format("~b (+~b failed)", [N, F])
           end,
    io_lib:format("| ~s~ts~s | ~s | ~s~b %~s | ~s | ~s | ~.2f | ~.2f | ~.2f |~n",
                  [Em, W, Em, Runs, Em, round(S * 100), Em, secs(P50), secs(P90), Wc, Bc, D]).

secs(none) -> "-";
secs(Ms) -> io_lib:format("~.1f", [Ms / 1000]).

%% @doc One CSV line per world, with a header.
-spec worlds_csv(torobot_batch:report()) -> iodata().
worlds_csv(#{worlds := Rows, overall := Overall}) ->
    Keys = [world, runs, failed, success_rate, red_p50_ms, red_p90_ms,
            wall_contacts_per_min, blue_contacts_per_min, distance_m],
    csv(Keys, [[maps:get(K, R) || K <- Keys] || R <- Rows ++ [Overall]]).

%% @doc One CSV line per run (and robot), with a header.
-spec runs_csv(torobot_batch:report()) -> iodata().
runs_csv(#{runs := Runs}) ->
    Keys = [red_touched_ms, wall_contacts, blue_contacts, distance_m],
    csv([world, run, robot | Keys] ++ [time_ms],
        [[W, I, Robot | [maps:get(K, S) || K <- Keys]] ++ [T]
         || #{world := W, run := I, robot := Robot, summary := S, time_ms := T} <- Runs]).

csv(Header, Lines) ->
    [lists:join(",", [atom_to_list(H) || H <- Header]), "\n",
     [[lists:join(",", [cell(V) || V <- Line]), "\n"] || Line <- Lines]].

cell(none) -> "";
cell(undefined) -> "";
cell(V) when is_float(V) -> float_to_list(V, [{decimals, 3}, compact]);
cell(V) when is_integer(V) -> integer_to_list(V);
cell(V) when is_atom(V) -> atom_to_list(V);
cell(V) when is_binary(V) -> ["\"", binary:replace(V, <<"\"">>, <<"\"\"">>, [global]), "\""].

%%====================================================================
%% Plots
%%====================================================================

%% @doc A histogram of the time to red (5 s bins) of the runs that touched it.
-spec histogram_svg(torobot_batch:report()) -> iodata().
histogram_svg(#{runs := Runs}) ->
    Reds = [Ms || #{summary := #{red_touched_ms := Ms}} <- Runs, Ms =/= none],
    Bin = 5000,
    Bins = case Reds of
               [] -> 1;
               _ -> lists:max(Reds) div Bin + 1
           end,
    Counts = [length([R || R <- Reds, R div Bin =:= B]) || B <- lists:seq(0, Bins - 1)],
    Top = max(1, lists:max(Counts)),
    BarW = (?PLOT_W - 2 * ?PAD) / Bins,
    Bars = [begin
                Hgt = C / Top * (?PLOT_H - 2 * ?PAD),
                X = ?PAD + I * BarW,
                [rect(X, ?PLOT_H - ?PAD - Hgt, BarW - 2, Hgt, "#d62728"),
                 text(X + BarW / 2, ?PLOT_H - ?PAD + 14, integer_to_list(I * Bin div 1000), middle),
                 case C of
                     0 -> [];
                     _ -> text(X + BarW / 2, ?PLOT_H - ?PAD - Hgt - 4, integer_to_list(C), middle)
                 end]
            end || {I, C} <- lists:zip(lists:seq(0, Bins - 1), Counts)],
    plot(?PLOT_W, ?PLOT_H,
         io_lib:format("Time to red (s, 5 s bins): ~b of ~b runs touched red",
                       [length(Reds), length(Runs)]), Bars).

%% @doc The success rate of each world, one bar each.
-spec success_svg(torobot_batch:report()) -> iodata().
success_svg(#{worlds := Rows}) ->
    N = max(1, length(Rows)),
    Width = max(?PLOT_W, 2 * ?PAD + N * 14),
    BarW = (Width - 2 * ?PAD) / N,
    Bars = [begin
                Hgt = S * (?PLOT_H - 2 * ?PAD),
                X = ?PAD + (I - 1) * BarW,
                [rect(X, ?PLOT_H - ?PAD - Hgt, max(1.0, BarW - 2), Hgt, "#2ca02c"),
                 ["<title>", torobot_svg:escape(W), "</title>"]]
            end || {I, #{world := W, success_rate := S}} <- lists:enumerate(Rows)],
    Axis = [text(?PAD - 6, ?PLOT_H - ?PAD, "0 %", 'end'),
            text(?PAD - 6, ?PAD + 4, "100 %", 'end')],
    plot(Width, ?PLOT_H, io_lib:format("Success (red touched) per world, ~b worlds", [N]),
         [Axis, Bars]).

%% @doc Every run's trajectory in its world, a grid of small pictures.
-spec trajectories_svg(torobot_batch:report()) -> iodata().
trajectories_svg(#{runs := Runs}) ->
    Cells = [cell_svg(I, Run) || {I, Run} <- lists:enumerate(Runs)],
    Rows = max(1, (length(Runs) + ?COLUMNS - 1) div ?COLUMNS),
    Width = min(length(Runs), ?COLUMNS) * ?CELL_W + 10,
    plot(max(Width, ?CELL_W), Rows * ?CELL_H + 30,
         io_lib:format("Trajectories of ~b runs", [length(Runs)]), Cells).

cell_svg(I, #{world := Name, run := Run, robot := Robot, summary := Summary, final := W}) ->
    {Aw, Ah} = torobot_world:arena(W),
    Scale = min((?CELL_W - 20) / Aw, (?CELL_H - 40) / Ah),
    Ox = 5 + ((I - 1) rem ?COLUMNS) * ?CELL_W + 5,
    Oy = 30 + ((I - 1) div ?COLUMNS) * ?CELL_H + 18,
    P = fun({X, Y}) -> {fmt(Ox + X * Scale), fmt(Oy + (Ah - Y) * Scale)} end,
    Line = fun({A, B}) ->
                   {X1, Y1} = P(A),
                   {X2, Y2} = P(B),
                   ["<line x1=\"", X1, "\" y1=\"", Y1, "\" x2=\"", X2, "\" y2=\"", Y2,
                    "\" stroke=\"#222\" stroke-width=\"2\"/>"]
           end,
    Dot = fun(C, R, Style) ->
                  {Cx, Cy} = P(C),
                  ["<circle cx=\"", Cx, "\" cy=\"", Cy, "\" r=\"", fmt(R), "\" ", Style, "/>"]
          end,
    Outcome = case Summary of
                  #{red_touched_ms := none} -> "no red";
                  #{red_touched_ms := Ms} -> io_lib:format("red ~.1f s", [Ms / 1000])
              end,
    Who = case Robot of
              undefined -> "";
              _ -> [" ", atom_to_list(Robot)]
          end,
    Points = [begin {Px, Py} = P({X, Y}), [Px, ",", Py] end
              || {_, X, Y, _} <- thin(torobot_world:trajectory(W))],
    {Sx, Sy, _} = torobot_world:start_pose(W),
    ["<g>",
     text(Ox, Oy - 6, [Name, " #", integer_to_list(Run), Who, ": ", Outcome], start),
     "<rect x=\"", fmt(Ox), "\" y=\"", fmt(Oy), "\" width=\"", fmt(Aw * Scale),
     "\" height=\"", fmt(Ah * Scale), "\" fill=\"#f7f7f2\" stroke=\"#222\" stroke-width=\"2\"/>",
     [Line(Wall) || Wall <- torobot_world:walls(W)],
     [Dot(C, max(1.5, R * Scale), ["fill=\"", colour(Col), "\""])
      || {Col, C, R} <- torobot_world:objects(W)],
     "<polyline fill=\"none\" stroke=\"#ff7f0e\" stroke-width=\"1.2\" points=\"",
     lists:join(" ", Points), "\"/>",
     Dot({Sx, Sy}, 3, "fill=\"none\" stroke=\"#555\""),
     "</g>\n"].

%% A thumbnail needs no more than a point every 250 ms (5 ticks of 50 ms),
%% and the last one.
thin(Samples) when length(Samples) < 3 ->
    Samples;
thin(Samples) ->
    [S || {I, S} <- lists:enumerate(0, Samples), I rem 5 =:= 0] ++ [lists:last(Samples)].

colour(red) -> "#d62728";
colour(blue) -> "#1f77b4".

plot(W, H, Title, Body) ->
    ["<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n",
     "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"", fmt(W),
     "\" height=\"", fmt(H), "\" font-family=\"sans-serif\" font-size=\"11\">\n",
     "<rect x=\"0\" y=\"0\" width=\"", fmt(W), "\" height=\"", fmt(H), "\" fill=\"#ffffff\"/>\n",
     text(10, 18, Title, start), "\n", Body, "</svg>\n"].

rect(X, Y, W, H, Fill) ->
    ["<rect x=\"", fmt(X), "\" y=\"", fmt(Y), "\" width=\"", fmt(W), "\" height=\"", fmt(H),
     "\" fill=\"", Fill, "\"/>"].

text(X, Y, Text, Anchor) ->
    ["<text x=\"", fmt(X), "\" y=\"", fmt(Y), "\" text-anchor=\"", atom_to_list(Anchor), "\">",
     torobot_svg:escape(Text), "</text>"].

fmt(N) when is_integer(N) -> integer_to_list(N);
fmt(N) -> float_to_list(float(N), [{decimals, 1}, compact]).
