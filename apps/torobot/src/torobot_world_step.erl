%% @doc The robot moving in the world, pure: kinematics, collisions and
%% contacts, the trajectory, and the run's summary with the figures a world
%% asks for. `torobot_world' exposes it ({@link torobot_world:step/4},
%% {@link torobot_world:done/1}, {@link torobot_world:summary/1},
%% {@link torobot_world:free/2}); `torobot_world_file' uses {@link contacts/3}
%% for the contacts at the start, and `torobot_world_sensing' the scene as
%% the robot meets it ({@link obstacles/1}, {@link radius/1}).
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
%% <h3>Figures</h3>
%% The figures of `{figures, [...]}' (doc in `torobot_sensors') are
%% measured on the trajectory here, for {@link summary/1}.
-module(torobot_world_step).

-include("torobot_world.hrl").

-export([step/4, done/1, summary/1]).
-export([obstacles/1, radius/1, body/1, contacts/3, free/2]).

-export_type([key/0]).

%% What contacts are counted by: a wall (the arena's first), an object by
%% colour and file order, another robot by name.
-type key() :: {wall, pos_integer()} | {torobot_world:colour(), pos_integer()}
             | {robot, atom()}.

%% Sub-steps keep a move far shorter than the robot's radius, so it can never
%% jump over a wall segment.
-define(MAX_SUBSTEP_MS, 10).
%% The cells `coverage' counts, metres.
-define(CELL, 0.2).

%%====================================================================
%% Stepping
%%====================================================================

%% @doc Advances the world by `DtMs' with the given wheel velocities
%% (`{Left, Right}', servo units) and records the pose at the end of the step
%% in the trajectory with `Tag'.
-spec step(#world{}, non_neg_integer(), {torobot_world:velocity(), torobot_world:velocity()},
           torobot_world:tag()) -> #world{}.
step(#world{time_ms = T0} = World, DtMs, {Left, Right}, Tag)
  when is_integer(DtMs), DtMs >= 0, is_number(Left), is_number(Right) ->
    #{max_wheel_speed := Vmax, wheel_base := Base} = World#world.geometry,
    Vl = torobot_geometry:clamp(Left, -100, 100) / 100 * Vmax,
    Vr = torobot_geometry:clamp(Right, -100, 100) / 100 * Vmax,
    N = max(1, (DtMs + ?MAX_SUBSTEP_MS - 1) div ?MAX_SUBSTEP_MS),
    Dt = DtMs / 1000 / N,
    Moved = lists:foldl(
              fun(I, W) -> substep(W, (Vl + Vr) / 2, (Vr - Vl) / Base, Dt,
                                   T0 + (I * DtMs) div N)
              end, World, lists:seq(1, N)),
    {X, Y} = Moved#world.pos,
    Moved#world{time_ms = T0 + DtMs,
                trajectory = [{T0 + DtMs, X, Y, Tag} | Moved#world.trajectory]}.

-spec substep(#world{}, float(), float(), float(), non_neg_integer()) -> #world{}.
substep(#world{pos = {X, Y} = Prev, theta = Th} = W, V, Omega, Dt, TimeMs) ->
    Th1 = Th + Omega * Dt,
    Wanted = case abs(Omega) < 1.0e-12 of
                 true -> {X + V * Dt * math:cos(Th), Y + V * Dt * math:sin(Th)};
                 false -> R = V / Omega,
                          {X + R * (math:sin(Th1) - math:sin(Th)),
                           Y - R * (math:cos(Th1) - math:cos(Th))}
             end,
    Pos = resolve(Prev, Wanted, obstacles(W), radius(W), 8),
    Touching = contacts(W, Pos, W#world.touching),
    New = ordsets:subtract(Touching, W#world.touching),
    count(New, TimeMs, W#world{pos = Pos, theta = torobot_geometry:normalise_rad(Th1),
                               touching = Touching,
                               distance = W#world.distance + torobot_geometry:distance(Prev, Pos)}).

%% Projects the wanted position out of every obstacle it overlaps; repeated
%% because leaving one obstacle can push into another (corners). If that does
%% not settle, the robot stays where it was.
-spec resolve(torobot_geometry:point(), torobot_geometry:point(),
              [torobot_geometry:obstacle()], float(), non_neg_integer()) ->
          torobot_geometry:point().
resolve(Prev, Pos, Obstacles, Radius, Tries) ->
    case push_out(Prev, Pos, Obstacles, Radius, false) of
        {Pos1, false} -> Pos1;
        {Pos1, true} when Tries > 0 -> resolve(Prev, Pos1, Obstacles, Radius, Tries - 1);
        {_, true} -> Prev
    end.

-spec push_out(torobot_geometry:point(), torobot_geometry:point(),
               [torobot_geometry:obstacle()], float(), boolean()) ->
          {torobot_geometry:point(), boolean()}.
push_out(_Prev, Pos, [], _Radius, Pushed) ->
    {Pos, Pushed};
push_out(Prev, Pos, [{_, Shape, _} | Rest], Radius, Pushed) ->
    {Near, Reach} = case Shape of
                        {segment, A, B} -> {torobot_geometry:closest(Pos, A, B), Radius};
                        {disc, C, R} -> {C, Radius + R}
                    end,
    D = torobot_geometry:distance(Pos, Near),
    if
        D >= Reach - ?SLACK -> push_out(Prev, Pos, Rest, Radius, Pushed);
        D < 1.0e-12 -> push_out(Prev, Prev, Rest, Radius, true);
        true ->
            Out = torobot_geometry:add(Near, torobot_geometry:scale(torobot_geometry:sub(Pos, Near),
                                                                    Reach / D)),
            push_out(Prev, Out, Rest, Radius, true)
    end.

%% @doc The obstacles the robot at `Pos' touches, with hysteresis: one
%% already touched (in `Before') stays touched until the robot is clearly
%% away from it.
-spec contacts(#world{}, torobot_geometry:point(), ordsets:ordset(key())) ->
          ordsets:ordset(key()).
contacts(W, Pos, Before) ->
    Radius = radius(W),
    ordsets:from_list(
      [Key || {Key, Shape, _} <- obstacles(W),
              torobot_geometry:gap(Pos, Radius, Shape) =< case ordsets:is_element(Key, Before) of
                                                               true -> ?RELEASE;
                                                               false -> ?TOUCH
                                                           end]).

-spec count([key()], non_neg_integer(), #world{}) -> #world{}.
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

%%====================================================================
%% The robot in the scene
%%====================================================================

%% @doc The scene's obstacles and the other robots.
-spec obstacles(#world{}) -> [torobot_geometry:obstacle()].
obstacles(#world{obstacles = Obstacles, others = []}) ->
    Obstacles;
obstacles(#world{obstacles = Obstacles, others = Others}) ->
    Obstacles ++ [{{robot, Name}, {disc, Pos, R}, Name} || {Name, Pos, R, _} <- Others].

%% @doc The robot's radius in metres.
-spec radius(#world{}) -> float().
radius(#world{geometry = #{radius := R}}) -> float(R).

%% @doc The robot as the other robots of the world see it now.
-spec body(#world{}) -> torobot_world:body().
body(#world{name = Name, pos = Pos, colour = Colour} = W) ->
    {Name, Pos, radius(W), Colour}.

%% @doc Whether the robot could stand at a point without touching the
%% scene (the other robots aside).
-spec free(#world{}, torobot_geometry:point()) -> boolean().
free(#world{obstacles = Obstacles} = W, Pos) ->
    Radius = radius(W),
    lists:all(fun({_, Shape, _}) -> torobot_geometry:gap(Pos, Radius, Shape) >= 0 end, Obstacles).

%%====================================================================
%% The run
%%====================================================================

%% @doc Whether the run is over: its duration reached, or a red object touched
%% when `stop_on_red' is on.
-spec done(#world{}) -> boolean().
done(#world{time_ms = T, duration_ms = D, stop_on_red = Stop, red_touched_ms = Red}) ->
    T >= D orelse (Stop andalso Red =/= none).

%% @doc The run's outcome, as `torobot_sim:run/2' returns it, with the
%% figures the world asks for. A named robot (a world of several) also has
%% `robot_contacts', counted as walls are.
-spec summary(#world{}) -> torobot_world:summary().
summary(#world{extras = #{figures := Figures}} = W) ->
    Summary = maps:merge(maps:from_list([{F, figure(F, W)} || F <- Figures]),
                         #{red_touched_ms => W#world.red_touched_ms,
                           wall_contacts => W#world.wall_contacts,
                           blue_contacts => W#world.blue_contacts,
                           distance_m => W#world.distance}),
    case W#world.name of
        undefined -> Summary;
        _ -> Summary#{robot_contacts => W#world.robot_contacts}
    end.

-spec figure(atom(), #world{}) -> term().
figure(laps, #world{extras = #{lap_centre := Centre}, arena = {Aw, Ah}} = W) ->
    {Cx, Cy} = case Centre of
                   none -> {Aw / 2, Ah / 2};
                   C -> C
               end,
    Angles = [math:atan2(Y - Cy, X - Cx) || {_, X, Y, _} <- trajectory(W)],
    Turned = lists:sum([math:atan2(math:sin(B - A), math:cos(B - A))
                        || {A, B} <- lists:zip(lists:droplast(Angles), tl(Angles))]),
    round(abs(Turned) / (2 * math:pi()) * 100) / 100;
figure(coverage, #world{arena = {Aw, Ah}} = W) ->
    R = radius(W),
    Cells = [{(I + 0.5) * ?CELL, (J + 0.5) * ?CELL}
             || I <- lists:seq(0, trunc(Aw / ?CELL) - 1), J <- lists:seq(0, trunc(Ah / ?CELL) - 1)],
    Free = [C || C <- Cells, free(W, C)],
    Swept = lists:usort([{trunc(X / ?CELL), trunc(Y / ?CELL)} || {_, X, Y, _} <- trajectory(W)]
                        ++ [{trunc(X / ?CELL), trunc(Y / ?CELL)}
                            || {_, X0, Y0, _} <- trajectory(W),
                               {Ox, Oy} <- [{R, 0}, {-R, 0}, {0, R}, {0, -R}],
                               {X, Y} <- [{X0 + Ox, Y0 + Oy}], X >= 0, Y >= 0]),
    Visited = [C || {X, Y} = C <- Free, lists:member({trunc(X / ?CELL), trunc(Y / ?CELL)}, Swept)],
    case Free of
        [] -> 0.0;
        _ -> round(length(Visited) / length(Free) * 100) / 100
    end;
figure(docked_ms, #world{extras = #{dock := none}}) ->
    none;
figure(docked_ms, #world{extras = #{dock := {Dx, Dy}, beacon := #{dock_radius := DockR}}} = W) ->
    case [T || {T, X, Y, _} <- trajectory(W),
               (X - Dx) * (X - Dx) + (Y - Dy) * (Y - Dy) =< DockR * DockR] of
        [] -> none;
        [T | _] -> T
    end;
figure(light_distance_m, #world{pos = {X, Y}} = W) ->
    lamp_distance(W, X, Y);
figure(light_mean_m, W) ->
    case [lamp_distance(W, X, Y) || {_, X, Y, _} <- trajectory(W)] of
        [none | _] -> none;
        Ds -> round(lists:sum(Ds) / length(Ds) * 100) / 100
    end.

-spec lamp_distance(#world{}, float(), float()) -> float() | none.
lamp_distance(#world{extras = #{lights := Lights}}, X, Y) ->
    case [math:sqrt((Lx - X) * (Lx - X) + (Ly - Y) * (Ly - Y)) || {{Lx, Ly}, _} <- Lights] of
        [] -> none;
        Ds -> round(lists:min(Ds) * 100) / 100
    end.

-spec trajectory(#world{}) -> [torobot_world:sample()].
trajectory(#world{trajectory = Samples}) -> lists:reverse(Samples).
