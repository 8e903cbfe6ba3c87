%% The simulated lab's benchmark (a section of `make bench'): how fast a
%% world can run and keep the outcome it has in real time, and how many
%% robots a world holds on this machine. Prints Markdown tables and writes
%% CSV files under the results directory.
%%
%% `main/1' takes the results directory and the root of the checkout; env
%% `TOROCO_BENCH_QUICK=1' tries fewer speeds and robot counts.
-module(torobot_lab_bench).
-export([main/1]).

main([Dir, Root]) ->
    Quick = toroco_bench:setup(Dir),
    Wiring = filename:join([Root, "config", "torobot.wiring"]),
    World = filename:join([Root, "config", "worlds", "default.world"]),
    io:format("~n## Simulated lab~n~n"),
    %% A quick run takes its reference outcome from lockstep (the same
    %% outcome, SPEC §14) rather than from 60 s of real time at speed 1.
    speeds(World, Wiring, Dir, case Quick of
                                   true -> {lockstep, [10, 40, 80]};
                                   false -> {1, [2, 5, 10, 20, 40, 80, 160]}
                               end),
    robots(Wiring, Dir, case Quick of
                            true -> [1, 4];
                            false -> [1, 2, 4, 8, 12]
                        end),
    halt(0).

%%--------------------------------------------------------------------
%% Speed
%%--------------------------------------------------------------------

speeds(World, Wiring, Dir, {Ref, Speeds}) ->
    {Reference, RefWall} = timed(World, Wiring, Ref),
    Rows = [row(Ref, Reference, RefWall, Reference)
            | [begin {S, W} = timed(World, Wiring, Speed), row(Speed, S, W, Reference) end
               || Speed <- Speeds]],
    Highest = lists:foldl(fun(#{speed := Sp, same := true}, _) when is_number(Sp) -> Sp;
                             (_, Acc) -> Acc
                          end, 1, Rows),
    Ok = [R || R = #{speed := Sp} <- Rows, not is_number(Sp) orelse Sp =< Highest],
    #{wall_per_min_s := PerMin} = lists:last(Ok),
    io:format("### Speed: the default world (config/worlds/default.world) at each speed~n~n"
              "| speed | red touched (s) | wall contacts | blue contacts | distance (m) | "
              "same outcome as the first row | wall time (s) | wall time per simulated minute (s) |~n"
              "|---:|---:|---:|---:|---:|---|---:|---:|~n"),
    [io:format("| ~p | ~s | ~b | ~b | ~.2f | ~s | ~.1f | ~.2f |~n",
               [Sp, red(R), Wc, Bc, D, yes(Same), Wall, Pm])
     || #{speed := Sp, red := R, walls := Wc, blues := Bc, distance := D, same := Same,
          wall_s := Wall, wall_per_min_s := Pm} <- Rows],
    io:format("~nHighest speed (of those tried, every one up to it) keeping the first row's "
              "outcome: ~p, ~.2f s of wall time per simulated minute.~n~n", [Highest, PerMin]),
    csv(filename:join(Dir, "lab_speeds.csv"),
        [speed, red_touched_ms, wall_contacts, blue_contacts, distance_m, same, wall_s],
        [[Sp, R, Wc, Bc, D, Same, Wall]
         || #{speed := Sp, red := R, walls := Wc, blues := Bc, distance := D, same := Same,
              wall_s := Wall} <- Rows]).

