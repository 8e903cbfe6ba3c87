%% @doc The Torobot's simulated world as a pure value: the API.
%%
%% A world is an arena with walls, red and blue objects and one Torobot: a
%% differential-drive disc with two Sharp IR distance sensors and a camera.
%% This module is the functional core of the simulator: `torobot_sim' (the
%% process that ticks it) calls {@link step/4} each tick with the motor
%% velocities and the name of the behavior that won the motors, reads
%% {@link ir/1} and {@link camera/1}, and hands them to the same devices
%% the board uses; `torobot_sensors' makes the library's sensor models of
%% {@link range/3}, {@link contact_bearings/1} and {@link line_of_sight/3};
%% `torobot_svg' and the dashboard draw the run. Nothing here starts a
%% process or does I/O, except {@link load/1} reading the world file.
%%
%% The work is done by one module per purpose, each documented there:
%% `torobot_world_file' (the world file: its terms, their checks and
%% defaults, the errors naming the culprit), `torobot_world_step'
%% (kinematics, collisions, contacts, the trajectory and the summary),
%% `torobot_world_sensing' (IR, camera and its detector datagrams, ranges
%% and lines of sight) and `torobot_geometry' (segments, discs, rays,
%% occlusion). They share the world record (`torobot_world.hrl'); outside
%% them a world is opaque and is used through this module only.
%%
%% Functions by purpose: building ({@link load/1}, {@link from_terms/1},
%% {@link load_all/1}, {@link from_terms_all/1}); stepping ({@link step/3},
%% {@link step/4}); sensing ({@link ir/1}, {@link ir_levels/2},
%% {@link ir_thresholds/1}, {@link camera/1}, {@link view/1}); the run
%% ({@link time_ms/1}, {@link pose/1}, {@link done/1}, {@link summary/1},
%% {@link trajectory/1}); the scene ({@link arena/1}, {@link walls/1},
%% {@link objects/1}, {@link start_pose/1}, {@link robot_radius/1},
%% {@link tick_ms/1}, {@link duration_ms/1}); several robots ({@link name/1},
%% {@link body/1}, {@link set_others/2}); for the sensor models of
%% `torobot_sensors' ({@link extras/1}, {@link geometry/1}, {@link range/3},
%% {@link contact_bearings/1}, {@link line_of_sight/3}, {@link free/2}).
-module(torobot_world).

-include("torobot_world.hrl").

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
-type point() :: torobot_geometry:point().
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
-opaque world() :: #world{}.

%%====================================================================
%% Building (torobot_world_file)
%%====================================================================

%% @doc Reads a world file (`file:consult/1' terms, see `torobot_world_file').
-spec load(file:name_all()) -> {ok, world()} | {error, reason()}.
load(File) -> torobot_world_file:load(File).

