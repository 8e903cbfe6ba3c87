%% The library's robots (config/robots/*.wiring), each in its world
%% (config/worlds/NAME.world), run by torobot_sim on the real runtime and
%% devices, in lockstep (SPEC §14: the world is the clock, so a run is the
%% same on any machine at any load; TOROCO_LIB_SPEED=S runs them in real
%% time at speed S instead). Each
%% robot reaches the figure the README gives for it; the bounds below are
%% those figures. Group `rooms' runs each robot in a second room
%% (test/rooms/), on which it was not tuned, against the same bounds.
%%
%% Each robot runs on a peer node of its own (torobot_sim's `nodes =>
%% peer'), one after the other. The summaries are logged, the SVGs are in
%% the cases' priv_dir.
-module(toroco_lib_robots_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-define(ROBOTS, [wanderer, wall_follower, bump_and_escape, colour_seeker, docker,
                 braitenberg_love, braitenberg_fear, teleop]).

suite() ->
    [{timetrap, {minutes, 2}}].

all() ->
    [every_robot_is_tested, {group, robots}, {group, rooms}].

groups() ->
    [{robots, [], ?ROBOTS},
     {rooms, [], [wanderer_b, wall_follower_b, bump_and_escape_b, colour_seeker_b,
                          docker_b, braitenberg_love_b, braitenberg_fear_b]}].

init_per_suite(Config) ->
    [{root, root()} | Config].

end_per_suite(_Config) ->
    ok.

%%====================================================================
%% Cases
%%====================================================================

every_robot_is_tested() ->
    [{doc, "Every wiring file of config/robots/ has a world of its name and a case "
      "here, and uses library behaviors only."}].
every_robot_is_tested(Config) ->
    Root = ?config(root, Config),
    Files = filelib:wildcard(filename:join([Root, "config", "robots", "*.wiring"])),
    Names = lists:sort([list_to_atom(filename:basename(F, ".wiring")) || F <- Files]),
    ?assertEqual(lists:sort(?ROBOTS), Names),
    Library = [M || {_, M} <- toroco_lib:behaviors()],
    lists:foreach(
      fun(F) ->
              ?assert(filelib:is_regular(world_file(Root, filename:basename(F, ".wiring")))),
              {ok, Terms} = file:consult(F),
              [?assert(lists:member(M, Library), {F, M}) || {behavior, _, M, _} <- Terms]
      end, Files).

teleop() ->
    [{doc, "Nobody driving, the teleop robot stands still in its room: the motors' idle "
      "holds it (driven from ROS 2 in toroco_ros_server_SUITE)."}].
teleop(Config) ->
    World = filename:join(?config(priv_dir, Config), "teleop.world"),
    {ok, Text} = file:read_file(world(teleop, Config)),
    ok = file:write_file(World, re:replace(Text, "\\{duration_s, *[0-9]+\\}", "{duration_s, 20}")),
    S = run(teleop, World, Config),
    ?assert(maps:get(distance_m, S) < 0.01),
    ?assertEqual({0, 0}, {maps:get(wall_contacts, S), maps:get(blue_contacts, S)}).

wanderer() ->
    [{doc, "The wanderer covers at least 25% of its room in 45 s and touches nothing."}].
wanderer(Config) -> wanderer_in(world(wanderer, Config), Config).
wanderer_b(Config) -> wanderer_in(room(wanderer_b, Config), Config).
wanderer_in(World, Config) ->
    S = run(wanderer, World, Config),
    ?assert(maps:get(coverage, S) >= 0.25),
    ?assertEqual({0, 0}, {maps:get(wall_contacts, S), maps:get(blue_contacts, S)}).

wall_follower() ->
    [{doc, "The wall follower goes round its room at least once in 40 s, touching "
      "nothing."}].
wall_follower(Config) -> wall_follower_in(world(wall_follower, Config), Config).
wall_follower_b(Config) -> wall_follower_in(room(wall_follower_b, Config), Config).
wall_follower_in(World, Config) ->
    S = run(wall_follower, World, Config),
    ?assert(maps:get(laps, S) >= 1.0),
    ?assertEqual(0, maps:get(wall_contacts, S)).

bump_and_escape() ->
    [{doc, "The bump-and-escape robot, bumpers only, keeps going in its cluttered "
      "room: at least 5 m in 45 s and 10% of the floor (its bumper feels a wall 5 mm "
      "off, so a quick escape may leave no contact on the count)."}].
bump_and_escape(Config) -> bump_in(world(bump_and_escape, Config), Config).
bump_and_escape_b(Config) -> bump_in(room(bump_and_escape_b, Config), Config).
bump_in(World, Config) ->
    S = run(bump_and_escape, World, Config),
    ?assert(maps:get(distance_m, S) >= 5.0),
    ?assert(maps:get(coverage, S) >= 0.1).

colour_seeker() ->
    [{doc, "The colour seeker touches the red ball, out of sight at the start, within "
      "45 s."}].
colour_seeker(Config) -> seeker_in(world(colour_seeker, Config), Config).
colour_seeker_b(Config) -> seeker_in(room(colour_seeker_b, Config), Config).
seeker_in(World, Config) ->
    S = run(colour_seeker, World, Config),
    Red = maps:get(red_touched_ms, S),
    ?assert(is_integer(Red) andalso Red =< 45000).

docker() ->
    [{doc, "The docker reaches its dock, hidden behind a wall at the start, within "
      "45 s."}].
docker(Config) -> docker_in(world(docker, Config), Config).
docker_b(Config) -> docker_in(room(docker_b, Config), Config).
docker_in(World, Config) ->
    S = run(docker, World, Config),
    Docked = maps:get(docked_ms, S),
    ?assert(is_integer(Docked) andalso Docked =< 45000).

braitenberg_love() ->
    [{doc, "Love turns to the lamp and ends the 40 s within 0.7 m of it, touching "
      "nothing."}].
braitenberg_love(Config) -> love_in(world(braitenberg_love, Config), Config).
braitenberg_love_b(Config) -> love_in(room(braitenberg_b, Config), Config).
love_in(World, Config) ->
    S = run(braitenberg_love, World, Config),
    ?assert(maps:get(light_distance_m, S) =< 0.7),
    ?assertEqual(0, maps:get(wall_contacts, S)).

braitenberg_fear() ->
    [{doc, "Fear, starting 0.6 m from the lamp and facing it, keeps 1.2 m from it on "
      "average over the 40 s, touching nothing."}].
braitenberg_fear(Config) -> fear_in(world(braitenberg_fear, Config), Config).
braitenberg_fear_b(Config) -> fear_in(room(braitenberg_b, Config), Config).
fear_in(World, Config) ->
    S = run(braitenberg_fear, World, Config),
    ?assert(maps:get(light_mean_m, S) >= 1.2),
    ?assertEqual(0, maps:get(wall_contacts, S)).

%%====================================================================
%% Running a robot on a peer node
%%====================================================================

run(Robot, World, Config) ->
    Root = ?config(root, Config),
    Wiring = filename:join([Root, "config", "robots", atom_to_list(Robot) ++ ".wiring"]),
    Svg = filename:join(?config(priv_dir, Config), filename:basename(World, ".world") ++ ".svg"),
    {ok, Summary} = torobot_sim:run(World, (time_opts())#{wiring => Wiring, svg => Svg,
                                                      nodes => peer}),
    ct:comment("~s", [torobot_sim:summary_json(Summary)]),
    ct:pal("~s in ~s: ~s", [Robot, World, torobot_sim:summary_json(Summary)]),
    Summary.

time_opts() ->
    case os:getenv("TOROCO_LIB_SPEED") of
        false -> #{time => lockstep};
        S -> #{time => realtime, speed => list_to_integer(S)}
    end.

world(Robot, Config) ->
    world_file(?config(root, Config), atom_to_list(Robot)).

world_file(Root, Name) ->
    filename:join([Root, "config", "worlds", Name ++ ".world"]).

room(Name, Config) ->
    filename:join([?config(root, Config), "apps", "toroco_lib", "test", "rooms",
                   atom_to_list(Name) ++ ".world"]).

root() ->
    toroco_test_lib:root().
