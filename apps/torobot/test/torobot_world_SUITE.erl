%% The simulated world's pure core (torobot_world) and its picture
%% (torobot_svg): world files, kinematics, collisions and contact counting,
%% the IR and camera models, the summary, and the SVG.
-module(torobot_world_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-include_lib("xmerl/include/xmerl.hrl").

-compile([export_all, nowarn_export_all]).

all() ->
    [{group, loading}, {group, kinematics}, {group, collisions}, {group, ir},
     {group, camera}, {group, run}, {group, svg}, {group, several_robots},
     {group, modules}].

groups() ->
    [{loading, [parallel],
      [load_good_file, load_defaults, load_missing_file, load_syntax_error,
       bad_terms, missing_terms, duplicate_terms, outside_arena, blocked_start,
       shipped_worlds_load]},
     {kinematics, [parallel],
      [straight_line, heading_convention, spin_in_place, step_size_independent,
       velocities_clamped]},
     {collisions, [parallel],
      [drive_into_wall, slide_along_wall, second_approach_counts, corner,
       inner_wall_not_crossed, objects_are_solid, red_touch_time, stop_on_red]},
     {ir, [parallel],
      [ir_monotonic, ir_side, ir_sees_objects, ir_levels_hysteresis]},
     {several_robots, [parallel],
      [robots_load, robots_refused, robots_are_solid, robots_seen_by_ir,
       robots_colour_seen, robots_summary_and_svg]},
     {camera, [parallel],
      [camera_ahead, camera_left_right, camera_behind_wall, camera_out_of_fov,
       camera_out_of_range, camera_occlusion_by_object, camera_largest,
       camera_area_shrinks, camera_datagram_keys, camera_datagram_text]},
     {run, [parallel],
      [summary_keys, done_at_duration, trajectory_tags]},
     {svg, [parallel],
      [svg_parses, svg_write, svg_empty_run]},
     {modules, [parallel],
      [no_module_cycle, world_record_stays_inside]}].

%%====================================================================
%% Loading
%%====================================================================

load_good_file() -> [{doc, "A world file with every term loads, and its values are kept."}].
load_good_file(Config) ->
    File = write_world(Config, "good.world",
                       [{arena, {6.0, 4.0}},
                        {wall, {{1.0, 1.0}, {1.0, 2.5}}},
                        {object, red, {4.5, 2.0}, 0.10},
                        {object, blue, {3.0, 2.2}, 0.1},
                        {robot, {1.5, 2.0, 90}},
                        {duration_s, 30},
                        {robot_geometry, #{radius => 0.1, wheel_base => 0.25, max_wheel_speed => 0.3}},
                        {ir, #{mount_deg => 25, threshold_high => 300, threshold_low => 250}},
                        {camera, #{fov_deg => 70, frame => {640, 480}, range => 3}},
                        {seed, 7}, {tick_ms, 20}, {stop_on_red, false}]),
    {ok, W} = torobot_world:load(File),
    ?assertEqual({6.0, 4.0}, torobot_world:arena(W)),
    ?assertEqual([{{1.0, 1.0}, {1.0, 2.5}}], torobot_world:walls(W)),
    ?assertEqual([{red, {4.5, 2.0}, 0.1}, {blue, {3.0, 2.2}, 0.1}], torobot_world:objects(W)),
    ?assertEqual({1.5, 2.0, 90.0}, torobot_world:start_pose(W)),
    ?assertEqual({1.5, 2.0, 90.0}, torobot_world:pose(W)),
    ?assertEqual(0.1, torobot_world:robot_radius(W)),
    ?assertEqual(#{threshold_high => 300, threshold_low => 250}, torobot_world:ir_thresholds(W)),
    ?assertEqual(20, torobot_world:tick_ms(W)),
    ?assertEqual(30000, torobot_world:duration_ms(W)),
    ?assertEqual(0, torobot_world:time_ms(W)),
    ?assertEqual([{0, 1.5, 2.0, start}], torobot_world:trajectory(W)).

load_defaults() -> [{doc, "Only arena, robot and duration_s are required; the rest has documented defaults."}].
load_defaults(_Config) ->
    W = world([]),
    ?assertEqual(0.12, torobot_world:robot_radius(W)),
    ?assertEqual(#{threshold_high => 240, threshold_low => 200}, torobot_world:ir_thresholds(W)),
    ?assertEqual(50, torobot_world:tick_ms(W)),
    ?assertEqual([], torobot_world:walls(W)),
    ?assertEqual([], torobot_world:objects(W)),
    ?assertEqual(#{red_touched_ms => none, wall_contacts => 0, blue_contacts => 0, distance_m => 0.0},
                 torobot_world:summary(W)),
    ?assertNot(torobot_world:done(W)).

load_missing_file() -> [{doc, "A file that cannot be read gives {file, Reason}."}].
load_missing_file(Config) ->
    Missing = filename:join(?config(priv_dir, Config), "no_such.world"),
    ?assertEqual({error, {file, enoent}}, torobot_world:load(Missing)).

load_syntax_error() -> [{doc, "A file that does not parse gives {file, Reason} with the line."}].
load_syntax_error(Config) ->
    File = filename:join(?config(priv_dir, Config), "syntax.world"),
    ok = file:write_file(File, "{arena, {6.0, 4.0}}.\n{robot, {1.0, 1.0, 0.0}\n"),
    ?assertMatch({error, {file, {_Line, erl_parse, _}}}, torobot_world:load(File)).

bad_terms() -> [{doc, "Each malformed term is refused as {bad_term, Term}, naming that term."}].
bad_terms(_Config) ->
    Bad = [{arena, {0, 4.0}}, {arena, 6.0},
           {wall, {{1.0, 1.0}, {1.0, 1.0}}}, {wall, {1.0, 1.0}},
           {object, green, {1.0, 1.0}, 0.1}, {object, red, {1.0, 1.0}, -0.1},
           {object, red, {1.0, x}, 0.1},
           {robot, {1.0, 1.0}}, {duration_s, 0}, {seed, 1.5}, {tick_ms, 0},
           {stop_on_red, yes},
           {robot_geometry, #{radius => 0}}, {robot_geometry, [{radius, 0.1}]},
           {ir, #{threshold_high => 200, threshold_low => 300}},
           {ir, #{min_range => 0.9}}, {ir, #{threshold_high => 2000}},
           {ir, #{range => 1.0}},
           {camera, #{fov_deg => 200}}, {camera, #{frame => {320.0, 240}}},
           {colour, red}, not_a_tuple],
    [?assertEqual({error, {bad_term, T}}, torobot_world:from_terms(base() ++ [T])) || T <- Bad],
    ?assertEqual({error, {bad_term, not_a_list}}, torobot_world:from_terms(not_a_list)).

missing_terms() -> [{doc, "Leaving out arena, robot or duration_s gives {missing, Key}."}].
missing_terms(_Config) ->
    [?assertEqual({error, {missing, Key}},
                  torobot_world:from_terms(lists:keydelete(Key, 1, base())))
     || Key <- [arena, robot, duration_s]].

duplicate_terms() -> [{doc, "A term that may appear once, given twice, is refused as {duplicate, Term}."}].
duplicate_terms(_Config) ->
    Once = base() ++ [{seed, 1}, {ir, #{}}],
    [?assertEqual({error, {duplicate, T}}, torobot_world:from_terms(Once ++ [T]))
     || T <- [{arena, {5.0, 5.0}}, {robot, {2.0, 2.0, 0.0}}, {duration_s, 5},
              {seed, 2}, {ir, #{}}]],
    ?assertMatch({ok, _}, torobot_world:from_terms(base() ++ [{wall, {{1.0, 0.5}, {1.0, 1.0}}},
                                                              {wall, {{1.0, 0.5}, {1.0, 1.0}}}])).

outside_arena() -> [{doc, "Walls, objects or a robot outside the arena are refused as {outside_arena, Term}."}].
outside_arena(_Config) ->
    [?assertEqual({error, {outside_arena, T}}, torobot_world:from_terms(base() ++ [T]))
     || T <- [{object, red, {7.0, 1.0}, 0.1}, {wall, {{5.0, 1.0}, {6.5, 1.0}}}]],
    Outside = {robot, {3.0, -1.0, 0.0}},
    ?assertEqual({error, {outside_arena, Outside}},
                 torobot_world:from_terms(lists:keyreplace(robot, 1, base(), Outside))).

blocked_start() -> [{doc, "A robot starting inside a wall or an object names both."}].
blocked_start(_Config) ->
    Robot = {robot, {1.0, 2.0, 0.0}},
    Wall = {wall, {{1.05, 1.0}, {1.05, 3.0}}},
    Object = {object, blue, {1.2, 2.0}, 0.1},
    ?assertEqual({error, {blocked_start, Robot, Wall}},
                 torobot_world:from_terms([{arena, {6.0, 4.0}}, Robot, {duration_s, 1}, Wall])),
    ?assertEqual({error, {blocked_start, Robot, Object}},
                 torobot_world:from_terms([{arena, {6.0, 4.0}}, Robot, {duration_s, 1}, Object])),
    Arena = {arena, {6.0, 4.0}},
    Corner = {robot, {0.05, 0.05, 0.0}},
    ?assertEqual({error, {blocked_start, Corner, Arena}},
                 torobot_world:from_terms([Arena, Corner, {duration_s, 1}])).

shipped_worlds_load() -> [{doc, "Every world shipped in config/worlds and test/worlds loads and is not over at the start."}].
shipped_worlds_load(_Config) ->
    Root = repo_root(),
    Expected = ["config/worlds/default.world", "test/worlds/empty.world",
                "test/worlds/red_in_view.world", "test/worlds/blue_on_path.world",
                "test/worlds/blue_near_wall.world", "test/worlds/red_behind_blue.world"],
    Found = filelib:wildcard("{config,test}/worlds/*.world", Root),
    ?assertEqual([], Expected -- Found),
    [begin
         {ok, Ws} = torobot_world:load_all(filename:join(Root, F)),
         [?assertNot(torobot_world:done(W)) || W <- Ws]
     end || F <- Found].

%%====================================================================
%% Kinematics
%%====================================================================

straight_line() -> [{doc, "Equal wheel velocities drive straight: velocity 100 is 0.25 m/s, 50 is half that."}].
straight_line(_Config) ->
    W1 = drive(world([{robot, {1.0, 2.0, 0.0}}]), {100, 100}, 2000),
    assert_pose({1.5, 2.0, 0.0}, torobot_world:pose(W1)),
    assert_close(0.5, distance(W1)),
    W2 = drive(world([{robot, {1.0, 2.0, 0.0}}]), {50, 50}, 2000),
    assert_pose({1.25, 2.0, 0.0}, torobot_world:pose(W2)),
    W3 = drive(world([{robot, {3.0, 2.0, 0.0}}]), {-100, -100}, 2000),
    assert_pose({2.5, 2.0, 0.0}, torobot_world:pose(W3)),
    assert_close(0.5, distance(W3)),
    ?assertEqual(2000, torobot_world:time_ms(W3)).

heading_convention() -> [{doc, "Heading 0 is +x and 90 is +y; a faster right wheel turns counter-clockwise."}].
heading_convention(_Config) ->
    W1 = drive(world([{robot, {3.0, 1.0, 90.0}}]), {100, 100}, 2000),
    assert_pose({3.0, 1.5, 90.0}, torobot_world:pose(W1)),
    W2 = drive(world([{robot, {2.0, 2.0, 0.0}}]), {50, 100}, 1000),
    {X2, Y2, H2} = torobot_world:pose(W2),
    ?assert(X2 > 2.0 andalso Y2 > 2.0 andalso H2 > 0.0),
    W3 = drive(world([{robot, {2.0, 2.0, 0.0}}]), {100, 50}, 1000),
    {_, Y3, H3} = torobot_world:pose(W3),
    ?assert(Y3 < 2.0 andalso H3 < 0.0).

spin_in_place() -> [{doc, "Opposite wheel velocities spin in place at (vr - vl) / wheel base, travelling nothing."}].
spin_in_place(_Config) ->
    %% 0.125 m/s each way on a 0.2 m wheel base: 1.25 rad/s.
    W1 = drive(world([{robot, {3.0, 2.0, 0.0}}]), {-50, 50}, 1000),
    assert_pose({3.0, 2.0, 1.25 * 180 / math:pi()}, torobot_world:pose(W1)),
    ?assert(distance(W1) < 1.0e-9),
    W2 = drive(world([{robot, {3.0, 2.0, 0.0}}]), {50, -50}, 1000),
    assert_pose({3.0, 2.0, -1.25 * 180 / math:pi()}, torobot_world:pose(W2)),
    %% Heading stays in (-180, 180] however long it spins.
    W3 = drive(world([{robot, {3.0, 2.0, 0.0}}]), {-100, 100}, 7000),
    {_, _, H3} = torobot_world:pose(W3),
    assert_close(normalise(2.5 * 7 * 180 / math:pi()), H3),
    ?assert(H3 > -180.0 andalso H3 =< 180.0).

step_size_independent() -> [{doc, "One long step lands where many short steps do (arcs are integrated exactly)."}].
step_size_independent(_Config) ->
    W0 = world([{robot, {2.0, 1.0, 10.0}}]),
    Long = torobot_world:step(W0, 2000, {30, 90}),
    Short = drive(W0, {30, 90}, 2000, 10),
    assert_pose(torobot_world:pose(Short), torobot_world:pose(Long)),
    assert_close(distance(Short), distance(Long)),
    ?assertEqual(torobot_world:time_ms(Short), torobot_world:time_ms(Long)).

velocities_clamped() -> [{doc, "Velocities beyond +-100 are clamped to it."}].
velocities_clamped(_Config) ->
    W0 = world([{robot, {1.0, 2.0, 0.0}}]),
    assert_pose(torobot_world:pose(drive(W0, {100, 100}, 1000)),
                torobot_world:pose(drive(W0, {250, 1000.0}, 1000))).

%%====================================================================
%% Collisions
%%====================================================================

drive_into_wall() -> [{doc, "Driving straight into a wall stops the robot touching it and counts one contact."}].
drive_into_wall(_Config) ->
    W = drive(world([{robot, {5.0, 2.0, 0.0}}]), {100, 100}, 10000),
    assert_pose({6.0 - 0.12, 2.0, 0.0}, torobot_world:pose(W)),
    assert_close(0.88, distance(W)),
    ?assertMatch(#{wall_contacts := 1, blue_contacts := 0, red_touched_ms := none},
                 torobot_world:summary(W)).

slide_along_wall() -> [{doc, "Meeting a wall at an angle slides along it, counted as one contact however long it slides."}].
slide_along_wall(_Config) ->
    W0 = world([{robot, {0.5, 3.0, 30.0}}]),
    W = drive(W0, {100, 100}, 12000),
    {X, Y, H} = torobot_world:pose(W),
    %% Hits the top wall near x = 2.0 and slides along it, heading unchanged.
    assert_close(4.0 - 0.12, Y),
    ?assert(X > 2.5 andalso X < 5.88),
    assert_close(30.0, H),
    ?assertMatch(#{wall_contacts := 1}, torobot_world:summary(W)),
    Ys = [Yi || {_, _, Yi, _} <- torobot_world:trajectory(W)],
    ?assert(lists:max(Ys) =< 4.0 - 0.12 + 1.0e-9).

second_approach_counts() -> [{doc, "Backing clearly away and driving in again counts a new contact; a 2 mm wobble does not."}].
second_approach_counts(_Config) ->
    W1 = drive(world([{robot, {5.5, 2.0, 0.0}}]), {100, 100}, 3000),
    Wobble = drive(drive(W1, {-100, -100}, 10, 10), {100, 100}, 1000),
    ?assertMatch(#{wall_contacts := 1}, torobot_world:summary(Wobble)),
    Again = drive(drive(Wobble, {-100, -100}, 500), {100, 100}, 3000),
    ?assertMatch(#{wall_contacts := 2}, torobot_world:summary(Again)).

corner() -> [{doc, "Driving into a corner ends touching both walls (two contacts), never outside."}].
corner(_Config) ->
    W = drive(world([{robot, {5.0, 3.0, 45.0}}]), {100, 100}, 10000),
    {X, Y, _} = torobot_world:pose(W),
    assert_close(6.0 - 0.12, X),
    assert_close(4.0 - 0.12, Y),
    ?assertMatch(#{wall_contacts := 2}, torobot_world:summary(W)).

inner_wall_not_crossed() -> [{doc, "A thin inner wall is never crossed, even with long steps at an angle."}].
inner_wall_not_crossed(_Config) ->
    W0 = world([{wall, {{3.0, 0.5}, {3.0, 3.5}}}, {robot, {2.0, 1.0, 20.0}}]),
    Ws = lists:foldl(fun(_, [W | _] = Acc) -> [torobot_world:step(W, 1000, {100, 100}) | Acc] end,
                     [W0], lists:seq(1, 15)),
    [?assert(X =< 3.0 - 0.12 + 1.0e-9) || W <- Ws, {X, _, _} <- [torobot_world:pose(W)]],
    ?assertMatch(#{wall_contacts := 1}, torobot_world:summary(hd(Ws))).

objects_are_solid() -> [{doc, "Objects stop the robot at contact; a blue contact is counted once."}].
objects_are_solid(_Config) ->
    W = drive(world([{object, blue, {3.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}]), {100, 100}, 15000),
    assert_pose({3.0 - 0.1 - 0.12, 2.0, 0.0}, torobot_world:pose(W)),
    ?assertMatch(#{blue_contacts := 1, wall_contacts := 0, red_touched_ms := none},
                 torobot_world:summary(W)).

red_touch_time() -> [{doc, "The time of the first red touch is recorded to within a sub-step."}].
red_touch_time(_Config) ->
    W = drive(world([{object, red, {3.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}},
                     {stop_on_red, false}]), {100, 100}, 15000),
    %% 2.0 - 0.22 m at 0.25 m/s.
    #{red_touched_ms := T} = torobot_world:summary(W),
    ?assert(abs(T - 7120) =< 10),
    assert_pose({3.0 - 0.22, 2.0, 0.0}, torobot_world:pose(W)).

stop_on_red() -> [{doc, "Touching red ends the run unless stop_on_red is false."}].
stop_on_red(_Config) ->
    Terms = [{object, red, {2.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}],
    Stops = drive(world(Terms), {100, 100}, 5000),
    ?assert(torobot_world:done(Stops)),
    Goes = drive(world([{stop_on_red, false} | Terms]), {100, 100}, 5000),
    ?assertNot(torobot_world:done(Goes)),
    ?assertMatch(#{red_touched_ms := T} when is_integer(T), torobot_world:summary(Goes)).

%%====================================================================
%% IR sensors
%%====================================================================

ir_monotonic() -> [{doc, "IR readings fall as a wall gets further away, within 10 bits, strictly inside the range."}].
ir_monotonic(_Config) ->
    Gaps = [0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 1.0, 2.0, 4.0],
    Readings = [torobot_world:ir(world([{robot, {6.0 - 0.12 - G, 2.0, 0.0}}])) || G <- Gaps],
    Lefts = [L || #{left := L} <- Readings],
    ?assertEqual(Lefts, [R || #{right := R} <- Readings]),
    ?assertEqual(lists:reverse(lists:sort(Lefts)), Lefts),
    [?assert(V >= 0 andalso V =< 1023) || V <- Lefts],
    %% Between about 10 and 60 cm of ray the curve strictly falls.
    Inside = [L || {G, L} <- lists:zip(Gaps, Lefts), G >= 0.1, G =< 0.5],
    ?assertEqual(length(Inside), length(lists:usort(Inside))),
    #{threshold_high := High, threshold_low := Low} =
        torobot_world:ir_thresholds(world([])),
    ?assert(hd(Lefts) >= High andalso lists:last(Lefts) =< Low).

ir_side() -> [{doc, "An obstacle ahead-left reads higher on the left sensor, ahead-right on the right."}].
ir_side(_Config) ->
    %% A short wall 0.3 m out along each sensor's axis.
    Left = ir_with_wall(30.0),
    Right = ir_with_wall(-30.0),
    ?assert(maps:get(left, Left) > maps:get(right, Left)),
    ?assert(maps:get(right, Right) > maps:get(left, Right)).

ir_sees_objects() -> [{doc, "Objects are obstacles to IR as walls are."}].
ir_sees_objects(_Config) ->
    A = math:pi() / 6,
    {Ox, Oy} = {3.0 + 0.4 * math:cos(A), 2.0 + 0.4 * math:sin(A)},
    Clear = torobot_world:ir(world([{robot, {3.0, 2.0, 0.0}}])),
    Seen = torobot_world:ir(world([{object, red, {Ox, Oy}, 0.1}, {robot, {3.0, 2.0, 0.0}}])),
    ?assert(maps:get(left, Seen) > maps:get(left, Clear)),
    ?assertEqual(maps:get(right, Clear), maps:get(right, Seen)).

ir_levels_hysteresis() -> [{doc, "Near at or above threshold_high, far at or below threshold_low, unchanged between."}].
ir_levels_hysteresis(_Config) ->
    At = fun(Gap) -> world([{robot, {6.0 - 0.12 - Gap, 2.0, 0.0}}]) end,
    Near = #{left => near, right => near},
    Far = #{left => far, right => far},
    #{threshold_high := High, threshold_low := Low} = torobot_world:ir_thresholds(At(1.0)),
    Between = hd([W || G <- lists:seq(5, 60), W <- [At(G / 100)],
                       #{left := L} <- [torobot_world:ir(W)], L < High, L > Low]),
    ?assertEqual(Near, torobot_world:ir_levels(Between, Near)),
    ?assertEqual(Far, torobot_world:ir_levels(Between, Far)),
    ?assertEqual(Near, torobot_world:ir_levels(At(0.05), Far)),
    ?assertEqual(Far, torobot_world:ir_levels(At(1.0), Near)).

%%====================================================================
%% Camera
%%====================================================================

camera_ahead() -> [{doc, "An object straight ahead is at x = 0, below the centre (the camera looks down on it), t = world time."}].
camera_ahead(_Config) ->
    W = torobot_world:step(world([{object, red, {3.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}]),
                           40, {0, 0}),
    [Red, Blue] = camera(W),
    ?assertMatch(#{<<"color">> := <<"red">>, <<"x">> := 0, <<"t">> := 40}, Red),
    ?assert(maps:get(<<"y">>, Red) > 0 andalso maps:get(<<"area">>, Red) > 0),
    ?assertEqual(#{<<"color">> => <<"blue">>, <<"none">> => true}, Blue).

camera_left_right() -> [{doc, "An object to the robot's right has x > 0, to its left x < 0, whatever the heading."}].
camera_left_right(_Config) ->
    [#{<<"x">> := Xr} | _] = camera(world([{object, red, {3.0, 1.5}, 0.1}, {robot, {1.0, 2.0, 0.0}}])),
    ?assert(Xr > 0),
    [#{<<"x">> := Xl} | _] = camera(world([{object, red, {3.0, 2.5}, 0.1}, {robot, {1.0, 2.0, 0.0}}])),
    ?assert(Xl < 0),
    %% Facing -y, +x is on the left.
    [_, #{<<"x">> := Xb}] = camera(world([{object, blue, {3.5, 1.0}, 0.1}, {robot, {3.0, 3.0, -90.0}}])),
    ?assert(Xb < 0).

camera_behind_wall() -> [{doc, "An object behind a wall is not seen."}].
camera_behind_wall(_Config) ->
    Terms = [{object, red, {4.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}],
    ?assertMatch([#{<<"x">> := 0}, _], camera(world(Terms))),
    ?assertMatch([#{<<"none">> := true}, _],
                 camera(world([{wall, {{2.5, 1.5}, {2.5, 2.5}}} | Terms]))).

camera_out_of_fov() -> [{doc, "Objects outside the 60 degree field of view (or behind) are not seen; inside it they are."}].
camera_out_of_fov(_Config) ->
    At = fun(Deg) ->
                 A = Deg * math:pi() / 180,
                 camera(world([{object, blue, {3.0 + math:cos(A), 2.0 + math:sin(A)}, 0.1},
                               {robot, {3.0, 2.0, 0.0}}]))
         end,
    [?assertMatch([_, #{<<"none">> := true}], At(D)) || D <- [-180, -90, -40, 35, 90]],
    [?assertMatch([_, #{<<"x">> := _}], At(D)) || D <- [-25, 0, 25]],
    [_, #{<<"x">> := X25}] = At(25),
    [_, #{<<"x">> := Xm25}] = At(-25),
    ?assert(X25 < 0 andalso Xm25 > 0 andalso X25 >= -160).

camera_out_of_range() -> [{doc, "Objects beyond the camera's range are not seen."}].
camera_out_of_range(_Config) ->
    Far = [{object, red, {5.7, 2.0}, 0.1}, {robot, {0.5, 2.0, 0.0}}],
    ?assertMatch([#{<<"none">> := true}, _], camera(world(Far))),
    ?assertMatch([#{<<"x">> := _}, _], camera(world([{camera, #{range => 6.0}} | Far]))).

camera_occlusion_by_object() -> [{doc, "An object hides another behind it on the line of sight."}].
camera_occlusion_by_object(_Config) ->
    W = world([{object, blue, {2.5, 2.0}, 0.1}, {object, red, {4.0, 2.0}, 0.1},
               {robot, {1.0, 2.0, 0.0}}]),
    ?assertMatch([#{<<"none">> := true}, #{<<"x">> := 0}], camera(W)).

camera_largest() -> [{doc, "Of two objects of one colour the larger in the image is reported."}].
camera_largest(_Config) ->
    W = world([{object, red, {4.0, 2.5}, 0.1}, {object, red, {2.0, 1.7}, 0.1},
               {robot, {1.0, 2.0, 0.0}}]),
    [#{<<"x">> := X}, _] = camera(W),
    ?assert(X > 0).

camera_area_shrinks() -> [{doc, "Apparent area falls with the square of the distance."}].
camera_area_shrinks(_Config) ->
    Area = fun(D) ->
                   [#{<<"area">> := A}, _] =
                       camera(world([{object, red, {1.0 + D, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}])),
                   A
           end,
    Ratio = Area(1.0) / Area(2.0),
    ?assert(Ratio > 3.8 andalso Ratio < 4.2),
    ?assert(Area(0.5) > Area(1.0)).

camera_datagram_keys() -> [{doc, "Datagrams are one red then one blue, decoding to exactly the SPEC section 7 keys."}].
camera_datagram_keys(_Config) ->
    Seen = torobot_world:step(world([{object, red, {3.0, 2.0}, 0.1},
                                     {object, blue, {3.0, 2.5}, 0.1},
                                     {robot, {1.0, 2.0, 0.0}}]), 120, {0, 0}),
    [R, B] = [jiffy:decode(D, [return_maps]) || D <- torobot_world:camera(Seen)],
    Keys = [<<"area">>, <<"color">>, <<"t">>, <<"x">>, <<"y">>],
    ?assertEqual(Keys, lists:sort(maps:keys(R))),
    ?assertEqual(Keys, lists:sort(maps:keys(B))),
    ?assertMatch(#{<<"color">> := <<"red">>, <<"t">> := 120}, R),
    ?assertMatch(#{<<"color">> := <<"blue">>, <<"t">> := 120}, B),
    [?assert(is_integer(V)) || M <- [R, B], K <- Keys -- [<<"color">>], V <- [maps:get(K, M)]],
    [NR, NB] = [jiffy:decode(D, [return_maps]) || D <- torobot_world:camera(world([]))],
    ?assertEqual(#{<<"color">> => <<"red">>, <<"none">> => true}, NR),
    ?assertEqual(#{<<"color">> => <<"blue">>, <<"none">> => true}, NB).

camera_datagram_text() -> [{doc, "The datagrams are the detector's text byte for byte: compact, "
                            "keys in the order color, x, y, area, t (or color, none)."}].
camera_datagram_text(_Config) ->
    Seen = torobot_world:step(world([{object, red, {3.0, 2.0}, 0.1},
                                     {object, blue, {3.0, 2.5}, 0.1},
                                     {robot, {1.0, 2.0, 0.0}}]), 120, {0, 0}),
    ?assertEqual([<<"{\"color\":\"red\",\"x\":0,\"y\":14,\"area\":603,\"t\":120}">>,
                  <<"{\"color\":\"blue\",\"x\":-69,\"y\":14,\"area\":568,\"t\":120}">>],
                 torobot_world:camera(Seen)),
    ?assertEqual([<<"{\"color\":\"red\",\"none\":true}">>, <<"{\"color\":\"blue\",\"none\":true}">>],
                 torobot_world:camera(world([]))).

%%====================================================================
%% The run
%%====================================================================

summary_keys() -> [{doc, "The summary has exactly the four keys of SPEC section 8, with their types."}].
summary_keys(_Config) ->
    W = drive(world([{object, red, {2.0, 2.0}, 0.1}, {robot, {1.0, 2.0, 0.0}}]), {100, 100}, 5000),
    S = torobot_world:summary(W),
    ?assertEqual([blue_contacts, distance_m, red_touched_ms, wall_contacts], lists:sort(maps:keys(S))),
    #{red_touched_ms := T, wall_contacts := Wc, blue_contacts := Bc, distance_m := D} = S,
    ?assert(is_integer(T) andalso T >= 0),
    ?assert(is_integer(Wc) andalso is_integer(Bc) andalso is_float(D)).

done_at_duration() -> [{doc, "The run is done once world time reaches duration_s."}].
done_at_duration(_Config) ->
    W = world([{duration_s, 1}]),
    ?assertNot(torobot_world:done(drive(W, {0, 0}, 950))),
    ?assert(torobot_world:done(drive(W, {0, 0}, 1000))).

trajectory_tags() -> [{doc, "Each step records the time, position and the caller's tag; step/3 tags none."}].
trajectory_tags(_Config) ->
    W0 = world([{robot, {1.0, 2.0, 0.0}}]),
    W1 = torobot_world:step(W0, 1000, {100, 100}, forward),
    W2 = torobot_world:step(W1, 500, {-100, 100}, {avoid, left}),
    W3 = torobot_world:step(W2, 0, {0, 0}),
    [{0, 1.0, 2.0, start}, {1000, X1, Y1, forward}, {1500, X1, Y1, {avoid, left}},
     {1500, X1, Y1, none}] = torobot_world:trajectory(W3),
    assert_close(1.25, X1),
    assert_close(2.0, Y1).

%%====================================================================
%% SVG
%%====================================================================

svg_parses() -> [{doc, "The picture is well-formed SVG with one polyline per run of a tag and a legend entry per tag."}].
svg_parses(_Config) ->
    W0 = world([{wall, {{4.0, 1.0}, {4.0, 3.0}}}, {object, red, {5.0, 1.0}, 0.1},
                {object, blue, {2.0, 3.5}, 0.1}, {robot, {1.0, 1.0, 30.0}}]),
    Steps = [{forward, {80, 80}, 2000}, {avoid_left, {60, -60}, 400},
             {forward, {80, 80}, 2000}, {"odd <&> \"tag\"", {100, 60}, 1000}],
    W = lists:foldl(fun({Tag, V, Ms}, Acc) -> drive(Acc, V, Ms, 50, Tag) end, W0, Steps),
    {Svg, []} = xmerl_scan:string(binary_to_list(iolist_to_binary(torobot_svg:render(W)))),
    ?assertMatch(#xmlElement{name = svg}, Svg),
    ?assertEqual(4, length(xmerl_xpath:string("//polyline", Svg))),
    Legend = [V || #xmlText{value = V} <- xmerl_xpath:string("//g[@id='legend']/text/text()", Svg)],
    ?assertEqual(["forward", "avoid_left", "\"odd <&> \\\"tag\\\"\""], Legend),
    ?assertEqual(2, length(xmerl_xpath:string("//g[@id='objects']/circle", Svg))),
    ?assertEqual(1, length(xmerl_xpath:string("//g[@id='walls']/line", Svg))),
    [#xmlText{value = Caption}] = xmerl_xpath:string("//text[@id='caption']/text()", Svg),
    ?assertNotEqual(nomatch, string:find(Caption, "wall contacts")).

svg_write() -> [{doc, "write/2 leaves exactly the rendered picture at the path and no temporary file."}].
svg_write(Config) ->
    Dir = ?config(priv_dir, Config),
    Path = filename:join(Dir, "run.svg"),
    W = drive(world([]), {100, 90}, 3000, 50, forward),
    ok = torobot_svg:write(W, Path),
    {ok, Bin} = file:read_file(Path),
    ?assertEqual(iolist_to_binary(torobot_svg:render(W)), Bin),
    ?assertEqual([], filelib:wildcard(filename:join(Dir, "*.tmp"))),
    ?assertMatch({error, _}, torobot_svg:write(W, filename:join([Dir, "no_dir", "run.svg"]))).

svg_empty_run() -> [{doc, "A world that has not moved still draws as well-formed SVG with no trajectory."}].
svg_empty_run(_Config) ->
    {Svg, []} = xmerl_scan:string(binary_to_list(iolist_to_binary(torobot_svg:render(world([]))))),
    ?assertEqual([], xmerl_xpath:string("//polyline", Svg)).

%%====================================================================
%% Several robots
%%====================================================================

robots_load() -> [{doc, "Named robots give one world each, in file order, each with the others as bodies; load/1 refuses several."}].
robots_load(_Config) ->
    Terms = [{arena, {6.0, 4.0}}, {duration_s, 10}, {robot, a, {1.0, 2.0, 0.0}},
             {robot, b, {5.0, 2.0, 180.0}, #{colour => red}}],
    {ok, [A, B]} = torobot_world:from_terms_all(Terms),
    ?assertEqual({a, b}, {torobot_world:name(A), torobot_world:name(B)}),
    assert_pose({5.0, 2.0, 180.0}, torobot_world:start_pose(B)),
    ?assertMatch({b, {5.0, 2.0}, 0.12, red}, torobot_world:body(B)),
    ?assertEqual({error, {several_robots, [a, b]}}, torobot_world:from_terms(Terms)),
    %% one named robot is a world of one
    {ok, One} = torobot_world:from_terms(lists:droplast(Terms)),
    ?assertEqual(a, torobot_world:name(One)),
    %% the one-robot form has no name
    ?assertEqual(undefined, torobot_world:name(world([]))).

robots_refused() -> [{doc, "A repeated name, both robot forms, or robots starting on each other are refused naming the term."}].
robots_refused(_Config) ->
    Base = [{arena, {6.0, 4.0}}, {duration_s, 10}],
    A = {robot, a, {1.0, 2.0, 0.0}},
    ?assertEqual({error, {duplicate, {robot, a, {3.0, 2.0, 0.0}}}},
                 torobot_world:from_terms_all(Base ++ [A, {robot, a, {3.0, 2.0, 0.0}}])),
    ?assertEqual({error, {duplicate, A}},
                 torobot_world:from_terms_all(Base ++ [{robot, {3.0, 2.0, 0.0}}, A])),
    Near = {robot, b, {1.2, 2.0, 0.0}},
    ?assertEqual({error, {blocked_start, A, Near}}, torobot_world:from_terms_all(Base ++ [A, Near])),
    Odd = {robot, c, {3.0, 2.0, 0.0}, #{colour => green}},
    ?assertEqual({error, {bad_term, Odd}}, torobot_world:from_terms_all(Base ++ [A, Odd])).

robots_are_solid() -> [{doc, "A robot driving into another stops touching it and counts one robot contact; the other counts none until it moves."}].
robots_are_solid(_Config) ->
    {ok, [A, B]} = torobot_world:from_terms_all(
                     [{arena, {6.0, 4.0}}, {duration_s, 60},
                      {robot, a, {1.0, 2.0, 0.0}}, {robot, b, {2.0, 2.0, 0.0}}]),
    Among = torobot_world:set_others(A, [torobot_world:body(B)]),
    Driven = drive(Among, {100, 100}, 8000),
    {X, _, _} = torobot_world:pose(Driven),
    assert_close(2.0 - 0.24, X),
    ?assertMatch(#{robot_contacts := 1, wall_contacts := 0}, torobot_world:summary(Driven)).

robots_seen_by_ir() -> [{doc, "Another robot ahead-left reads on the left IR sensor as an obstacle does."}].
robots_seen_by_ir(_Config) ->
    A = math:pi() / 6,
    Other = {b, {3.0 + 0.4 * math:cos(A), 2.0 + 0.4 * math:sin(A)}, 0.12, none},
    Clear = torobot_world:ir(world([])),
    Seen = torobot_world:ir(torobot_world:set_others(world([]), [Other])),
    ?assert(maps:get(left, Seen) > maps:get(left, Clear)),
    ?assertEqual(maps:get(right, Clear), maps:get(right, Seen)).

robots_colour_seen() -> [{doc, "The camera sees another robot's colour when it carries one, and nothing when it does not; robots hide objects behind them."}].
robots_colour_seen(_Config) ->
    W = world([{object, blue, {5.0, 2.0}, 0.1}]),
    Red = {b, {4.0, 2.0}, 0.12, red},
    Plain = {b, {4.0, 2.0}, 0.12, none},
    [#{<<"color">> := <<"red">>, <<"x">> := 0}, #{<<"none">> := true}] =
        camera(torobot_world:set_others(W, [Red])),
    [#{<<"none">> := true}, #{<<"none">> := true}] =
        camera(torobot_world:set_others(W, [Plain])),
    [#{<<"none">> := true}, #{<<"color">> := <<"blue">>}] = camera(W).

robots_summary_and_svg() -> [{doc, "A named robot's summary adds robot_contacts; one picture draws every robot with its name and caption."}].
robots_summary_and_svg(_Config) ->
    {ok, Ws} = torobot_world:from_terms_all(
                 [{arena, {6.0, 4.0}}, {duration_s, 60},
                  {robot, a, {1.0, 1.0, 0.0}}, {robot, b, {1.0, 3.0, 0.0}}]),
    Driven = [drive(W, {80, 80}, 2000, 50, forward) || W <- Ws],
    [?assertEqual([blue_contacts, distance_m, red_touched_ms, robot_contacts, wall_contacts],
                  lists:sort(maps:keys(torobot_world:summary(W)))) || W <- Driven],
    {Svg, []} = xmerl_scan:string(binary_to_list(iolist_to_binary(torobot_svg:render_all(Driven)))),
    ?assertEqual(2, length(xmerl_xpath:string("//polyline", Svg))),
    [_] = xmerl_xpath:string("//g[@id='final-a']", Svg),
    [_] = xmerl_xpath:string("//g[@id='final-b']", Svg),
    [#xmlText{value = "b: " ++ _}] = xmerl_xpath:string("//text[@id='caption-b']/text()", Svg),
    Legend = [V || #xmlText{value = V} <- xmerl_xpath:string("//g[@id='legend']/text/text()", Svg)],
    ?assertEqual(["forward"], Legend).

%%====================================================================
%% Modules
%%====================================================================

no_module_cycle() -> [{doc, "No two modules of torobot call each other, directly or round a cycle "
                       "(torobot_world and torobot_sensors were one)."}].
no_module_cycle(_Config) ->
    with_xref(fun(X) ->
                      {ok, Components} = xref:q(X, "components (ME || torobot : App)"),
                      ?assertEqual([], [C || C <- Components, length(C) > 1])
              end).

world_record_stays_inside() -> [{doc, "Only torobot_world calls the modules that share the world "
                                 "record (torobot_world_file, _step, _sensing): the rest of the "
                                 "project uses its API."}].
world_record_stays_inside(_Config) ->
    Inside = [torobot_world, torobot_world_file, torobot_world_step, torobot_world_sensing],
    with_xref(fun(X) ->
                      {ok, Calls} = xref:q(X, "ME"),
                      ?assertEqual([], [{From, To} || {From, To} <- Calls,
                                                      lists:member(To, tl(Inside)),
                                                      not lists:member(From, Inside)])
              end).

with_xref(Check) ->
    {ok, X} = xref:start([{xref_mode, modules}]),
    try
        ok = xref:set_default(X, [{warnings, false}, {verbose, false}]),
        [{ok, _} = xref:add_application(X, code:lib_dir(App), [{name, App}])
         || App <- [torobot, toroco_lib, toroco_live, toroco_hw]],
        Check(X)
    after
        xref:stop(X)
    end.

%%====================================================================
%% Helpers
%%====================================================================

%% A 6 x 4 m arena with the robot in the middle; Extra replaces or adds terms.
base() ->
    [{arena, {6.0, 4.0}}, {robot, {3.0, 2.0, 0.0}}, {duration_s, 60}].

world(Extra) ->
    Singles = [element(1, T) || T <- Extra, element(1, T) =/= wall, element(1, T) =/= object],
    {ok, W} = torobot_world:from_terms([T || T <- base(), not lists:member(element(1, T), Singles)]
                                       ++ Extra),
    W.

drive(W, Vels, Ms) -> drive(W, Vels, Ms, 50).

drive(W, Vels, Ms, Tick) -> drive(W, Vels, Ms, Tick, none).

drive(W, _Vels, Ms, _Tick, _Tag) when Ms =< 0 -> W;
drive(W, Vels, Ms, Tick, Tag) ->
    drive(torobot_world:step(W, min(Tick, Ms), Vels, Tag), Vels, Ms - Tick, Tick, Tag).

distance(W) -> maps:get(distance_m, torobot_world:summary(W)).

camera(W) -> [jiffy:decode(D, [return_maps]) || D <- torobot_world:camera(W)].

ir_with_wall(Deg) ->
    A = Deg * math:pi() / 180,
    {Cx, Cy} = {3.0 + 0.42 * math:cos(A), 2.0 + 0.42 * math:sin(A)},
    {Nx, Ny} = {-math:sin(A) * 0.1, math:cos(A) * 0.1},
    torobot_world:ir(world([{wall, {{Cx - Nx, Cy - Ny}, {Cx + Nx, Cy + Ny}}}])).

assert_pose({X, Y, H}, {X1, Y1, H1}) ->
    assert_close(X, X1),
    assert_close(Y, Y1),
    assert_close(0.0, normalise(H - H1)).

assert_close(Expected, Actual) ->
    case abs(Expected - Actual) < 1.0e-6 of
        true -> ok;
        false -> ct:fail({not_close, Expected, Actual})
    end.

normalise(Deg) ->
    R = Deg * math:pi() / 180,
    math:atan2(math:sin(R), math:cos(R)) * 180 / math:pi().

write_world(Config, Name, Terms) ->
    File = filename:join(?config(priv_dir, Config), Name),
    ok = file:write_file(File, [io_lib:format("~tp.~n", [T]) || T <- Terms]),
    File.

%% The checkout's root: the first directory holding config/worlds above this
%% suite's source, its beam or the current directory, so the suite runs the
%% same by hand and from rebar3's _build copy.
repo_root() ->
    Source = proplists:get_value(source, ?MODULE:module_info(compile), "."),
    {ok, Cwd} = file:get_cwd(),
    Starts = [filename:dirname(filename:absname(Path)) || Path <- [Source, code:which(?MODULE)]]
        ++ [Cwd],
    case lists:filtermap(fun(D) -> up_to_worlds(D) end, Starts) of
        [Root | _] -> Root;
        [] -> ct:fail({no_worlds_above, Starts})
    end.

up_to_worlds(Dir) ->
    case filelib:is_file(filename:join([Dir, "config", "worlds", "default.world"])) of
        true -> {true, Dir};
        false ->
            case filename:dirname(Dir) of
                Dir -> false;
                Parent -> up_to_worlds(Parent)
            end
    end.
