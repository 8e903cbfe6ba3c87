%% The simulated lab (SPEC §14): generated worlds (torobot_worlds), batch
%% evaluation (torobot_batch through torobot_sim:batch/1, in lockstep unless
%% said otherwise, on one node and spread over peer nodes on loopback) and
%% what make eval writes (torobot_eval). Speed and several robots are run in
%% torobot_scenarios_SUITE, with the Torobot's scenarios.
-module(torobot_lab_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-include_lib("xmerl/include/xmerl.hrl").

-compile([export_all, nowarn_export_all]).

suite() ->
    [{timetrap, {minutes, 3}}].

all() ->
    [{group, generated}, {group, batch}, {group, nodes}].

groups() ->
    [{generated, [parallel], [generate_1000_seeds, generate_options, percentiles, bad_speed]},
     {batch, [], [batch_refuses_bad_option, batch_refuses_bad_world, batch_refuses_bad_wiring,
                  batch_20_generated, batch_lockstep_repeats]},
     %% distributed: this node gets a name for the group, peers on loopback
     {nodes, [], [batch_two_nodes_same_report, batch_node_gone]}].

init_per_suite(Config) ->
    Root = root(),
    [{root, Root}, {wiring, filename:join([Root, "config", "torobot.wiring"])} | Config].

end_per_suite(_Config) ->
    ok.

init_per_group(nodes, Config) ->
    [{stop_dist, toroco_test_lib:distributed("torobot_lab")} | Config];
init_per_group(_Group, Config) ->
    Config.

end_per_group(nodes, Config) ->
    _ = ?config(stop_dist, Config) andalso net_kernel:stop(),
    ok;
end_per_group(_Group, _Config) ->
    ok.

%%====================================================================
%% Generated worlds
%%====================================================================

generate_1000_seeds() ->
    [{doc, "Over 1,000 seeds every generated world loads, is not over, keeps objects off "
      "walls and each other, starts the robot clear, has red reachable, and comes out "
      "the same for the same seed."}].
generate_1000_seeds(_Config) ->
    Worlds = [{Seed, torobot_worlds:generate(Seed, #{})} || Seed <- lists:seq(1, 1000)],
    [begin
         ?assertEqual({Seed, Terms}, {Seed, torobot_worlds:generate(Seed, #{})}),
         {ok, W} = torobot_world:from_terms(Terms),
         ?assertNot(torobot_world:done(W)),
         ?assert(torobot_worlds:reachable(Terms)),
         check_clear(Seed, Terms)
     end || {Seed, Terms} <- Worlds],
    %% seeds make different worlds
    ?assert(length(lists:usort([T || {_, T} <- Worlds])) > 990),
    %% and the generator uses its range: walls and blue objects occur
    ?assert(lists:any(fun({_, T}) -> lists:keymember(wall, 1, T) end, Worlds)),
    ?assert(lists:any(fun({_, T}) -> lists:member(blue, [C || {object, C, _, _} <- T]) end,
                      Worlds)).

generate_options() ->
    [{doc, "Options fix the arena, the number of walls and blue objects, and the duration."}].
generate_options(_Config) ->
    Opts = #{arena => {5, 4}, walls => 0, blue => 0, duration_s => 12, stop_on_red => false},
    [begin
         T = torobot_worlds:generate(Seed, Opts),
         ?assertEqual({arena, {5.0, 4.0}}, lists:keyfind(arena, 1, T)),
         ?assertEqual([], [W || {wall, _} = W <- T]),
         ?assertEqual([red], [C || {object, C, _, _} <- T]),
         ?assertEqual({duration_s, 12}, lists:keyfind(duration_s, 1, T)),
         ?assertEqual({stop_on_red, false}, lists:keyfind(stop_on_red, 1, T))
     end || Seed <- lists:seq(1, 50)].

percentiles() ->
    [{doc, "Time-to-red percentiles are nearest-rank, none for no value."}].
percentiles(_Config) ->
    ?assertEqual(none, torobot_batch:percentile([], 50)),
    ?assertEqual(7, torobot_batch:percentile([7], 90)),
    L = lists:seq(1, 10),
    ?assertEqual(5, torobot_batch:percentile(lists:reverse(L), 50)),
    ?assertEqual(9, torobot_batch:percentile(L, 90)),
    ?assertEqual(10, torobot_batch:percentile(L, 100)).

bad_speed() ->
    [{doc, "A speed that is not a number above 0 is refused before anything starts."}].
bad_speed(Config) ->
    World = filename:join([?config(root, Config), "test", "worlds", "red_in_view.world"]),
    Wiring = ?config(wiring, Config),
    ?assertEqual({error, {speed, 0}}, torobot_sim:run(World, #{speed => 0, wiring => Wiring})),
    ?assertEqual({error, {speed, fast}}, torobot_sim:run(World, #{speed => fast, wiring => Wiring})),
    ?assertEqual({error, {speed, -1}}, torobot_sim:batch(#{worlds => [World], speed => -1})).

%%====================================================================
%% Batch
%%====================================================================

batch_refuses_bad_option() ->
    [{doc, "A batch refuses an option it does not know, and a bad time or node list, naming "
      "it, before any world is run or generated."}].
batch_refuses_bad_option(Config) ->
    Opts = #{worlds => {generated, 2, 1}, wiring => ?config(wiring, Config)},
    ?assertEqual({error, {bad_option, colour}}, torobot_sim:batch(Opts#{colour => red})),
    ?assertEqual({error, {bad_option, trace}}, torobot_sim:batch(Opts#{trace => "t.txt"})),
    ?assertEqual({error, {time, fast}}, torobot_sim:batch(Opts#{time => fast})),
    ?assertEqual({error, {nodes, []}}, torobot_sim:batch(Opts#{nodes => []})),
    ?assertEqual({error, {nodes, here}}, torobot_sim:batch(Opts#{nodes => here})),
    Twice = [node(), node()],
    ?assertEqual({error, {nodes, Twice}}, torobot_sim:batch(Opts#{nodes => Twice})),
    ?assertEqual({error, {parallel, 0}}, torobot_sim:batch(Opts#{parallel => 0})).

batch_refuses_bad_world() ->
    [{doc, "A batch with one bad world file is refused naming that file and its reason."}].
batch_refuses_bad_world(Config) ->
    Good = filename:join([?config(root, Config), "test", "worlds", "red_in_view.world"]),
    Bad = write_file(Config, "bad.world", [{arena, {6.0, 4.0}}, {duration_s, 10}]),
    ?assertEqual({error, {world, Bad, {missing, robot}}},
                 torobot_sim:batch(#{worlds => [Good, Bad], wiring => ?config(wiring, Config)})).

batch_refuses_bad_wiring() ->
    [{doc, "A wiring that does not parse, or names an unknown input, is refused naming the "
      "file, before any run."}].
batch_refuses_bad_wiring(Config) ->
    Worlds = {generated, 3, 1},
    Garbled = filename:join(?config(priv_dir, Config), "garbled.wiring"),
    ok = file:write_file(Garbled, "{behavior, forward, torobot_forward"),
    ?assertMatch({error, {wiring, Garbled, _}},
                 torobot_sim:batch(#{worlds => Worlds, wiring => Garbled})),
    {ok, Terms} = file:consult(?config(wiring, Config)),
    Wrong = write_file(Config, "wrong.wiring",
                       Terms ++ [{inputs, forward, #{nowhere => [{ir, left}]}}]),
    {error, {wiring, Wrong, Reason}} = torobot_sim:batch(#{worlds => Worlds, wiring => Wrong}),
    ct:log("refused: ~p", [Reason]),
    ?assertNotEqual(nomatch, string:find(io_lib:format("~p", [Reason]), "nowhere")).

batch_20_generated() ->
    [{doc, "batch/1 on 20 generated worlds, two at a time in lockstep: a row per world and "
      "an overall row whose figures agree with the runs, and make eval's files."}].
batch_20_generated(Config) ->
    {ok, Report} = torobot_sim:batch(#{worlds => {generated, 20, 100},
                                       parallel => 2, wiring => ?config(wiring, Config),
                                       generate => #{duration_s => 20}}),
    #{worlds := Rows, overall := Overall, runs := Runs, failures := Failures} = Report,
    ct:log("~s", [torobot_eval:markdown(Report)]),
    ?assertEqual([], Failures),
    ?assertEqual(20, length(Rows)),
    ?assertEqual(20, length(Runs)),
    ?assertMatch(#{runs := 20, failed := 0}, Overall),
    Reds = [Ms || #{summary := #{red_touched_ms := Ms}} <- Runs, Ms =/= none],
    ?assertEqual(length(Reds) / 20, maps:get(success_rate, Overall)),
    [?assert(Ms =< 20000) || Ms <- Reds],
    case Reds of
        [] -> ok;
        _ -> ?assert(maps:get(red_p50_ms, Overall) =< maps:get(red_p90_ms, Overall))
    end,
    %% the runs are the worlds it was given: the same arena as the generator's
    [#{final := First} | _] = Runs,
    {arena, Arena} = lists:keyfind(arena, 1, torobot_worlds:generate(100, #{duration_s => 20})),
    ?assertEqual(Arena, torobot_world:arena(First)),
    %% make eval's files
    Dir = filename:join(?config(priv_dir, Config), "eval"),
    ok = torobot_eval:write(Report, Dir),
    {ok, Md} = file:read_file(filename:join(Dir, "report.md")),
    ?assertEqual(2 + 20 + 1, length([L || L <- binary:split(Md, <<"\n">>, [global]),
                                          binary:first(<<L/binary, " ">>) =:= $|])),
    {ok, Csv} = file:read_file(filename:join(Dir, "runs.csv")),
    ?assertEqual(21, length(binary:split(Csv, <<"\n">>, [global, trim]))),
    [begin
         {Svg, []} = xmerl_scan:file(filename:join(Dir, F)),
         ?assertMatch(#xmlElement{name = svg}, Svg)
     end || F <- ["time_to_red.svg", "success.svg", "trajectories.svg"]],
    {Grid, []} = xmerl_scan:file(filename:join(Dir, "trajectories.svg")),
    ?assertEqual(20, length(xmerl_xpath:string("//polyline", Grid))).

batch_lockstep_repeats() ->
    [{doc, "In lockstep (the batch's default) a batch of generated worlds run twice, two "
      "at a time and then one at a time, gives the same report but for its wall time, "
      "and each run's summary is exactly that of the world run alone."}].
batch_lockstep_repeats(Config) ->
    Opts = small_batch(Config),
    {ok, First} = torobot_sim:batch(Opts#{parallel => 2}),
    {ok, Second} = torobot_sim:batch(Opts#{parallel => 1}),
    ct:log("~s", [torobot_eval:markdown(First)]),
    ?assertMatch(#{time := lockstep, failures := [], overall := #{runs := 6, failed := 0}},
                 First),
    same_report(First, Second),
    #{worlds := {generated, N, Seed}, generate := GenOpts} = Opts,
    Alone = [begin
                 {ok, Summary} = torobot_sim:run(torobot_worlds:generate(S, GenOpts),
                                                 #{time => lockstep, nodes => peer,
                                                   wiring => ?config(wiring, Config)}),
                 Summary
             end || S <- lists:seq(Seed, Seed + N - 1)],
    ?assertEqual([Summary || Summary <- Alone, _Run <- [1, 2]],
                 [Summary || #{summary := Summary} <- maps:get(runs, First)]).

batch_two_nodes_same_report() ->
    [{doc, "The same lockstep batch spread over two peer nodes on loopback gives the report "
      "of one node, row for row."}].
batch_two_nodes_same_report(Config) ->
    Opts = small_batch(Config),
    {ok, Here} = torobot_sim:batch(Opts),
    with_peers(2, fun([A, B]) ->
                          {ok, Spread} = torobot_sim:batch(Opts#{nodes => [A, B]}),
                          ct:log("~s", [torobot_eval:markdown(Spread)]),
                          ?assertEqual([], maps:get(failures, Spread)),
                          same_report(Here, Spread)
                  end).

batch_node_gone() ->
    [{doc, "A node that is not connected, or goes down mid-batch, has its runs reported as "
      "failures naming it; the other node's runs are whole and nothing hangs."}].
batch_node_gone(Config) ->
    Opts = small_batch(Config),
    {ok, Here} = torobot_sim:batch(Opts),
    Nowhere = 'torobot_lab_nowhere@127.0.0.1',
    with_peers(2, fun([A, B]) ->
                          %% not connected: B's share is every other run
                          {ok, Partly} = torobot_sim:batch(Opts#{nodes => [A, Nowhere]}),
                          check_share_failed(Here, Partly, Nowhere, not_connected),
                          %% B goes down once its first worker is up
                          Self = self(),
                          Batch = spawn_link(fun() ->
                                                     Self ! {batch, torobot_sim:batch(
                                                                      Opts#{nodes => [A, B]})}
                                             end),
                          ok = toroco_test_lib:wait_until(fun() -> has_worker(B) end, 30000, {no_worker_on, B}),
                          [Peer] = [P || {P, N} <- get(lab_peers), N =:= B],
                          ok = peer:stop(Peer),
                          {ok, Cut} = receive {batch, Result} -> Result
                                      after 60000 -> ct:fail({batch_hangs, Batch})
                                      end,
                          ct:log("~s", [torobot_eval:markdown(Cut)]),
                          #{failures := Failures, runs := Runs} = Cut,
                          ?assertNotEqual([], Failures),
                          [?assertMatch({node, B, _}, Why) || {_, _, Why} <- Failures],
                          %% A's share is whole and is what one node gives
                          ASide = [R || R = #{world := W, run := I} <- Runs,
                                        lists:member({W, I}, share_of(1, Opts))],
                          ?assertEqual([R || R = #{world := W, run := I} <- maps:get(runs, Here),
                                             lists:member({W, I}, share_of(1, Opts))],
                                       ASide)
                  end).

%%====================================================================
%% Helpers
%%====================================================================

%% A few short generated worlds, in lockstep: three worlds run twice.
small_batch(Config) ->
    #{worlds => {generated, 3, 40}, runs => 2, wiring => ?config(wiring, Config),
      generate => #{duration_s => 15}}.

%% Two reports are the same but for the wall time.
same_report(A, B) ->
    ?assertEqual(maps:get(worlds, A), maps:get(worlds, B)),
    ?assertEqual(maps:get(overall, A), maps:get(overall, B)),
    ?assertEqual([maps:remove(final, R) || R <- maps:get(runs, A)],
                 [maps:remove(final, R) || R <- maps:get(runs, B)]),
    ?assertEqual(maps:get(runs, A), maps:get(runs, B)),
    ?assertEqual(maps:remove(wall_ms, A), maps:remove(wall_ms, B)).

%% The (world, run) pairs dealt to the K-th of two nodes: every other job.
share_of(K, #{worlds := {generated, N, Seed}, runs := Runs}) ->
    Jobs = [{iolist_to_binary(["seed ", integer_to_list(S)]), I}
            || S <- lists:seq(Seed, Seed + N - 1), I <- lists:seq(1, Runs)],
    [Job || {J, Job} <- lists:enumerate(Jobs), (J - 1) rem 2 =:= K - 1].

check_share_failed(Here, Partly, Gone, Reason) ->
    #{failures := Failures, runs := Runs} = Partly,
    Jobs = [{W, I} || #{world := W, run := I} <- maps:get(runs, Here)],
    Theirs = [Job || {J, Job} <- lists:enumerate(Jobs), J rem 2 =:= 0],
    ?assertEqual([{W, I, {node, Gone, Reason}} || {W, I} <- Theirs], Failures),
    ?assertEqual([R || R = #{world := W, run := I} <- maps:get(runs, Here),
                       not lists:member({W, I}, Theirs)],
                 Runs).

%% N distributed peers on loopback with this node's code path and cookie,
%% stopped after Fun whatever happens (only these: the batch's own workers
%% go with them).
with_peers(N, Fun) ->
    Root = code:root_dir(),
    Paths = [P || P <- code:get_path(), not lists:prefix(Root, P)],
    Peers = [begin
                 Name = list_to_atom("torobot_lab_peer" ++
                                         integer_to_list(erlang:unique_integer([positive]))),
                 {ok, P, Node} = peer:start_link(
                                   #{name => Name, host => "127.0.0.1", longnames => true,
                                     args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                              "-connect_all", "false", "-pa" | Paths]}),
                 {P, Node}
             end || _ <- lists:seq(1, N)],
    put(lab_peers, Peers),
    try
        Fun([Node || {_, Node} <- Peers])
    after
        [catch peer:stop(P) || {P, _} <- Peers]
    end.

%% A batch's worker (torobot_batch:worker/2) is running on Node.
has_worker(Node) ->
    try
        Pids = erpc:call(Node, erlang, processes, [], 5000),
        lists:member({initial_call, {torobot_batch, worker, 2}},
                     [erpc:call(Node, erlang, process_info, [Pid, initial_call], 5000)
                      || Pid <- Pids])
    catch
        error:{erpc, _} -> false
    end.

%% Objects clear of every wall (the arena's too) and of each other; the
%% robot clear of everything.
check_clear(Seed, Terms) ->
    {arena, {W, H}} = lists:keyfind(arena, 1, Terms),
    {robot, {X, Y, _}} = lists:keyfind(robot, 1, Terms),
    Walls = [{{0.0, 0.0}, {W, 0.0}}, {{W, 0.0}, {W, H}}, {{W, H}, {0.0, H}}, {{0.0, H}, {0.0, 0.0}}]
        ++ [S || {wall, S} <- Terms],
    Objects = [{C, R} || {object, _, C, R} <- Terms],
    [require(gap(C, A, B) > R, {Seed, object_on_wall, C, {A, B}})
     || {C, R} <- Objects, {A, B} <- Walls],
    [require(dist(C1, C2) > R1 + R2, {Seed, objects_overlap, C1, C2})
     || {I, {C1, R1}} <- lists:enumerate(Objects), {J, {C2, R2}} <- lists:enumerate(Objects),
        I < J],
    [require(gap({X, Y}, A, B) > 0.12, {Seed, robot_on_wall, {A, B}}) || {A, B} <- Walls],
    [require(dist({X, Y}, C) > 0.12 + R, {Seed, robot_on_object, C}) || {C, R} <- Objects].

require(true, _What) -> ok;
require(false, What) -> ct:fail(What).

gap(P, {Ax, Ay}, {Bx, By}) ->
    {Ex, Ey} = {Bx - Ax, By - Ay},
    {Px, Py} = P,
    T = max(0.0, min(1.0, ((Px - Ax) * Ex + (Py - Ay) * Ey) / (Ex * Ex + Ey * Ey))),
    dist(P, {Ax + T * Ex, Ay + T * Ey}).

dist({X1, Y1}, {X2, Y2}) ->
    math:sqrt((X1 - X2) * (X1 - X2) + (Y1 - Y2) * (Y1 - Y2)).

write_file(Config, Name, Terms) ->
    File = filename:join(?config(priv_dir, Config), Name),
    ok = file:write_file(File, [io_lib:format("~tp.~n", [T]) || T <- Terms]),
    File.

%% The project's root: this file is apps/torobot/test/ in it.
root() ->
    toroco_test_lib:root().
