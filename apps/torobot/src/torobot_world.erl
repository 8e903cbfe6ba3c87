%% @doc The Torobot's simulated world as a pure value.
%%
%% A world is an arena with walls, red and blue objects and one Torobot: a
%% differential-drive disc with two Sharp IR distance sensors and a camera.
%% This module is the functional core of the simulator: `torobot_sim' (the
%% process that ticks it in real time) calls {@link step/4} each tick with the
%% motor velocities and the name of the behavior that won the motors, reads
%% {@link ir/1} and {@link camera/1}, and hands them to the same devices the
%% board uses; `torobot_svg' draws the run. Nothing here starts a process or
%% does I/O, except {@link load/1} reading the world file.
%%
%% <h3>World files</h3>
%% A world is a `file:consult/1' file (or the same terms given to
%% {@link from_terms/1}). Required, once each:
%% <ul>
%% <li>`{arena, {W, H}}': metres; walls all around, origin bottom-left.</li>
%% <li>`{robot, {X, Y, HeadingDeg}}': start pose; heading 0 = +x,
%%     counter-clockwise positive.</li>
%% <li>or, for several robots, any number of `{robot, Name, {X, Y,
%%     HeadingDeg}}' (optionally a fourth element `#{colour => red | blue}',
%%     a colour the robot carries for the others' cameras): one world value
%%     per robot, from {@link load_all/1} or {@link from_terms_all/1}, each
%%     seeing the others as solid discs ({@link set_others/2}); contacts
%%     with them are counted per robot as `robot_contacts'.</li>
%% <li>`{duration_s, S}': the run ends at S seconds.</li>
%% </ul>
%% Any number of:
%% <ul>
%% <li>`{wall, {{X1, Y1}, {X2, Y2}}}': a wall segment inside the arena.</li>
%% <li>`{object, red | blue, {X, Y}, Radius}': a ball resting on the floor.</li>
%% </ul>
%% Optional, at most once each (defaults in brackets):
%% <ul>
%% <li>`{robot_geometry, #{radius => 0.12, wheel_base => 0.20,
%%     max_wheel_speed => 0.25}}': metres, and m/s of a wheel at velocity 100.</li>
%% <li>`{ir, #{mount_deg => 30, min_range => 0.10, max_range => 0.80,
%%     curve => {6787, 4, 3}, threshold_high => 240, threshold_low => 200,
%%     noise => 0}}': sensors at ±`mount_deg' on the robot's rim; a reading
%%     is the 10-bit ADC value `K / (Dcm + D0) + C' of a GP2D12 for
%%     `curve => {K, D0, C}' and the distance `Dcm' (centimetres, clamped
%%     to `[min_range, max_range]'; nothing in range reads as `max_range').
%%     The thresholds are ADC levels: near at or above `threshold_high', far
%%     again at or below `threshold_low' (about 24 and 30 cm). `noise' is a
%%     standard deviation in ADC counts.</li>
%% <li>`{camera, #{fov_deg => 60, frame => {320, 240}, range => 4.0,
%%     height => 0.20, min_area => 10, noise => 0}}': a pinhole camera at the
%%     robot's centre, `height' metres above the floor, looking along the
%%     heading; `range' in metres, `min_area' the detector's smallest blob in
%%     pixels, `noise' a standard deviation in pixels.</li>
%% <li>`{seed, 1}': seeds the sensor noise; the same world, seed and
%%     commands give the same run.</li>
%% <li>`{tick_ms, 50}': the period the simulator should step the world with.</li>
%% <li>`{stop_on_red, true}': whether touching a red object ends the run.</li>
%% </ul>
%% The sensors and fixtures of the library's robots (range sensors,
%% bumpers, odometry, lights and light sensors, a dock and its beacon) and
%% the figures a run is measured by are terms of `torobot_sensors', all
%% optional; their doc is there.
%%
%% A bad world gives `{error, Reason}' naming the culprit: `{file, Why}',
%% `{bad_term, Term}', `{duplicate, Term}', `{missing, arena | robot |
%% duration_s}', `{outside_arena, Term}' or `{blocked_start, RobotTerm,
%% ObstacleTerm}' (the robot starts overlapping a wall or an object).
%%
%% <h3>Kinematics, collisions and contacts</h3>
%% Wheel velocities are servo commands in -100..100 (clamped), positive
%% forward on both wheels, mapped linearly to `max_wheel_speed'. A step is
%% integrated in sub-steps of at most 10 ms along exact arcs. Walls
%% (including the arena's) and objects are solid: a move that would overlap
%% one is projected back to touching it, so the robot stops when it drives
%% straight in and slides when it comes at an angle. A contact begins when
%% the robot comes within 0.1 mm of an obstacle it was not touching and ends
%% when it is more than 5 mm away; each beginning is counted once per
%% obstacle (a corner where two walls meet counts as two). Distance
%% travelled is the path length of the robot's centre.
%%
%% <h3>Sensors</h3>
%% IR: one ray from each sensor, stopped by walls and objects. Camera: an
%% object is seen when its centre is ahead within half the field of view and
%% within range, the line of sight to its centre crosses no wall and no other
%% object, and its apparent area reaches `min_area'. The image `y' of a
%% centre below the frame is clamped to the frame's edge, where the detector
%% would find the visible part of the ball. Of each colour the largest
%% (closest) object is reported.
%%
%% Functions by purpose: building ({@link load/1}, {@link from_terms/1});
%% stepping ({@link step/3}, {@link step/4}); sensing ({@link ir/1},
%% {@link ir_levels/2}, {@link ir_thresholds/1}, {@link camera/1}); the run
%% ({@link time_ms/1}, {@link pose/1}, {@link done/1}, {@link summary/1},
%% {@link trajectory/1}); the scene ({@link arena/1}, {@link walls/1},
%% {@link objects/1}, {@link start_pose/1}, {@link robot_radius/1},
%% {@link tick_ms/1}, {@link duration_ms/1}).
-module(torobot_world).

-export([load/1, from_terms/1, load_all/1, from_terms_all/1]).
-export([step/3, step/4]).
-export([ir/1, ir_levels/2, ir_thresholds/1, camera/1, view/1]).
-export([time_ms/1, pose/1, done/1, summary/1, trajectory/1]).
-export([arena/1, walls/1, objects/1, start_pose/1, robot_radius/1,
         tick_ms/1, duration_ms/1]).
-export([name/1, body/1, set_others/2]).
%% For the sensor models of `torobot_sensors'.
-export([extras/1, geometry/1, range/3, contact_bearings/1, line_of_sight/3, free/2]).

-export_type([world/0, colour/0, point/0, pose/0, velocity/0, tag/0,
              sample/0, summary/0, ir_reading/0, ir_levels/0, reason/0, body/0]).

-type colour() :: red | blue.
-type point() :: {X :: float(), Y :: float()}.
-type pose() :: {X :: float(), Y :: float(), HeadingDeg :: float()}.
%% Heading in degrees in (-180, 180], 0 = +x, counter-clockwise positive.
-type velocity() :: number().
%% A servo command in -100..100; values outside are clamped.
-type tag() :: term().
-type sample() :: {TimeMs :: non_neg_integer(), X :: float(), Y :: float(), tag()}.
-type summary() :: #{red_touched_ms := non_neg_integer() | none,
                     wall_contacts := non_neg_integer(),
                     blue_contacts := non_neg_integer(),
                     distance_m := float(),
                     robot_contacts => non_neg_integer(),
                     %% the figures a world asks for (torobot_sensors)
                     atom() => term()}.
-type adc() :: 0..1023.
-type ir_reading() :: #{left := adc(), right := adc()}.
-type ir_levels() :: #{left := near | far, right := near | far}.
-type reason() :: {file, term()}
                | {bad_term, term()}
                | {duplicate, term()}
                | {missing, arena | robot | duration_s}
                | {outside_arena, term()}
                | {blocked_start, term(), term()}
                | {several_robots, [atom()]}.
%% A robot as the others see it: name, centre, radius and the colour it
%% carries (`none' when it carries none).
-type body() :: {atom() | undefined, point(), float(), colour() | none}.

-type key() :: {wall, pos_integer()} | {colour(), pos_integer()} | {robot, atom()}.
-type shape() :: {segment, point(), point()} | {disc, point(), float()}.
-type obstacle() :: {key(), shape(), Source :: term()}.
%% What the camera makes of an object: {Area, -Distance, X, Y}, so that
%% the largest blob, then the closest, is the maximum.
-type blob() :: {non_neg_integer(), float(), integer(), integer()}.

-record(world, {
          arena :: {float(), float()},
          walls :: [{point(), point()}],
          objects :: [{colour(), point(), float()}],
          obstacles :: [obstacle()],
          start :: pose(),
          pos :: point(),
          theta :: float(),
          time_ms = 0 :: non_neg_integer(),
          duration_ms :: pos_integer(),
          geometry :: map(),
          ir :: map(),
          camera :: map(),
          seed :: integer(),
          tick_ms :: pos_integer(),
          stop_on_red :: boolean(),
          touching = [] :: ordsets:ordset(key()),
          wall_contacts = 0 :: non_neg_integer(),
          blue_contacts = 0 :: non_neg_integer(),
          red_touched_ms = none :: non_neg_integer() | none,
          distance = 0.0 :: float(),
          trajectory = [] :: [sample()],
          extras = #{} :: map(),
          %% Several robots in one world: this robot's name and colour, the
          %% other robots where the simulator last put them, and the
          %% contacts with them.
          name :: atom() | undefined,
          colour = none :: colour() | none,
          others = [] :: [body()],
          robot_contacts = 0 :: non_neg_integer()
         }).

-opaque world() :: #world{}.

-define(GEOMETRY, #{radius => 0.12, wheel_base => 0.20, max_wheel_speed => 0.25}).
-define(IR, #{mount_deg => 30, min_range => 0.10, max_range => 0.80,
              curve => {6787, 4, 3}, threshold_high => 240, threshold_low => 200,
              noise => 0}).
-define(CAMERA, #{fov_deg => 60, frame => {320, 240}, range => 4.0,
                  height => 0.20, min_area => 10, noise => 0}).
