%% The Torobot in its simulated worlds (test/worlds/*.world): each case runs
%% the shipped wiring (config/torobot.wiring) on the real runtime and
%% devices through torobot_sim in lockstep (SPEC §14: the world is the
%% clock, so every run is exact on any machine at any load), and checks the
%% run's summary. The lockstep group checks that runs repeat byte for byte
%% and that a cascade lands in its own tick; one case runs the default world
%% in real time too. The robots group runs two robots, each on
%% its own peer node, in one world. The cases run one after another: each
%% run starts and stops the applications, and one node holds one network.
%% Summaries are logged (and put in each case's comment), the SVG of each
%% run is in the case's priv_dir.
-module(torobot_scenarios_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

suite() ->
    [{timetrap, {minutes, 2}}].

all() ->
    [empty_arena, red_in_view, blue_on_path, blue_near_wall, blue_near_wall_without_holds,
     red_behind_blue, red_follower_crashing, {group, lockstep}, {group, robots}].

groups() ->
    [{lockstep, [], [lockstep_repeats, lockstep_cascade_in_one_tick, real_time_default_world,
                     refuses_bad_options]},
     {robots, [], [two_robots_head_on, two_robots_dead_ahead]}].

%% The exact summaries of the shipped wiring in lockstep (JSON as the run
%% command prints it): a change of behavior shows here first.
-define(EXACT, #{"empty.world" => <<"{\"red_touched_ms\":null,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":11.25}">>,
                 "red_in_view.world" => <<"{\"red_touched_ms\":8900,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":1.78}">>,
                 "blue_on_path.world" => <<"{\"red_touched_ms\":null,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":4.825}">>,
                 "blue_near_wall.world" => <<"{\"red_touched_ms\":null,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":4.6}">>,
                 "red_behind_blue.world" => <<"{\"red_touched_ms\":20200,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":3.851}">>,
                 "head_on.world" => <<"{\"alpha\":{\"red_touched_ms\":null,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":2.9,\"robot_contacts\":0},\"beta\":{\"red_touched_ms\":null,\"wall_contacts\":0,\"blue_contacts\":0,\"distance_m\":2.9,\"robot_contacts\":0}}">>}).
-define(ALL_WORLDS, ["empty.world", "red_in_view.world", "blue_on_path.world",
                     "blue_near_wall.world", "red_behind_blue.world", "red_crashing.world"]).

init_per_suite(Config) ->
    Root = root(),
    [{root, Root}, {wiring, filename:join([Root, "config", "torobot.wiring"])} | Config].

end_per_suite(_Config) ->
    ok.

init_per_testcase(_Case, Config) ->
    Config.

end_per_testcase(_Case, _Config) ->
    _ = persistent_term:erase(torobot_crashes),
    ok.

%%====================================================================
%% Cases
%%====================================================================

empty_arena() ->
    [{doc, "Forward and the IR avoids alone roam an empty arena for a minute without "
      "touching a wall."}].
empty_arena(Config) ->
    {Summary, World} = run("empty.world", Config),
    ?assertEqual(0, maps:get(wall_contacts, Summary)),
    ?assertEqual(none, maps:get(red_touched_ms, Summary)),
    %% it roams, it does not stand still or spin in place
    ?assert(maps:get(distance_m, Summary) > 5.0),
    ?assert(won(World, [hold_left, hold_right, avoid_left, avoid_right])).

red_in_view() ->
    [{doc, "A red ball in view is charged and touched within 30 s, hitting no wall."}].
red_in_view(Config) ->
    {Summary, World} = run("red_in_view.world", Config),
    #{red_touched_ms := Red, wall_contacts := Walls} = Summary,
    ?assert(is_integer(Red) andalso Red =< 30000),
    ?assertEqual(0, Walls),
    ?assert(won(World, [red_follower])).

blue_on_path() ->
    [{doc, "A blue ball on the path is steered around: neither it nor a wall is touched."}].
blue_on_path(Config) ->
    {Summary, World} = run("blue_on_path.world", Config),
    ?assertMatch(#{blue_contacts := 0, wall_contacts := 0}, Summary),
    ?assert(won(World, [trq_ignore])).

blue_near_wall() ->
    [{doc, "Blue close to a wall on an oblique approach: the holds keep the avoid's turn "
      "while blue is seen, and neither the ball nor the wall is touched."}].
blue_near_wall(Config) ->
    {Summary, World} = run("blue_near_wall.world", Config),
    ?assertMatch(#{blue_contacts := 0, wall_contacts := 0}, Summary),
    ?assert(won(World, [hold_left, hold_right])).

blue_near_wall_without_holds() ->
    [{doc, "The same world with the hold modules taken out of the wiring hits the wall: "
      "the holds are what blue_near_wall checks."}].
blue_near_wall_without_holds(Config) ->
    Wiring = without_holds(Config),
    {Summary, _World} = run("blue_near_wall.world", [{wiring, Wiring} | Config]),
    ?assert(maps:get(wall_contacts, Summary) + maps:get(blue_contacts, Summary) > 0).

red_behind_blue() ->
    [{doc, "Red hidden behind blue at the start: the robot steers away from blue, sees red "
      "once off the line, and touches it."}].
red_behind_blue(Config) ->
    {Summary, World} = run("red_behind_blue.world", Config),
    ?assert(is_integer(maps:get(red_touched_ms, Summary))),
    ?assertEqual(0, maps:get(wall_contacts, Summary)),
    ?assert(won(World, [trq_ignore])).

red_follower_crashing() ->
    [{doc, "A red_follower that crashes every 2 s while it sees red: it is restarted, its "
      "layer is taken out in the end, and the layers below go on avoiding walls."}].
red_follower_crashing(Config) ->
    Crashes = counters:new(1, []),
    persistent_term:put(torobot_crashes, Crashes),
    Wiring = with_module(red_follower, torobot_crashing_follower, Config),
    %% each second of the run, note whether red_follower's layer is out
    Self = self(),
    Watch = fun(TimeS) -> Self ! {layers_out, TimeS, maps:get(removed_layers, toroco:inspect())} end,
    %% The crash timer counts world time, and so does the layer's restart
    %% intensity in lockstep (SPEC §17): six crashes 2 s apart are one more
    %% than 5 in 10 s, so the layer goes out at 12 s, and the run is exact
    %% (torobot_chaos_SUITE compares two traces of it).
    {Summary, World} = run("red_crashing.world", [{wiring, Wiring}, {each_second, Watch} | Config]),
    N = counters:get(Crashes, 1),
    Out = [T || {T, Removed} <- flush_layers_out(), lists:member(4, Removed)],
    Tags = [{T, Tag} || {T, _, _, Tag} <- torobot_world:trajectory(World)],
    ct:log("red_follower crashed ~b times; its layer out from ~p s", [N, first(Out)]),
    %% it crashed, was restarted (won the motors again after a crash), and
    %% its layer was taken out in the end
    ?assert(N >= 2),
    ?assert(lists:any(fun({T, Tag}) -> T > 2500 andalso Tag =:= red_follower end, Tags)),
    ?assertNotEqual(none, first(Out)),
    %% the layers below carried on: no wall touched, and the avoids turned
    %% the robot after the first crash
    ?assertEqual(0, maps:get(wall_contacts, Summary)),
    ?assert(lists:any(fun({T, Tag}) -> T > 2000 andalso
                                           lists:member(Tag, [avoid_left, avoid_right,
                                                              hold_left, hold_right])
                      end, Tags)),
    ct:comment("~s; ~b crashes, layer out at ~p s; red ~s",
               [torobot_sim:summary_json(Summary), N, first(Out),
                case maps:get(red_touched_ms, Summary) of
                    none -> "not reached";
                    _ -> "reached"
                end]).

flush_layers_out() ->
    receive {layers_out, T, Removed} -> [{T, Removed} | flush_layers_out()]
    after 0 -> []
    end.

first([]) -> none;
first([X | _]) -> X.

%%====================================================================
%% Lockstep and real time
%%====================================================================

lockstep_repeats() ->
    [{doc, "Lockstep: every scenario world run twice gives the same summary and a "
      "byte-identical trace, robot after robot (head_on's two peers included)."}].
lockstep_repeats(Config) ->
    [begin
         {A, TraceA} = traced(W, "a", Config),
         {B, TraceB} = traced(W, "b", Config),
         ?assertEqual({W, A}, {W, B}),
         ?assertEqual({W, sha(TraceA)}, {W, sha(TraceB)}),
         ct:log("~s: ~s, trace ~s", [W, torobot_sim:summary_json(A), sha(TraceA)])
     end || W <- ?ALL_WORLDS ++ ["head_on.world"]],
    ok.

lockstep_cascade_in_one_tick() ->
    [{doc, "Lockstep: in the default world the first tick's camera datagram (blue in view) "
      "reaches trq_ignore, the motors and the wheels before the world moves: the trace's "
      "first wheels line is at 0 ms, driven by trq_ignore."}].
lockstep_cascade_in_one_tick(Config) ->
    World = filename:join([?config(root, Config), "config", "worlds", "default.world"]),
    Trace = filename:join(?config(priv_dir, Config), "default_first.trace"),
    {ok, _} = torobot_sim:run(World, #{time => lockstep, trace => Trace,
                                       wiring => ?config(wiring, Config)}),
    {ok, Bin} = file:read_file(Trace),
    [First | _] = [L || L <- binary:split(Bin, <<"\n">>, [global]),
                        binary:match(L, <<" wheels ">>) =/= nomatch],
    ?assertEqual(<<"0 wheels 50 70 trq_ignore">>, First).

real_time_default_world() ->
    [{doc, "Real time (speed 1) keeps the default world's known summary, the one lockstep "
      "gives exactly: red touched at 45.5 s (within a tenth), no contact; on a machine "
      "too loaded to keep real time (a 10 ms timer late by over 25 ms) the real-time "
      "half says so and is skipped."}].
real_time_default_world(Config) ->
    World = filename:join([?config(root, Config), "config", "worlds", "default.world"]),
    Opts = #{wiring => ?config(wiring, Config)},
    {ok, Lockstep} = torobot_sim:run(World, Opts#{time => lockstep}),
    ?assertMatch(#{red_touched_ms := 45500, wall_contacts := 0, blue_contacts := 0}, Lockstep),
    Probe = lateness_probe(),
    {ok, Real} = torobot_sim:run(World, Opts#{speed => 1}),
    Late = lateness(Probe),
    ct:comment("lockstep ~s; real time ~s; timers up to ~b ms late",
               [torobot_sim:summary_json(Lockstep), torobot_sim:summary_json(Real), Late]),
    case Late > 25 of
        true ->
            %% a reaction lands in whichever tick its real latency allows: on a
            %% machine that does not keep time the run is another run
            {skip, io_lib:format("this machine did not keep real time (timers ~b ms late): "
                                 "real time ~s", [Late, torobot_sim:summary_json(Real)])};
        false ->
            ?assertMatch(#{wall_contacts := 0, blue_contacts := 0}, Real),
            Red = maps:get(red_touched_ms, Real),
            ?assert(is_integer(Red) andalso abs(Red - 45500) =< 4550)
    end.

%% How late a 10 ms timer fires while the run goes: the machine's own
%% measure of whether it kept real time.
lateness_probe() ->
    spawn_link(fun() -> probe(0) end).

probe(Worst) ->
    T0 = erlang:monotonic_time(millisecond),
    receive
        {stop, From} -> From ! {lateness, Worst}
    after 10 ->
            probe(max(Worst, erlang:monotonic_time(millisecond) - T0 - 10))
    end.

lateness(Probe) ->
    Probe ! {stop, self()},
    receive {lateness, L} -> L after 5000 -> 1000 end.

refuses_bad_options() ->
    [{doc, "run/2 refuses an option it does not know, a bad time, and a trace in real "
      "time, naming each, before anything starts."}].
refuses_bad_options(Config) ->
    World = filename:join([?config(root, Config), "config", "worlds", "default.world"]),
    ?assertEqual({error, {bad_option, tiem}}, torobot_sim:run(World, #{tiem => lockstep})),
    ?assertEqual({error, {time, fast}}, torobot_sim:run(World, #{time => fast})),
    ?assertEqual({error, {trace, "t.trace"}}, torobot_sim:run(World, #{trace => "t.trace"})),
    ?assertEqual(undefined, whereis(torobot_sim_robot)).

traced(WorldName, Tag, Config) ->
    Trace = filename:join(?config(priv_dir, Config),
                          filename:rootname(WorldName) ++ "_" ++ Tag ++ ".trace"),
    {Summary, _} = run(WorldName, [{trace, Trace} | Config]),
    {ok, Bin} = file:read_file(Trace),
    ?assert(byte_size(Bin) > 0),
    {Summary, Bin}.

sha(Bin) ->
    binary:encode_hex(crypto:hash(sha256, Bin)).

%%====================================================================
%% Several robots
%%====================================================================

two_robots_head_on() ->
    [{doc, "Two robots on their own nodes drive at each other on paths 10 cm apart: each "
      "sees the other with its IR and turns away, neither touches the other nor a wall."}].
two_robots_head_on(Config) ->
    {#{alpha := A, beta := B} = Summaries, Worlds} = run("head_on.world", Config),
    [?assertMatch(#{robot_contacts := 0, wall_contacts := 0}, S) || S <- [A, B]],
    %% both turned (the avoid or its hold won the motors), and both went on
    [?assert(won(W, [hold_left, hold_right, avoid_left, avoid_right])) || W <- Worlds],
    [?assert(maps:get(distance_m, S) > 2.0) || S <- [A, B]],
    ct:comment("~s", [torobot_sim:summary_json(Summaries)]).

two_robots_dead_ahead() ->
    [{doc, "Exactly head-on, a robot falls between the other's two IR rays (30 degrees "
      "out): they meet, and each counts the contact (robots do bump)."}].
two_robots_dead_ahead(Config) ->
    {ok, Terms} = file:consult(filename:join([?config(root, Config), "test", "worlds",
                                              "head_on.world"])),
    Ahead = [case T of
                 {robot, beta, {X, _, H}} -> {robot, beta, {X, 2.0, H}};
                 _ -> T
             end || T <- Terms],
    File = write_terms("dead_ahead.world", Ahead, Config),
    {#{alpha := A, beta := B}, _} = run(File, Config),
    [?assert(maps:get(robot_contacts, S) >= 1) || S <- [A, B]].

%%====================================================================
%% Helpers
%%====================================================================

run(WorldName, Config) ->
    Root = ?config(root, Config),
    World = filename:join([Root, "test", "worlds", WorldName]),
    Svg = filename:join(?config(priv_dir, Config),
                        filename:basename(filename:rootname(WorldName)) ++ ".svg"),
    EachSecond = proplists:get_value(each_second, Config, fun(_) -> ok end),
    Second = counters:new(1, []),
    Status = fun(Line) ->
                     ct:log("~s", [Line]),
                     counters:add(Second, 1, 1),
                     EachSecond(counters:get(Second, 1))
             end,
    Opts0 = #{wiring => ?config(wiring, Config), svg => Svg, status => Status, time => lockstep},
    Opts = case proplists:get_value(trace, Config) of
               undefined -> Opts0;
               Trace -> Opts0#{trace => Trace}
           end,
    {ok, Final} = torobot_sim:simulate(World, Opts),
    Summary = case Final of
                  [_ | _] -> maps:from_list([{torobot_world:name(W), torobot_world:summary(W)}
                                             || W <- Final]);
                  _ -> torobot_world:summary(Final)
              end,
    Json = torobot_sim:summary_json(Summary),
    ct:pal("~s in lockstep: ~s (winners: ~p)", [WorldName, Json, winners(Final)]),
    ct:comment("~s", [Json]),
    Shipped = filename:join([Root, "config", "torobot.wiring"]),
    case {?config(wiring, Config), ?EXACT} of
        {Shipped, #{WorldName := Exact}} -> ?assertEqual({WorldName, Exact}, {WorldName, Json});
        _ -> ok
    end,
    {Summary, Final}.

%% Whether one of Tags won the motors at some tick of the run.
won(World, Tags) ->
    lists:any(fun(Tag) -> lists:member(Tag, Tags) end, winners(World)).

winners(Worlds) when is_list(Worlds) ->
    lists:usort(lists:append([winners(W) || W <- Worlds]));
winners(World) ->
    lists:usort([Tag || {_, _, _, Tag} <- torobot_world:trajectory(World)]).

%% The shipped wiring with the hold modules taken out.
without_holds(Config) ->
    {ok, Terms} = file:consult(?config(wiring, Config)),
    Holds = [hold_left, hold_right],
    Kept = [strip_holds(T, Holds) || T <- Terms,
                                     not lists:member(element(2, T), Holds)],
    write_terms("without_holds.wiring", Kept, Config).

strip_holds({inputs, motors, #{setvel := #{sources := Srcs} = In} = Ins}, Holds) ->
    {inputs, motors, Ins#{setvel := In#{sources := [S || S <- Srcs,
                                                        not lists:member(element(1, S), Holds)]}}};
strip_holds(Term, _Holds) ->
    Term.

%% The shipped wiring with behavior Name running Module instead.
with_module(Name, Module, Config) ->
    {ok, Terms} = file:consult(?config(wiring, Config)),
    Swapped = [case T of
                   {behavior, Name, _, Opts} -> {behavior, Name, Module, Opts};
                   _ -> T
               end || T <- Terms],
    write_terms(atom_to_list(Module) ++ ".wiring", Swapped, Config).

write_terms(FileName, Terms, Config) ->
    File = filename:join(?config(priv_dir, Config), FileName),
    ok = file:write_file(File, [io_lib:format("~tp.~n", [T]) || T <- Terms]),
    File.

%% The project's root: this file is apps/torobot/test/ in it.
root() ->
    toroco_test_lib:root().