timed(World, Wiring, Speed) ->
    T0 = erlang:monotonic_time(millisecond),
    Time = case Speed of
               lockstep -> #{time => lockstep};
               _ -> #{speed => Speed}
           end,
    {ok, Summary} = torobot_sim:run(World, Time#{wiring => Wiring}),
    {Summary, (erlang:monotonic_time(millisecond) - T0) / 1000}.

row(Speed, S = #{red_touched_ms := Red}, Wall, Reference) ->
    SimMs = case Red of
                none -> 60000;
                _ -> Red
            end,
    #{speed => Speed, red => Red, walls => maps:get(wall_contacts, S),
      blues => maps:get(blue_contacts, S), distance => maps:get(distance_m, S),
      same => same(S, Reference), wall_s => Wall, wall_per_min_s => Wall / (SimMs / 60000)}.

%% The same outcome: red touched or not, the same contacts, the time to
%% red and the distance within 10 %.
same(#{red_touched_ms := R1, distance_m := D1} = A, #{red_touched_ms := R2, distance_m := D2} = B) ->
    (R1 =:= none) =:= (R2 =:= none)
        andalso maps:with([wall_contacts, blue_contacts], A) =:= maps:with([wall_contacts, blue_contacts], B)
        andalso close(R1, R2) andalso close(D1, D2).

close(none, none) -> true;
close(A, B) -> abs(A - B) =< 0.1 * abs(B).

%%--------------------------------------------------------------------
%% Robots per world
%%--------------------------------------------------------------------

%% N robots in a large empty arena, each on its own node, at speed 10 for
%% 30 simulated seconds. Each robot alone keeps off the walls; the world
%% holds N robots while they still do, and run at the speed asked.
robots(Wiring, Dir, Counts) ->
    io:format("### Robots: N Torobots in one 12 x 12 m arena, each on its own node, "
              "speed 10, 30 simulated s~n~n"
              "| robots | wall contacts (all robots) | robot contacts (all) | distance per robot (m) | "
              "wall time (s) | of which nodes' start and stop (s) | achieved speed |~n"
              "|---:|---:|---:|---:|---:|---:|---:|~n"),
    Rows = [robots_row(N, Wiring) || N <- Counts],
    [io:format("| ~b | ~b | ~b | ~.2f | ~.1f | ~.1f | ~.1f |~n",
               [N, Wc, Rc, D, Wall, Boot, 29 / max(0.1, Wall - Boot)])
     || {N, Wc, Rc, D, Wall, Boot} <- Rows],
    io:format("~nOne robot per node by design (a node is one robot's runtime, its devices "
              "named as on the board); robots per machine is the count the table reaches "
              "with contacts still 0 and the achieved speed near 10.~n"),
    csv(filename:join(Dir, "lab_robots.csv"),
        [robots, wall_contacts, robot_contacts, distance_per_robot_m, wall_s, boot_s],
        [tuple_to_list(R) || R <- Rows]).

robots_row(N, Wiring) ->
    Side = 12.0,
    Per = ceil(math:sqrt(N)),
    Step = Side / (Per + 1),
    Robots = [{robot, list_to_atom("r" ++ integer_to_list(I)),
               {Step * (1 + (I - 1) rem Per), Step * (1 + (I - 1) div Per), 45.0 * I}}
              || I <- lists:seq(1, N)],
    Run = fun(Seconds) ->
                  T0 = erlang:monotonic_time(millisecond),
                  {ok, PerRobot} = torobot_sim:run([{arena, {Side, Side}}, {duration_s, Seconds}
                                                    | Robots],
                                                   #{speed => 10, wiring => Wiring}),
                  {PerRobot, (erlang:monotonic_time(millisecond) - T0) / 1000}
          end,
    %% the nodes' start and stop, timed on a 1 s run, is taken off
    {_, Boot} = Run(1),
    {PerRobot, Wall} = Run(30),
    Sums = maps:values(PerRobot),
    {N, lists:sum([maps:get(wall_contacts, S) || S <- Sums]),
     lists:sum([maps:get(robot_contacts, S) || S <- Sums]),
     lists:sum([maps:get(distance_m, S) || S <- Sums]) / N, Wall, Boot}.

%%--------------------------------------------------------------------

red(none) -> "-";
red(Ms) -> io_lib:format("~.2f", [Ms / 1000]).

yes(true) -> "yes";
yes(false) -> "**no**".

csv(File, Header, Rows) ->
    ok = file:write_file(File, [lists:join(",", [atom_to_list(H) || H <- Header]), "\n",
                                [[lists:join(",", [io_lib:format("~p", [V]) || V <- Row]), "\n"]
                                 || Row <- Rows]]).