-define(SINGLE, [arena, robot, duration_s, robot_geometry, ir, camera, seed,
                 tick_ms, stop_on_red]).

%% Sub-steps keep a move far shorter than the robot's radius, so it can never
%% jump over a wall segment.
-define(MAX_SUBSTEP_MS, 10).
-define(TOUCH, 1.0e-4).
-define(RELEASE, 5.0e-3).
%% Overlaps smaller than this are rounding, not penetration.
-define(SLACK, 1.0e-9).

%%====================================================================
%% Building
%%====================================================================

%% @doc Reads a world file (`file:consult/1' terms, see the module doc).
-spec load(file:name_all()) -> {ok, world()} | {error, reason()}.
load(File) ->
    case file:consult(File) of
        {ok, Terms} -> from_terms(Terms);
        {error, Why} -> {error, {file, Why}}
    end.

%% @doc Builds a world from the terms of a world file. A world of several
%% robots is refused as `{several_robots, Names}': see {@link from_terms_all/1}.
-spec from_terms([term()]) -> {ok, world()} | {error, reason()}.
from_terms(Terms) ->
    case from_terms_all(Terms) of
        {ok, [World]} -> {ok, World};
        {ok, Worlds} -> {error, {several_robots, [name(W) || W <- Worlds]}};
        {error, _} = Error -> Error
    end.

%% @doc Reads a world file of any number of robots: one world per robot,
%% in file order (see {@link from_terms_all/1}).
-spec load_all(file:name_all()) -> {ok, [world(), ...]} | {error, reason()}.
load_all(File) ->
    case file:consult(File) of
        {ok, Terms} -> from_terms_all(Terms);
        {error, Why} -> {error, {file, Why}}
    end.

%% @doc Builds one world per robot of a world file: the same scene, each
%% with its own robot and the others as bodies ({@link set_others/2}).
%% Robots are either the one `{robot, Pose}' or any number of
%% `{robot, Name, Pose}' / `{robot, Name, Pose, #{colour => red | blue}}'
%% with distinct names; mixing the forms or repeating a name is
%% `{duplicate, Term}', robots starting on each other `{blocked_start,
%% RobotTerm, OtherRobotTerm}'.
-spec from_terms_all([term()]) -> {ok, [world(), ...]} | {error, reason()}.
from_terms_all(Terms) when is_list(Terms) ->
    case parse(Terms, #{wall => [], object => [], robots => []}) of
        {ok, #{robots := []} = Parsed} ->
            case build(Parsed) of
                {ok, World} -> {ok, [World]};
                {error, _} = Error -> Error
            end;
        {ok, #{robots := Named} = Parsed} ->
            fleet(lists:reverse(Named), Parsed);
        {error, _} = Error ->
            Error
    end;
from_terms_all(Other) ->
    {error, {bad_term, Other}}.

-spec fleet([{{atom(), pose(), colour() | none}, term()}], map()) ->
          {ok, [world(), ...]} | {error, reason()}.
fleet([{_, First} | _], #{robot := _}) ->
    {error, {duplicate, First}};
fleet(Named, Parsed) ->
    {Repeated, _} = lists:foldl(fun({{Name, _, _}, T}, {Dups, Seen}) ->
                                        case lists:member(Name, Seen) of
                                            true -> {Dups ++ [T], Seen};
                                            false -> {Dups, [Name | Seen]}
                                        end
                                end, {[], []}, Named),
    Built = [{build(Parsed#{robot => {Pose, Term}}), Name, Colour, Term}
             || {{Name, Pose, Colour}, Term} <- Named],
    case {Repeated, [E || {{error, _} = E, _, _, _} <- Built]} of
        {[Term | _], _} ->
            {error, {duplicate, Term}};
        {[], [Error | _]} ->
            Error;
        {[], []} ->
            Worlds = [W#world{name = Name, colour = Colour}
                      || {{ok, W}, Name, Colour, _} <- Built],
            Terms = [T || {_, _, _, T} <- Built],
            Overlaps = [{A, B} || {I, WA, A} <- lists:zip3(lists:seq(1, length(Worlds)), Worlds, Terms),
                                  {J, WB, B} <- lists:zip3(lists:seq(1, length(Worlds)), Worlds, Terms),
                                  I < J, overlapping(WA, WB)],
            case Overlaps of
                [{A, B} | _] -> {error, {blocked_start, A, B}};
                [] -> {ok, [set_others(W, [body(O) || O <- Worlds, O =/= W]) || W <- Worlds]}
            end
    end.

-spec overlapping(world(), world()) -> boolean().
overlapping(A, B) ->
    {_, Pa, Ra, _} = body(A),
    {_, Pb, Rb, _} = body(B),
    distance(Pa, Pb) - Ra - Rb < -?SLACK.

-spec parse([term()] | term(), map()) -> {ok, map()} | {error, reason()}.
parse([], Acc) ->
    {ok, Acc};
parse([Term | Terms], Acc) ->
    case term(Term) of
        {ok, Key, Value} ->
            case lists:member(Key, ?SINGLE ++ torobot_sensors:single_terms()) of
                true when is_map_key(Key, Acc) ->
                    {error, {duplicate, Term}};
                true ->
                    parse(Terms, Acc#{Key => {Value, Term}});
                false ->
                    parse(Terms, maps:update_with(Key, fun(L) -> [{Value, Term} | L] end,
                                                      [{Value, Term}], Acc))
            end;
        error ->
            {error, {bad_term, Term}}
    end;
parse(Improper, _Acc) ->
    {error, {bad_term, Improper}}.

%% Checks one term on its own; returns the value with numbers as floats.
-spec term(term()) -> {ok, atom(), term()} | error.
term({arena, {W, H}}) when is_number(W), is_number(H), W > 0, H > 0 ->
    {ok, arena, {float(W), float(H)}};
term({wall, {A, B}}) ->
    case {point(A), point(B)} of
        {{ok, PA}, {ok, PB}} when PA =/= PB -> {ok, wall, {PA, PB}};
        _ -> error
    end;
term({object, Colour, C, R}) when (Colour =:= red orelse Colour =:= blue),
                                  is_number(R), R > 0 ->
    case point(C) of
        {ok, P} -> {ok, object, {Colour, P, float(R)}};
        error -> error
    end;
term({robot, {X, Y, H}}) when is_number(X), is_number(Y), is_number(H) ->
    {ok, robot, {float(X), float(Y), float(H)}};
term({robot, Name, {X, Y, H}}) when is_atom(Name), is_number(X), is_number(Y), is_number(H) ->
    {ok, robots, {Name, {float(X), float(Y), float(H)}, none}};
term({robot, Name, Pose, #{colour := Colour} = Opts})
  when map_size(Opts) =:= 1, (Colour =:= red orelse Colour =:= blue) ->
    case term({robot, Name, Pose}) of
        {ok, robots, {Name, P, none}} -> {ok, robots, {Name, P, Colour}};
        error -> error
    end;
term({duration_s, S}) when is_number(S), S > 0 ->
    {ok, duration_s, S};
term({seed, N}) when is_integer(N) ->
    {ok, seed, N};
term({tick_ms, N}) when is_integer(N), N > 0 ->
    {ok, tick_ms, N};
term({stop_on_red, B}) when is_boolean(B) ->
    {ok, stop_on_red, B};
term({Section, Opts}) when (Section =:= robot_geometry orelse Section =:= ir
                            orelse Section =:= camera), is_map(Opts) ->
    Merged = maps:merge(defaults(Section), Opts),
    Known = lists:all(fun({K, V}) -> is_map_key(K, defaults(Section))
                                         andalso option(Section, K, V) end,
                      maps:to_list(Opts)),
    case Known andalso consistent(Section, Merged) of
        true -> {ok, Section, Merged};
        false -> error
    end;
term(Other) ->
    torobot_sensors:term(Other).

-spec point(term()) -> {ok, point()} | error.
point({X, Y}) when is_number(X), is_number(Y) -> {ok, {float(X), float(Y)}};
point(_) -> error.

-spec defaults(robot_geometry | ir | camera) -> map().
defaults(robot_geometry) -> ?GEOMETRY;
defaults(ir) -> ?IR;
defaults(camera) -> ?CAMERA.

-spec option(atom(), atom(), term()) -> boolean().
option(robot_geometry, _, V) -> positive(V);
option(ir, mount_deg, V) -> is_number(V) andalso V >= 0 andalso V < 180;
option(ir, min_range, V) -> positive(V);
option(ir, max_range, V) -> positive(V);
option(ir, curve, {K, D0, C}) -> positive(K) andalso is_number(D0) andalso D0 >= 0
                                     andalso is_number(C);
option(ir, threshold_high, V) -> is_integer(V) andalso V >= 0 andalso V =< 1023;
option(ir, threshold_low, V) -> is_integer(V) andalso V >= 0 andalso V =< 1023;
option(ir, noise, V) -> is_number(V) andalso V >= 0;
option(camera, fov_deg, V) -> is_number(V) andalso V > 0 andalso V < 180;
option(camera, frame, {W, H}) -> is_integer(W) andalso W > 0 andalso is_integer(H) andalso H > 0;
option(camera, range, V) -> positive(V);
option(camera, height, V) -> is_number(V) andalso V >= 0;
option(camera, min_area, V) -> is_number(V) andalso V >= 0;
option(camera, noise, V) -> is_number(V) andalso V >= 0;
option(_, _, _) -> false.

-spec positive(term()) -> boolean().
positive(V) -> is_number(V) andalso V > 0.

-spec consistent(atom(), map()) -> boolean().
consistent(ir, #{min_range := Min, max_range := Max,
                 threshold_low := Low, threshold_high := High}) ->
    Min < Max andalso Low < High;
consistent(_, _) ->
    true.

-spec build(map()) -> {ok, world()} | {error, reason()}.
build(#{arena := {{W, H}, ArenaTerm}, robot := {{X, Y, Hd}, RobotTerm},
        duration_s := {S, _}} = P) ->
    Walls = lists:reverse(maps:get(wall, P)),
    Objects = lists:reverse(maps:get(object, P)),
    Geometry = value(robot_geometry, P),
    Radius = float(maps:get(radius, Geometry)),
    Inside = fun({Px, Py}) -> Px >= 0 andalso Px =< W andalso Py >= 0 andalso Py =< H end,
    Outside = [T || {{A, B}, T} <- Walls, not (Inside(A) andalso Inside(B))]
        ++ [T || {{_, C, _}, T} <- Objects, not Inside(C)],
    Corners = [{0.0, 0.0}, {W, 0.0}, {W, H}, {0.0, H}],
    Boundary = lists:zip(Corners, tl(Corners) ++ [hd(Corners)]),
    Segments = [{A, B, ArenaTerm} || {A, B} <- Boundary] ++ [{A, B, T} || {{A, B}, T} <- Walls],
    Obstacles = [{{wall, I}, {segment, A, B}, T}
                 || {I, {A, B, T}} <- lists:enumerate(Segments)]
        ++ [{{Colour, I}, {disc, C, R}, T}
            || {I, {{Colour, C, R}, T}} <- lists:enumerate(Objects)],
    Pos = {X, Y},
    Blocking = [T || {_, Shape, T} <- Obstacles, gap(Pos, Radius, Shape) < -?SLACK],
    case {Outside, Inside(Pos), Blocking} of
        {[Culprit | _], _, _} ->
            {error, {outside_arena, Culprit}};
        {[], false, _} ->
            {error, {outside_arena, RobotTerm}};
        {[], true, [Obstacle | _]} ->
            {error, {blocked_start, RobotTerm, Obstacle}};
        {[], true, []} ->
            Start = {X, Y, normalise_deg(Hd)},
            World = #world{arena = {W, H},
                           walls = [Wall || {Wall, _} <- Walls],
                           objects = [O || {O, _} <- Objects],
                           obstacles = Obstacles,
                           start = Start,
                           pos = Pos,
                           theta = deg_to_rad(Hd),
                           duration_ms = max(1, round(S * 1000)),
                           geometry = Geometry,
                           ir = value(ir, P),
                           camera = value(camera, P),
                           seed = value(seed, P),
                           tick_ms = value(tick_ms, P),
                           stop_on_red = value(stop_on_red, P),
                           trajectory = [{0, X, Y, start}],
                           extras = torobot_sensors:build(P)},
            {ok, World#world{touching = contacts(World, Pos, [])}}
    end;
build(P) ->
    [Missing | _] = [K || K <- [arena, robot, duration_s], not is_map_key(K, P)],
    {error, {missing, Missing}}.

-spec value(atom(), map()) -> term().
value(Key, Parsed) ->
    case Parsed of
        #{Key := {V, _}} -> V;
        #{} -> default(Key)
    end.

-spec default(atom()) -> term().
default(robot_geometry) -> ?GEOMETRY;
default(ir) -> ?IR;
default(camera) -> ?CAMERA;
default(seed) -> 1;
default(tick_ms) -> 50;
default(stop_on_red) -> true.

%%====================================================================
%% Stepping
%%====================================================================

%% @doc Advances the world by `DtMs' with the given wheel velocities; the
%% trajectory sample it records is tagged `none'.
-spec step(world(), non_neg_integer(), {velocity(), velocity()}) -> world().
step(World, DtMs, Velocities) ->
    step(World, DtMs, Velocities, none).

%% @doc Advances the world by `DtMs' with the given wheel velocities
%% (`{Left, Right}', servo units) and records the pose at the end of the step
%% in the trajectory with `Tag' (the simulator passes the behavior that won
%% the motors).
-spec step(world(), non_neg_integer(), {velocity(), velocity()}, tag()) -> world().
step(#world{time_ms = T0} = World, DtMs, {Left, Right}, Tag)
  when is_integer(DtMs), DtMs >= 0, is_number(Left), is_number(Right) ->
    #{max_wheel_speed := Vmax, wheel_base := Base} = World#world.geometry,
    Vl = clamp(Left, -100, 100) / 100 * Vmax,
    Vr = clamp(Right, -100, 100) / 100 * Vmax,
    N = max(1, (DtMs + ?MAX_SUBSTEP_MS - 1) div ?MAX_SUBSTEP_MS),
    Dt = DtMs / 1000 / N,
    Moved = lists:foldl(
              fun(I, W) -> substep(W, (Vl + Vr) / 2, (Vr - Vl) / Base, Dt,
                                   T0 + (I * DtMs) div N)
              end, World, lists:seq(1, N)),
    {X, Y} = Moved#world.pos,
    Moved#world{time_ms = T0 + DtMs,
                trajectory = [{T0 + DtMs, X, Y, Tag} | Moved#world.trajectory]}.

-spec substep(world(), float(), float(), float(), non_neg_integer()) -> world().
substep(#world{pos = {X, Y} = Prev, theta = Th} = W, V, Omega, Dt, TimeMs) ->
    Th1 = Th + Omega * Dt,
    Wanted = case abs(Omega) < 1.0e-12 of
                 true -> {X + V * Dt * math:cos(Th), Y + V * Dt * math:sin(Th)};
                 false -> R = V / Omega,
                          {X + R * (math:sin(Th1) - math:sin(Th)),
                           Y - R * (math:cos(Th1) - math:cos(Th))}
             end,
    Radius = robot_radius(W),
    Pos = resolve(Prev, Wanted, obstacles(W), Radius, 8),
    Touching = contacts(W, Pos, W#world.touching),
    New = ordsets:subtract(Touching, W#world.touching),
    count(New, TimeMs, W#world{pos = Pos, theta = normalise_rad(Th1), touching = Touching,
                               distance = W#world.distance + distance(Prev, Pos)}).

%% Projects the wanted position out of every obstacle it overlaps; repeated
%% because leaving one obstacle can push into another (corners). If that does
%% not settle, the robot stays where it was.
-spec resolve(point(), point(), [obstacle()], float(), non_neg_integer()) -> point().
resolve(Prev, Pos, Obstacles, Radius, Tries) ->
    case push_out(Prev, Pos, Obstacles, Radius, false) of
        {Pos1, false} -> Pos1;
        {Pos1, true} when Tries > 0 -> resolve(Prev, Pos1, Obstacles, Radius, Tries - 1);
        {_, true} -> Prev
    end.

-spec push_out(point(), point(), [obstacle()], float(), boolean()) -> {point(), boolean()}.
push_out(_Prev, Pos, [], _Radius, Pushed) ->
    {Pos, Pushed};
push_out(Prev, Pos, [{_, Shape, _} | Rest], Radius, Pushed) ->
    {Near, Reach} = case Shape of
                        {segment, A, B} -> {closest(Pos, A, B), Radius};
                        {disc, C, R} -> {C, Radius + R}
                    end,
    D = distance(Pos, Near),
    if
        D >= Reach - ?SLACK -> push_out(Prev, Pos, Rest, Radius, Pushed);
        D < 1.0e-12 -> push_out(Prev, Prev, Rest, Radius, true);
        true -> push_out(Prev, add(Near, scale(sub(Pos, Near), Reach / D)), Rest, Radius, true)
    end.

%% The obstacles the robot at Pos touches, with hysteresis: one already
%% touched stays touched until the robot is clearly away from it.
-spec contacts(world(), point(), ordsets:ordset(key())) -> ordsets:ordset(key()).
contacts(W, Pos, Before) ->
    Radius = robot_radius(W),
    ordsets:from_list(
      [Key || {Key, Shape, _} <- obstacles(W),
              gap(Pos, Radius, Shape) =< case ordsets:is_element(Key, Before) of
                                             true -> ?RELEASE;
                                             false -> ?TOUCH
                                         end]).

-spec count([key()], non_neg_integer(), world()) -> world().
count([], _TimeMs, W) -> W;
count([{wall, _} | New], TimeMs, W) ->
    count(New, TimeMs, W#world{wall_contacts = W#world.wall_contacts + 1});
count([{blue, _} | New], TimeMs, W) ->
    count(New, TimeMs, W#world{blue_contacts = W#world.blue_contacts + 1});
count([{red, _} | New], TimeMs, #world{red_touched_ms = none} = W) ->
    count(New, TimeMs, W#world{red_touched_ms = TimeMs});
count([{red, _} | New], TimeMs, W) ->
    count(New, TimeMs, W);
count([{robot, _} | New], TimeMs, W) ->
    count(New, TimeMs, W#world{robot_contacts = W#world.robot_contacts + 1}).

%% The scene's obstacles and the other robots.
-spec obstacles(world()) -> [obstacle()].
obstacles(#world{obstacles = Obstacles, others = []}) ->
    Obstacles;
obstacles(#world{obstacles = Obstacles, others = Others}) ->
    Obstacles ++ [{{robot, Name}, {disc, Pos, R}, Name} || {Name, Pos, R, _} <- Others].

%% The colours the other robots carry, as objects the camera may see.
-spec carried(world()) -> [{colour(), point(), float()}].
carried(#world{others = Others}) ->
    [{Colour, Pos, R} || {_, Pos, R, Colour} <- Others, Colour =/= none].

-spec gap(point(), float(), shape()) -> float().
gap(Pos, Radius, {segment, A, B}) -> distance(Pos, closest(Pos, A, B)) - Radius;
gap(Pos, Radius, {disc, C, R}) -> distance(Pos, C) - Radius - R.

%%====================================================================
%% Sensing
%%====================================================================

%% @doc The raw 10-bit ADC readings of the two IR sensors (higher = nearer).
-spec ir(world()) -> ir_reading().
ir(#world{ir = #{mount_deg := Mount}} = W) ->
    #{left => ir_reading(W, deg_to_rad(Mount), left),
      right => ir_reading(W, -deg_to_rad(Mount), right)}.

-spec ir_reading(world(), float(), left | right) -> adc().
ir_reading(#world{ir = Ir} = W, Mount, Side) ->
    #{min_range := Min, max_range := Max, curve := {K, D0, C}, noise := Noise} = Ir,
    D = clamp(range(W, Mount, Max), Min, Max),
    Value = K / (D * 100 + D0) + C + noise(W, {ir, Side}, Noise),
    clamp(round(Value), 0, 1023).

%% @doc The distance in metres from the robot's rim, at `MountRad' from the
%% heading (counter-clockwise), to the first wall, object or other robot
%% along that direction; `Max' when there is none nearer.
-spec range(world(), float(), number()) -> number().
range(#world{pos = Pos, theta = Th} = W, MountRad, Max) ->
    Dir = {math:cos(Th + MountRad), math:sin(Th + MountRad)},
    Origin = add(Pos, scale(Dir, robot_radius(W))),
    Hits = [T || {_, Shape, _} <- obstacles(W), {hit, T} <- [ray(Origin, Dir, Shape)]],
    lists:min([Max | Hits]).

%% @doc The bearings (degrees from the heading, counter-clockwise) of the
%% walls, objects and other robots the robot touches now.
-spec contact_bearings(world()) -> [float()].
contact_bearings(#world{pos = Pos, theta = Th} = W) ->
    Radius = robot_radius(W),
    [rad_to_deg(normalise_rad(math:atan2(Dy, Dx) - Th))
     || {_, Shape, _} <- obstacles(W), gap(Pos, Radius, Shape) =< ?RELEASE,
        {Dx, Dy} <- [sub(case Shape of
                             {segment, A, B} -> closest(Pos, A, B);
                             {disc, C, _} -> C
                         end, Pos)]].

%% @doc Whether no wall (the arena's included) crosses the segment between
%% two points.
-spec line_of_sight(world(), point(), point()) -> boolean().
line_of_sight(#world{obstacles = Obstacles}, From, To) ->
    Sight = sub(To, From),
    not lists:any(fun({_, {segment, _, _} = Wall, _}) ->
                          case ray(From, Sight, Wall) of
                              {hit, T} -> T < 1;
                              miss -> false
                          end;
                     (_) -> false
                  end, Obstacles).

%% @doc Whether the robot could stand at a point without touching anything.
-spec free(world(), point()) -> boolean().
free(#world{obstacles = Obstacles} = W, Pos) ->
    Radius = robot_radius(W),
    lists:all(fun({_, Shape, _}) -> gap(Pos, Radius, Shape) >= 0 end, Obstacles).

%% @doc What `torobot_sensors' parsed from the world file.
-spec extras(world()) -> map().
extras(#world{extras = Extras}) -> Extras.

%% @doc The robot's geometry (`radius', `wheel_base', `max_wheel_speed').
-spec geometry(world()) -> map().
geometry(#world{geometry = G}) -> G.

%% @doc What a viewer draws of the sensors now: each IR ray from its sensor
%% to what it meets (or to its range) with its reading, and the camera's
%% field of view (it looks along the heading from the robot's centre).
-spec view(world()) -> #{ir := [#{side := left | right, from := point(), to := point(),
                                  adc := adc()}],
                         camera := #{fov_deg := number(), range := number()}}.
view(#world{pos = Pos, theta = Th, ir = #{mount_deg := Mount, max_range := Max},
            camera = #{fov_deg := Fov, range := Range}} = W) ->
    Readings = ir(W),
    Ray = fun(Side, Angle) ->
                  Dir = {math:cos(Th + Angle), math:sin(Th + Angle)},
                  Origin = add(Pos, scale(Dir, robot_radius(W))),
                  Hits = [T || {_, Shape, _} <- obstacles(W),
                               {hit, T} <- [ray(Origin, Dir, Shape)]],
                  #{side => Side, from => Origin,
                    to => add(Origin, scale(Dir, lists:min([Max | Hits]))),
                    adc => maps:get(Side, Readings)}
          end,
    #{ir => [Ray(left, deg_to_rad(Mount)), Ray(right, -deg_to_rad(Mount))],
      camera => #{fov_deg => Fov, range => Range}}.

%% @doc The near/far state of each IR sensor after the current readings, given
%% the previous state: the same hysteresis the PRU applies to the ADC.
-spec ir_levels(world(), ir_levels()) -> ir_levels().
ir_levels(#world{ir = #{threshold_high := High, threshold_low := Low}} = W, Previous) ->
    maps:map(fun(Side, Adc) ->
                     if Adc >= High -> near;
                        Adc =< Low -> far;
                        true -> maps:get(Side, Previous)
                     end
             end, ir(W)).

%% @doc The world's IR thresholds as ADC levels, for configuring the sensors.
-spec ir_thresholds(world()) -> #{threshold_high := adc(), threshold_low := adc()}.
ir_thresholds(#world{ir = Ir}) ->
    maps:with([threshold_high, threshold_low], Ir).

%% @doc What the detector would send for the current camera frame: one JSON
%% datagram for red, then one for blue, each either the largest visible
%% object of that colour or the `none' form.
-spec camera(world()) -> [binary()].
camera(W) ->
    Seen = [{Colour, Blob} || {Colour, _, _} = Object <- W#world.objects ++ carried(W),
                              {ok, Blob} <- [project(W, Object)]],
    [datagram(Colour, largest([Blob || {C, Blob} <- Seen, C =:= Colour]), W)
     || Colour <- [red, blue]].

-spec project(world(), {colour(), point(), float()}) ->
          {ok, blob()} | error.
project(#world{pos = Pos, theta = Th, camera = Cam} = W, {Colour, Centre, R}) ->
    #{fov_deg := Fov, frame := {Wpx, Hpx}, range := Range, height := Height,
      min_area := MinArea, noise := Noise} = Cam,
    F = Wpx / 2 / math:tan(deg_to_rad(Fov) / 2),
    {Dx, Dy} = sub(Centre, Pos),
    Ahead = Dx * math:cos(Th) + Dy * math:sin(Th),
    Left = -Dx * math:sin(Th) + Dy * math:cos(Th),
    Dist = distance(Pos, Centre),
    Area = min(Wpx * Hpx, round(math:pi() * math:pow(F * R / Dist, 2))),
    Visible = Ahead > 0
        andalso Dist =< Range
        andalso abs(math:atan2(Left, Ahead)) =< deg_to_rad(Fov) / 2
        andalso Area >= MinArea
        andalso not occluded(W, Pos, {Colour, Centre, R}),
    case Visible of
        true ->
            X = round(-F * Left / Ahead + noise(W, {Colour, x}, Noise)),
            Y = round(F * (Height - R) / Ahead + noise(W, {Colour, y}, Noise)),
            {ok, {Area, -Dist, clamp(X, -(Wpx div 2), Wpx div 2),
                  clamp(Y, -(Hpx div 2), Hpx div 2)}};
        false ->
            error
    end.

-spec occluded(world(), point(), {colour(), point(), float()}) -> boolean().
occluded(W, Eye, {_, Centre, Radius}) ->
    Sight = sub(Centre, Eye),
    lists:any(fun({_, {segment, _, _} = Wall, _}) ->
                      case ray(Eye, Sight, Wall) of
                          {hit, T} -> T < 1;
                          miss -> false
                      end;
                 ({_, {disc, C, R}, _}) ->
                      {C, R} =/= {Centre, Radius}
                          andalso distance(C, closest(C, Eye, Centre)) < R
              end, obstacles(W)).

-spec largest([blob()]) -> blob() | none.
largest([]) -> none;
largest(Blobs) -> lists:max(Blobs).

-spec datagram(colour(), blob() | none, world()) -> binary().
datagram(Colour, none, _W) ->
    iolist_to_binary(["{\"color\":\"", atom_to_binary(Colour), "\",\"none\":true}"]);
datagram(Colour, {Area, _, X, Y}, #world{time_ms = T}) ->
    iolist_to_binary(["{\"color\":\"", atom_to_binary(Colour),
                      "\",\"x\":", integer_to_binary(X),
                      ",\"y\":", integer_to_binary(Y),
                      ",\"area\":", integer_to_binary(Area),
                      ",\"t\":", integer_to_binary(T), "}"]).

%% Gaussian noise that depends only on the seed, the time and the channel,
%% so sensing stays a function of the world.
-spec noise(world(), term(), number()) -> float().
noise(_W, _Channel, Sigma) when Sigma == 0 ->
    0.0;
noise(#world{seed = Seed, time_ms = T}, Channel, Sigma) ->
    {N, _} = rand:normal_s(rand:seed_s(exsss, {Seed, T, erlang:phash2(Channel)})),
    N * Sigma.

%%====================================================================
%% The run
%%====================================================================

%% @doc World time in milliseconds since the start.
-spec time_ms(world()) -> non_neg_integer().
time_ms(#world{time_ms = T}) -> T.

%% @doc The robot's pose now.
-spec pose(world()) -> pose().
pose(#world{pos = {X, Y}, theta = Th}) -> {X, Y, rad_to_deg(Th)}.

%% @doc Whether the run is over: its duration reached, or a red object touched
%% when `stop_on_red' is on.
-spec done(world()) -> boolean().
done(#world{time_ms = T, duration_ms = D, stop_on_red = Stop, red_touched_ms = Red}) ->
    T >= D orelse (Stop andalso Red =/= none).

%% @doc The run's outcome, as `torobot_sim:run/2' returns it. A named robot
%% (a world of several) also has `robot_contacts', counted as walls are.
-spec summary(world()) -> summary().
summary(#world{} = W) ->
    Summary = maps:merge(torobot_sensors:figures(W),
                         #{red_touched_ms => W#world.red_touched_ms,
                           wall_contacts => W#world.wall_contacts,
                           blue_contacts => W#world.blue_contacts,
                           distance_m => W#world.distance}),
    case W#world.name of
        undefined -> Summary;
        _ -> Summary#{robot_contacts => W#world.robot_contacts}
    end.

%% @doc The robot's positions, oldest first: the start (tagged `start') and
%% the end of every step with the step's tag.
-spec trajectory(world()) -> [sample()].
trajectory(#world{trajectory = Samples}) -> lists:reverse(Samples).

%%====================================================================
%% The scene
%%====================================================================

%% @doc The arena's width and height in metres.
-spec arena(world()) -> {float(), float()}.
arena(#world{arena = A}) -> A.

%% @doc The walls inside the arena (not the arena's own), in file order.
-spec walls(world()) -> [{point(), point()}].
walls(#world{walls = Walls}) -> Walls.

%% @doc The objects as `{Colour, Centre, Radius}', in file order.
-spec objects(world()) -> [{colour(), point(), float()}].
objects(#world{objects = Objects}) -> Objects.

%% @doc The robot's pose at the start.
-spec start_pose(world()) -> pose().
start_pose(#world{start = Start}) -> Start.

%% @doc The robot's radius in metres.
-spec robot_radius(world()) -> float().
robot_radius(#world{geometry = #{radius := R}}) -> float(R).

%% @doc The period the world file asks the simulator to step with.
-spec tick_ms(world()) -> pos_integer().
tick_ms(#world{tick_ms = T}) -> T.

%% @doc The run's duration in milliseconds.
-spec duration_ms(world()) -> pos_integer().
duration_ms(#world{duration_ms = D}) -> D.

%%====================================================================
%% Several robots
%%====================================================================

%% @doc The robot's name: `undefined' for the one-robot form of a world.
-spec name(world()) -> atom() | undefined.
name(#world{name = Name}) -> Name.

%% @doc The robot as the other robots of the world see it now.
-spec body(world()) -> body().
body(#world{name = Name, pos = Pos, colour = Colour} = W) ->
    {Name, Pos, robot_radius(W), Colour}.

%% @doc Puts the other robots where they are now: they block this robot's
%% moves, its IR rays and its camera's line of sight, and the camera sees
%% the colours they carry. Touching one counts a robot contact.
-spec set_others(world(), [body()]) -> world().
set_others(W, Others) ->
    W#world{others = Others}.

%%====================================================================
%% Geometry
%%====================================================================

%% Where the ray Origin + T * Dir (T >= 0) first meets a shape, T in units
%% of Dir. Parallel segments are missed: a ray grazing a wall end-on sees
%% the walls it meets next.
-spec ray(point(), point(), shape()) -> {hit, float()} | miss.
ray(Origin, Dir, {segment, A, B}) ->
    Edge = sub(B, A),
    Denom = cross(Dir, Edge),
    case abs(Denom) < 1.0e-12 of
        true -> miss;
        false ->
            ToA = sub(A, Origin),
            T = cross(ToA, Edge) / Denom,
            S = cross(ToA, Dir) / Denom,
            case T >= 0 andalso S >= 0 andalso S =< 1 of
                true -> {hit, T};
                false -> miss
            end
    end;
ray(Origin, Dir, {disc, C, R}) ->
    F = sub(Origin, C),
    A = dot(Dir, Dir),
    B = dot(F, Dir),
    Cc = dot(F, F) - R * R,
    Disc = B * B - A * Cc,
    if
        Cc =< 0 -> {hit, 0.0};
        Disc < 0 -> miss;
        true ->
            T = (-B - math:sqrt(Disc)) / A,
            case T >= 0 of
                true -> {hit, T};
                false -> miss
            end
    end.

-spec closest(point(), point(), point()) -> point().
closest(P, A, B) ->
    Edge = sub(B, A),
    T = clamp(dot(sub(P, A), Edge) / dot(Edge, Edge), 0.0, 1.0),
    add(A, scale(Edge, T)).

-spec add(point(), point()) -> point().
add({X1, Y1}, {X2, Y2}) -> {X1 + X2, Y1 + Y2}.
-spec sub(point(), point()) -> point().
sub({X1, Y1}, {X2, Y2}) -> {X1 - X2, Y1 - Y2}.
-spec scale(point(), number()) -> point().
scale({X, Y}, K) -> {X * K, Y * K}.
-spec dot(point(), point()) -> float().
dot({X1, Y1}, {X2, Y2}) -> X1 * X2 + Y1 * Y2.
-spec cross(point(), point()) -> float().
cross({X1, Y1}, {X2, Y2}) -> X1 * Y2 - Y1 * X2.
-spec distance(point(), point()) -> float().
distance(P, Q) -> {Dx, Dy} = sub(P, Q), math:sqrt(Dx * Dx + Dy * Dy).

-spec clamp(number(), number(), number()) -> number().
clamp(V, Low, High) -> max(Low, min(High, V)).

-spec deg_to_rad(number()) -> float().
deg_to_rad(D) -> D * math:pi() / 180.
-spec rad_to_deg(number()) -> float().
rad_to_deg(R) -> R * 180 / math:pi().

-spec normalise_rad(number()) -> float().
normalise_rad(R) -> math:atan2(math:sin(R), math:cos(R)).
-spec normalise_deg(number()) -> float().
normalise_deg(D) -> rad_to_deg(normalise_rad(deg_to_rad(D))).