%% @doc Builds a world from the terms of a world file. A world of several
%% robots is refused as `{several_robots, Names}': see {@link from_terms_all/1}.
-spec from_terms([term()]) -> {ok, world()} | {error, reason()}.
from_terms(Terms) -> torobot_world_file:from_terms(Terms).

%% @doc Reads a world file of any number of robots: one world per robot,
%% in file order (see {@link from_terms_all/1}).
-spec load_all(file:name_all()) -> {ok, [world(), ...]} | {error, reason()}.
load_all(File) -> torobot_world_file:load_all(File).

%% @doc Builds one world per robot of a world file: the same scene, each
%% with its own robot and the others as bodies ({@link set_others/2}).
%% Robots are either the one `{robot, Pose}' or any number of
%% `{robot, Name, Pose}' / `{robot, Name, Pose, #{colour => red | blue}}'
%% with distinct names; mixing the forms or repeating a name is
%% `{duplicate, Term}', robots starting on each other `{blocked_start,
%% RobotTerm, OtherRobotTerm}'.
-spec from_terms_all([term()]) -> {ok, [world(), ...]} | {error, reason()}.
from_terms_all(Terms) -> torobot_world_file:from_terms_all(Terms).

%%====================================================================
%% Stepping (torobot_world_step)
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
step(World, DtMs, Velocities, Tag) -> torobot_world_step:step(World, DtMs, Velocities, Tag).

%%====================================================================
%% Sensing (torobot_world_sensing)
%%====================================================================

%% @doc The raw 10-bit ADC readings of the two IR sensors (higher = nearer).
-spec ir(world()) -> ir_reading().
ir(W) -> torobot_world_sensing:ir(W).

%% @doc The near/far state of each IR sensor after the current readings, given
%% the previous state: the same hysteresis the PRU applies to the ADC.
-spec ir_levels(world(), ir_levels()) -> ir_levels().
ir_levels(W, Previous) -> torobot_world_sensing:ir_levels(W, Previous).

%% @doc The world's IR thresholds as ADC levels, for configuring the sensors.
-spec ir_thresholds(world()) -> #{threshold_high := adc(), threshold_low := adc()}.
ir_thresholds(W) -> torobot_world_sensing:ir_thresholds(W).

%% @doc What the detector would send for the current camera frame: one JSON
%% datagram for red, then one for blue, each either the largest visible
%% object of that colour or the `none' form.
-spec camera(world()) -> [binary()].
camera(W) -> torobot_world_sensing:camera(W).

%% @doc What a viewer draws of the sensors now: each IR ray from its sensor
%% to what it meets (or to its range) with its reading, and the camera's
%% field of view (it looks along the heading from the robot's centre).
-spec view(world()) -> #{ir := [#{side := left | right, from := point(), to := point(),
                                  adc := adc()}],
                         camera := #{fov_deg := number(), range := number()}}.
view(W) -> torobot_world_sensing:view(W).

%% @doc The distance in metres from the robot's rim, at `MountRad' from the
%% heading (counter-clockwise), to the first wall, object or other robot
%% along that direction; `Max' when there is none nearer.
-spec range(world(), float(), number()) -> number().
range(W, MountRad, Max) -> torobot_world_sensing:range(W, MountRad, Max).

%% @doc The bearings (degrees from the heading, counter-clockwise) of the
%% walls, objects and other robots the robot touches now.
-spec contact_bearings(world()) -> [float()].
contact_bearings(W) -> torobot_world_sensing:contact_bearings(W).

%% @doc Whether no wall (the arena's included) crosses the segment between
%% two points.
-spec line_of_sight(world(), point(), point()) -> boolean().
line_of_sight(W, From, To) -> torobot_world_sensing:line_of_sight(W, From, To).

%% @doc Whether the robot could stand at a point without touching anything.
-spec free(world(), point()) -> boolean().
free(W, Pos) -> torobot_world_step:free(W, Pos).

%% @doc What the world file gave for the library's sensors and fixtures
%% (`torobot_sensors').
-spec extras(world()) -> map().
extras(#world{extras = Extras}) -> Extras.

%% @doc The robot's geometry (`radius', `wheel_base', `max_wheel_speed').
-spec geometry(world()) -> map().
geometry(#world{geometry = G}) -> G.

%%====================================================================
%% The run
%%====================================================================

%% @doc World time in milliseconds since the start.
-spec time_ms(world()) -> non_neg_integer().
time_ms(#world{time_ms = T}) -> T.

%% @doc The robot's pose now.
-spec pose(world()) -> pose().
pose(#world{pos = {X, Y}, theta = Th}) -> {X, Y, torobot_geometry:rad_to_deg(Th)}.

%% @doc Whether the run is over: its duration reached, or a red object touched
%% when `stop_on_red' is on.
-spec done(world()) -> boolean().
done(W) -> torobot_world_step:done(W).

%% @doc The run's outcome, as `torobot_sim:run/2' returns it, with the
%% figures the world asks for (`torobot_sensors'). A named robot (a world
%% of several) also has `robot_contacts', counted as walls are.
-spec summary(world()) -> summary().
summary(W) -> torobot_world_step:summary(W).

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
robot_radius(W) -> torobot_world_step:radius(W).

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
body(W) -> torobot_world_step:body(W).

%% @doc Puts the other robots where they are now: they block this robot's
%% moves, its IR rays and its camera's line of sight, and the camera sees
%% the colours they carry. Touching one counts a robot contact.
-spec set_others(world(), [body()]) -> world().
set_others(W, Others) ->
    W#world{others = Others}.