%% The library's sensors and figures in the simulated world, as pure
%% functions of torobot_world values (torobot_sensors): each model reads
%% what the geometry says, bad terms are refused, and a world without
%% them is the Torobot's world as before.
-module(torobot_sensors_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

all() ->
    [ranges_read_metres, bumper_names_the_side, odometry_shows_a_stall, light_is_brighter_on_its_side,
     beacon_bearing_and_dock, beacon_hidden_by_a_wall, figures_laps_and_coverage,
     grey_sensors_see_the_tape, bad_terms_refused, torobot_summary_unchanged].

world(Terms) ->
    {ok, W} = torobot_world:from_terms([{arena, {4.0, 3.0}}, {duration_s, 60} | Terms]),
    W.

read(W) ->
    {Readings, _} = torobot_sensors:read(W, torobot_sensors:new(W)),
    Readings.

ranges_read_metres() ->
    [{doc, "Range sensors read the distance from the rim to the wall along their mount, "
      "to the centimetre, and max_range when nothing is nearer."}].
ranges_read_metres(_Config) ->
    #{range := R} = read(world([{robot, {3.0, 1.5, 0.0}}])),
    ?assertEqual(0.88, maps:get(front, R)),            % 4.0 - 3.0 - 0.12
    ?assertEqual(1.5, maps:get(rear, R)),              % max_range
    ?assertEqual(1.38, maps:get(left, R)),
    #{range := R2} = read(world([{robot, {1.0, 1.5, 0.0}},
                                 {range, #{sensors => #{ahead => 0}, max_range => 1.0}}])),
    ?assertEqual(#{ahead => 1.0}, R2).

bumper_names_the_side() ->
    [{doc, "The bumper reports none in the open and the side of a contact: front, left, "
      "right, rear."}].
bumper_names_the_side(_Config) ->
    Contact = fun(Heading) ->
                      maps:get(contact, maps:get(bumper, read(world([{robot, {0.12, 1.5, Heading}}]))))
              end,
    ?assertEqual(none, maps:get(contact, maps:get(bumper, read(world([{robot, {2.0, 1.5, 0.0}}]))))),
    ?assertEqual(front, Contact(180.0)),
    ?assertEqual(left, Contact(90.0)),                 % heading north, the wall west
    ?assertEqual(right, Contact(-90.0)),
    ?assertEqual(rear, Contact(0.0)).

odometry_shows_a_stall() ->
    [{doc, "Odometry measures the wheels as the robot really moved: the command in the "
      "open, nothing when driving into a wall (a stall), opposite wheels in a spin."}].
odometry_shows_a_stall(_Config) ->
    Measure = fun(Pose, Cmd) ->
                      W0 = world([{robot, Pose}]),
                      S0 = torobot_sensors:new(W0),
                      W1 = torobot_world:step(W0, 100, Cmd),
                      {#{odometry := #{wheels := Wheels}}, _} = torobot_sensors:read(W1, S0),
                      Wheels
              end,
    ?assertEqual({80, 80}, Measure({2.0, 1.5, 0.0}, {80, 80})),
    ?assertEqual({0, 0}, Measure({3.88, 1.5, 0.0}, {80, 80})),
    ?assertEqual({-50, 50}, Measure({2.0, 1.5, 0.0}, {-50, 50})).

light_is_brighter_on_its_side() ->
    [{doc, "The light sensor on the lamp's side reads more; nearer is brighter; a wall "
      "between hides the lamp."}].
light_is_brighter_on_its_side(_Config) ->
    Lamp = {light, {2.0, 2.0}, 1000},
    #{light := #{left := L, right := R}} = read(world([Lamp, {robot, {1.0, 1.5, 0.0}}])),
    ?assert(L > R),
    #{light := #{left := Near}} = read(world([Lamp, {robot, {1.5, 1.7, 0.0}}])),
    ?assert(Near > L),
    #{light := Dark} = read(world([Lamp, {wall, {{1.5, 0.5}, {1.5, 2.9}}},
                                   {robot, {1.0, 1.5, 0.0}}])),
    ?assertEqual(#{left => 0, right => 0}, Dark).

beacon_bearing_and_dock() ->
    [{doc, "The beacon gives the dock's bearing (counter-clockwise from the heading) and "
      "distance; docked is true within dock_radius."}].
beacon_bearing_and_dock(_Config) ->
    #{beacon := B} = read(world([{dock, {2.0, 2.5}}, {robot, {1.0, 1.5, 0.0}}])),
    ?assertEqual(#{bearing => {45, 1.41}, docked => false}, B),
    #{beacon := Docked} = read(world([{dock, {2.0, 2.5}}, {robot, {2.05, 2.5, 90.0}}])),
    ?assertMatch(#{docked := true}, Docked),
    ?assertEqual(#{bearing => none, docked => false}, maps:get(beacon, read(world([{robot, {1.0, 1.5, 0.0}}])))).

beacon_hidden_by_a_wall() ->
    [{doc, "A wall between robot and dock hides the beacon, and so does a wall end the "
      "robot's body would clip on the way."}].
beacon_hidden_by_a_wall(_Config) ->
    Hidden = world([{dock, {3.0, 1.5}}, {wall, {{2.0, 0.5}, {2.0, 2.5}}}, {robot, {1.0, 1.5, 0.0}}]),
    ?assertMatch(#{bearing := none}, maps:get(beacon, read(Hidden))),
    Clipped = world([{dock, {3.0, 1.5}}, {wall, {{2.0, 0.0}, {2.0, 1.45}}}, {robot, {1.0, 1.5, 0.0}}]),
    ?assertMatch(#{bearing := none}, maps:get(beacon, read(Clipped))),
    Clear = world([{dock, {3.0, 1.5}}, {wall, {{2.0, 0.0}, {2.0, 1.2}}}, {robot, {1.0, 1.5, 0.0}}]),
    ?assertMatch(#{bearing := {0, 2.0}}, maps:get(beacon, read(Clear))).

figures_laps_and_coverage() ->
    [{doc, "A world asking for figures gets them in its summary: a circle round the "
      "centre is one lap, a robot standing still covers little, the dock time is when "
      "it got there."}].
figures_laps_and_coverage(_Config) ->
    W0 = world([{robot, {3.0, 1.5, 90.0}}, {figures, [laps, coverage, docked_ms]},
                {dock, {2.0, 2.5}}]),
    %% a circle of radius 1 m round the centre (2.0, 1.5): 2 pi m at 0.125 m/s
    Circle = lists:foldl(fun(_, W) -> torobot_world:step(W, 100, {45, 55}) end, W0,
                         lists:seq(1, 505)),
    #{laps := Laps, coverage := C, docked_ms := Docked} = torobot_world:summary(Circle),
    ?assert(Laps >= 0.95 andalso Laps =< 1.1),
    ?assert(C > 0.1 andalso C < 0.5),
    ?assert(is_integer(Docked)),
    #{coverage := Still} = torobot_world:summary(W0),
    ?assert(Still < 0.05).

grey_sensors_see_the_tape() ->
    [{doc, "The grey sensors read dark over a floor line, light beside it: the one on the "
      "side the tape is reads dark; a world without grey_sensor has neither device."}].
grey_sensors_see_the_tape(_Config) ->
    Tape = {floor_line, [{0.0, 1.525}, {4.0, 1.525}]},   % under the left sensor
    Grey = {grey_sensor, #{offset => 0.06, spread => 0.025, width => 0.02}},
    R = read(world([{robot, {1.0, 1.5, 0.0}}, Tape, Grey])),
    ?assertMatch(#{trc_grey_left := #{value := 900}, trc_grey_right := #{value := 100}}, R),
    R2 = read(world([{robot, {1.0, 1.55, 0.0}}, Tape, Grey])),
    ?assertMatch(#{trc_grey_left := #{value := 100}, trc_grey_right := #{value := 900}}, R2),
    Plain = world([{robot, {1.0, 1.5, 0.0}}, Tape]),
    ?assertEqual(false, maps:is_key(trc_grey_left, read(Plain))),
    ?assertEqual([], [N || {N, Outputs} <- torobot_sensors:devices(), Outputs(Plain) =/= [],
                           lists:member(N, [trc_grey_left, trc_grey_right])]).

bad_terms_refused() ->
    [{doc, "Malformed sensor terms are refused naming the term; given twice, refused as "
      "duplicates."}].
bad_terms_refused(_Config) ->
    Base = [{arena, {4.0, 3.0}}, {duration_s, 10}, {robot, {1.0, 1.0, 0.0}}],
    [?assertEqual({error, {bad_term, T}}, torobot_world:from_terms(Base ++ [T]))
     || T <- [{range, #{sensors => #{front => x}}}, {bumper, #{front_deg => 0}},
              {light, {1, 1}, -3}, {dock, nowhere}, {figures, [happiness]},
              {beacon, #{colour => red}}, {floor_line, [{1, 1}]}, {floor_line, [{1, 1}, x]},
              {grey_sensor, #{dark => 2000}}, {grey_sensor, #{offset => -1}},
              {grey_sensor, #{colour => grey}}]],
    ?assertEqual({error, {duplicate, {dock, {1, 2}}}},
                 torobot_world:from_terms(Base ++ [{dock, {1, 1}}, {dock, {1, 2}}])).

torobot_summary_unchanged() ->
    [{doc, "A world with no figures term has exactly the Torobot's summary keys."}].
torobot_summary_unchanged(_Config) ->
    W = torobot_world:step(world([{robot, {1.0, 1.5, 0.0}}]), 500, {50, 50}),
    ?assertEqual([blue_contacts, distance_m, red_touched_ms, wall_contacts],
                 lists:sort(maps:keys(torobot_world:summary(W)))).
