%% @doc The simulated world's sensors and fixtures beyond the Torobot's:
%% what the library's robots (`config/robots/') sense, as pure functions of
%% a `torobot_world' value, and the figures their runs are measured by.
%% It sees the world through `torobot_world''s API only (the world uses
%% nothing of this module): `torobot_world_file' checks the terms below
%% and `torobot_world_step' measures the figures for the summary, which
%% {@link figures/1} picks out; `torobot_sim' adds one `torobot_sim_sensor'
%% device per entry of {@link devices/0} and feeds each tick's {@link
%% read/2} to them.
%%
%% <h3>World-file terms</h3>
%% All optional, at most once each unless said (defaults in brackets):
%% <ul>
%% <li>`{range, #{sensors => #{Name => MountDeg}, max_range => 1.5}}':
%%     range sensors (time-of-flight style) on the robot's rim, reading the
%%     distance in metres to the first wall or object along their mount
%%     direction (degrees from the heading, counter-clockwise), rounded to
%%     the centimetre, `max_range' when nothing is nearer. Default sensors:
%%     `front' 0, `front_left' 45, `front_right' -45, `left' 90, `right'
%%     -90, `rear' 180. Device `range', one output per sensor.</li>
%% <li>`{bumper, #{front_deg => 25, side_deg => 110}}': a bumper all
%%     round; a contact within `front_deg' of the heading is `front', up to
%%     `side_deg' `left' or `right', beyond that `rear'. Device `bumper',
%%     output `contact': `none' or the side of the contact nearest the
%%     front.</li>
%% <li>Wheel odometry, always there: device `odometry', output `wheels',
%%     the wheel velocities measured from the robot's real motion since the
%%     previous tick, in servo units (so a wheel pushing against a wall
%%     reads 0 while commanded 80: a stall).</li>
%% <li>`{light, {X, Y}, Power}', any number: lamps. `{light_sensor,
%%     #{mount_deg => 45, half_distance => 0.5}}': two light sensors on the
%%     rim at +-`mount_deg'; each reads, per lamp in line of sight (walls
%%     block light), `Power' x cos(angle off the sensor's axis) / (1 +
%%     (distance / `half_distance')^2), summed and clamped to 0..1023.
%%     Device `light', outputs `left', `right'.</li>
%% <li>`{dock, {X, Y}}': a charging dock, a pad on the floor with a beacon.
%%     `{beacon, #{range => 6.0, dock_radius => 0.10}}': the robot's beacon
%%     receiver sees the dock all round within `range' when no wall is in
%%     between; it is as wide as the robot (a receiver on each side), so the
%%     dock is seen only when the robot could drive straight to it without
%%     clipping a wall's end. Device `beacon', outputs `bearing' (`{BearingDeg,
%%     DistanceM}' from the robot's centre, bearing counter-clockwise from
%%     the heading, or `none') and `docked' (`true' while the robot's
%%     centre is within `dock_radius' of the dock).</li>
%% <li>`{floor_line, [{X, Y}, ...]}', any number: a strip of dark tape on
%%     the floor along those points. `{grey_sensor, #{offset => 0.06,
%%     spread => 0.03, width => 0.02, dark => 900, light => 100}}': the
%%     Torobot's two grey-level sensors under its front, `offset' metres
%%     ahead of its centre and `spread' to each side; each reads `dark'
%%     over a line (its point within `width' / 2 of one), `light' off it,
%%     as the original's ADC did. Devices `trc_grey_left' and
%%     `trc_grey_right' (the names the original Torocó's configuration
%%     gave them), output `value'; a world without `grey_sensor' has
%%     neither.</li>
%% <li>`{figures, [Figure]}': what the summary measures besides the
%%     Torobot's keys: `laps' (turns of the trajectory round the arena's
%%     centre, or round `{lap_centre, {X, Y}}'), `coverage' (the fraction of
%%     the 0.2 m cells the robot could stand in that its body swept),
%%     `docked_ms' (first time on the dock, or `none'), `light_distance_m'
%%     (the centre's distance to the nearest lamp at the end),
%%     `light_mean_m' (that distance averaged over the run).</li>
%% </ul>
-module(torobot_sensors).

-export([devices/0, new/1, read/2]).
-export([figures/1, lights/1, dock/1, floor_lines/1]).
-export_type([state/0, readings/0]).

-type readings() :: #{atom() => #{atom() => term()}}.
-opaque state() :: {torobot_world:pose(), non_neg_integer()}.

%%====================================================================
%% Fixtures
%%====================================================================

%% @doc The lamps, `{Centre, Power}'.
-spec lights(torobot_world:world()) -> [{torobot_world:point(), float()}].
lights(W) -> maps:get(lights, torobot_world:extras(W)).

%% @doc The lines of dark tape on the floor, each its points.
-spec floor_lines(torobot_world:world()) -> [[torobot_world:point()]].
floor_lines(W) -> maps:get(floor_lines, torobot_world:extras(W)).

%% @doc The dock's place, or `none'.
-spec dock(torobot_world:world()) -> torobot_world:point() | none.
dock(W) -> maps:get(dock, torobot_world:extras(W)).

%%====================================================================
%% Sensing
%%====================================================================

%% @doc The sensor devices and their outputs, for the given world.
-spec devices() -> [{atom(), fun((torobot_world:world()) -> [atom()])}].
devices() ->
    [{range, fun(W) -> lists:sort(maps:keys(maps:get(sensors, cfg(range, W)))) end},
     {bumper, fun(_) -> [contact] end},
     {odometry, fun(_) -> [wheels] end},
     {light, fun(_) -> [left, right] end},
     {beacon, fun(_) -> [bearing, docked] end},
     {trc_grey_left, fun grey_outputs/1},
     {trc_grey_right, fun grey_outputs/1}].

%% A world's grey sensors, if it has them.
grey_outputs(W) ->
    case cfg(grey_sensor, W) of
        none -> [];
        #{} -> [value]
    end.

%% @doc The sensing state at the start of a run.
-spec new(torobot_world:world()) -> state().
new(W) -> {torobot_world:pose(W), torobot_world:time_ms(W)}.

%% @doc Every sensor's reading now, by device and output.
-spec read(torobot_world:world(), state()) -> {readings(), state()}.
read(W, {Pose0, T0}) ->
    Pose = torobot_world:pose(W),
    T = torobot_world:time_ms(W),
    Readings = #{range => ranges(W), bumper => #{contact => bumper(W)},
                 odometry => #{wheels => odometry(W, Pose0, Pose, T - T0)},
                 light => light(W), beacon => beacon(W)},
    {maps:merge(Readings, grey(W)), {Pose, T}}.

cfg(Key, W) -> maps:get(Key, torobot_world:extras(W)).

ranges(W) ->
    #{sensors := Sensors, max_range := Max} = cfg(range, W),
    maps:map(fun(_Name, Deg) ->
                     round(torobot_world:range(W, Deg * math:pi() / 180, Max) * 100) / 100
             end, Sensors).

bumper(W) ->
    #{front_deg := Front, side_deg := Side} = cfg(bumper, W),
    case lists:sort([{abs(B), B} || B <- torobot_world:contact_bearings(W)]) of
        [] -> none;
        [{A, _} | _] when A =< Front -> front;
        [{A, B} | _] when A =< Side, B > 0 -> left;
        [{A, _} | _] when A =< Side -> right;
        _ -> rear
    end.

odometry(_W, _Pose0, _Pose, Dt) when Dt =< 0 ->
    {0, 0};
odometry(W, {X0, Y0, H0}, {X, Y, H}, DtMs) ->
    #{wheel_base := Base, max_wheel_speed := Vmax} = torobot_world:geometry(W),
    Dt = DtMs / 1000,
    Th0 = H0 * math:pi() / 180,
    V = ((X - X0) * math:cos(Th0) + (Y - Y0) * math:sin(Th0)) / Dt,
    Turned = math:atan2(math:sin((H - H0) * math:pi() / 180), math:cos((H - H0) * math:pi() / 180)),
    Omega = Turned / Dt,
    Servo = fun(Speed) -> round(Speed / Vmax * 100) end,
    {Servo(V - Omega * Base / 2), Servo(V + Omega * Base / 2)}.

light(W) ->
    #{mount_deg := Mount, half_distance := Half} = cfg(light_sensor, W),
    {X, Y, H} = torobot_world:pose(W),
    R = torobot_world:robot_radius(W),
    Reading = fun(Deg) ->
                      Axis = (H + Deg) * math:pi() / 180,
                      At = {X + R * math:cos(Axis), Y + R * math:sin(Axis)},
                      Sum = lists:sum([lamp(W, At, Axis, Lamp, Half) || Lamp <- lights(W)]),
                      max(0, min(1023, round(Sum)))
              end,
    #{left => Reading(Mount), right => Reading(-Mount)}.

lamp(W, {Sx, Sy} = At, Axis, {{Lx, Ly} = Centre, Power}, Half) ->
    Dx = Lx - Sx,
    Dy = Ly - Sy,
    D = math:sqrt(Dx * Dx + Dy * Dy),
    Cos = case D < 1.0e-9 of
              true -> 1.0;
              false -> (Dx * math:cos(Axis) + Dy * math:sin(Axis)) / D
          end,
    case Cos > 0 andalso torobot_world:line_of_sight(W, At, Centre) of
        true -> Power * Cos / (1 + (D / Half) * (D / Half));
        false -> 0.0
    end.

grey(W) ->
    case cfg(grey_sensor, W) of
        none ->
            #{};
        #{offset := Ahead, spread := Side, width := Width, dark := Dark, light := Light} ->
            {X, Y, H} = torobot_world:pose(W),
            Th = H * math:pi() / 180,
            Lines = floor_lines(W),
            Reading = fun(Across) ->
                              At = {X + Ahead * math:cos(Th) - Across * math:sin(Th),
                                    Y + Ahead * math:sin(Th) + Across * math:cos(Th)},
                              case on_line(At, Lines, Width / 2) of
                                  true -> Dark;
                                  false -> Light
                              end
                      end,
            #{trc_grey_left => #{value => Reading(Side)},
              trc_grey_right => #{value => Reading(-Side)}}
    end.

on_line(At, Lines, Half) ->
    lists:any(fun(Pts) ->
                      lists:any(fun({A, B}) when A =:= B -> torobot_geometry:distance(At, A) =< Half;
                                   ({A, B}) ->
                                        torobot_geometry:distance(
                                          At, torobot_geometry:closest(At, A, B)) =< Half
                                end, lists:zip(lists:droplast(Pts), tl(Pts)))
              end, Lines).

beacon(W) ->
    #{range := Range, dock_radius := DockR} = cfg(beacon, W),
    case dock(W) of
        none ->
            #{bearing => none, docked => false};
        {Dx, Dy} ->
            {X, Y, H} = torobot_world:pose(W),
            D = math:sqrt((Dx - X) * (Dx - X) + (Dy - Y) * (Dy - Y)),
            Bearing = math:atan2(Dy - Y, Dx - X) * 180 / math:pi() - H,
            R = torobot_world:robot_radius(W),
            Across = case D < 1.0e-9 of
                         true -> {0.0, 0.0};
                         false -> {-(Dy - Y) / D * R, (Dx - X) / D * R}
                     end,
            Seen = D =< Range andalso
                lists:all(fun({Ox, Oy}) ->
                                  torobot_world:line_of_sight(W, {X + Ox, Y + Oy}, {Dx + Ox, Dy + Oy})
                          end, [{0.0, 0.0}, Across, {-element(1, Across), -element(2, Across)}]),
            #{bearing => case Seen of
                             true -> {round(torobot_geometry:normalise_deg(Bearing)),
                                      round(D * 100) / 100};
                             false -> none
                         end,
              docked => D =< DockR}
    end.

%%====================================================================
%% Figures
%%====================================================================

%% @doc The figures the world asks for (`{figures, [...]}'), measured on
%% the run so far (by `torobot_world_step', as part of the summary).
-spec figures(torobot_world:world()) -> map().
figures(W) ->
    maps:with(cfg(figures, W), torobot_world:summary(W)).
