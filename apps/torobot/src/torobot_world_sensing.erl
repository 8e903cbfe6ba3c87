%% @doc What the robot senses in the world, pure: the Torobot's two IR
%% sensors and its camera (the detector's datagrams, as the board's
%% detector sends them), and the measurements the library's sensor models
%% (`torobot_sensors', through `torobot_world') are made of: a range along
%% a direction, the bearings of contacts, a line of sight. `torobot_world'
%% exposes each of them; the rays and occlusion are `torobot_geometry''s.
%%
%% <h3>Sensors</h3>
%% IR: one ray from each sensor, stopped by walls, objects and other robots.
%% Camera: an object is seen when its centre is ahead within half the field
%% of view and within range, the line of sight to its centre crosses no
%% wall and no other object or robot, and its apparent area reaches
%% `min_area'. The image `y' of a centre below the frame is clamped to the
%% frame's edge, where the detector would find the visible part of the
%% ball. Of each colour the largest (closest) object is reported. Noise is
%% Gaussian and depends only on the seed, the time and the channel, so
%% sensing stays a function of the world.
%%
%% <h3>JSON</h3>
%% The datagrams are written with `jiffy', the project's JSON encoder
%% (`toroco_net' and `toroco_udp_camera' decode them with it; the dashboard
%% uses it through `toroco_rec_json', and `toroco_rec_json_text' is the
%% one plain-Erlang writer, for the event path's small messages where a NIF
%% call's fixed cost would dominate).
-module(torobot_world_sensing).

-include("torobot_world.hrl").

-export([ir/1, ir_levels/2, ir_thresholds/1, camera/1, view/1]).
-export([range/3, contact_bearings/1, line_of_sight/3]).

-type adc() :: 0..1023.
%% What the camera makes of an object: {Area, -Distance, X, Y}, so that
%% the largest blob, then the closest, is the maximum.
-type blob() :: {non_neg_integer(), float(), integer(), integer()}.

%%====================================================================
%% IR
%%====================================================================

%% @doc The raw 10-bit ADC readings of the two IR sensors (higher = nearer).
-spec ir(#world{}) -> torobot_world:ir_reading().
ir(#world{ir = #{mount_deg := Mount}} = W) ->
    #{left => ir_reading(W, torobot_geometry:deg_to_rad(Mount), left),
      right => ir_reading(W, -torobot_geometry:deg_to_rad(Mount), right)}.

-spec ir_reading(#world{}, float(), left | right) -> adc().
ir_reading(#world{ir = Ir} = W, Mount, Side) ->
    #{min_range := Min, max_range := Max, curve := {K, D0, C}, noise := Noise} = Ir,
    D = torobot_geometry:clamp(range(W, Mount, Max), Min, Max),
    Value = K / (D * 100 + D0) + C + noise(W, {ir, Side}, Noise),
    torobot_geometry:clamp(round(Value), 0, 1023).

%% @doc The near/far state of each IR sensor after the current readings, given
%% the previous state: the same hysteresis the PRU applies to the ADC.
-spec ir_levels(#world{}, torobot_world:ir_levels()) -> torobot_world:ir_levels().
ir_levels(#world{ir = #{threshold_high := High, threshold_low := Low}} = W, Previous) ->
    maps:map(fun(Side, Adc) ->
                     if Adc >= High -> near;
                        Adc =< Low -> far;
                        true -> maps:get(Side, Previous)
                     end
             end, ir(W)).

%% @doc The world's IR thresholds as ADC levels, for configuring the sensors.
-spec ir_thresholds(#world{}) -> #{threshold_high := adc(), threshold_low := adc()}.
ir_thresholds(#world{ir = Ir}) ->
    maps:with([threshold_high, threshold_low], Ir).

%% @doc What a viewer draws of the sensors now: each IR ray from its sensor
%% to what it meets (or to its range) with its reading, and the camera's
%% field of view (it looks along the heading from the robot's centre).
-spec view(#world{}) -> #{ir := [#{side := left | right, from := torobot_geometry:point(),
                                   to := torobot_geometry:point(), adc := adc()}],
                          camera := #{fov_deg := number(), range := number()}}.
view(#world{ir = #{mount_deg := Mount, max_range := Max},
            camera = #{fov_deg := Fov, range := Range}} = W) ->
    Readings = ir(W),
    Ray = fun(Side, Angle) ->
                  {Origin, Dir} = beam(W, Angle),
                  #{side => Side, from => Origin,
                    to => torobot_geometry:add(Origin, torobot_geometry:scale(Dir, range(W, Angle, Max))),
                    adc => maps:get(Side, Readings)}
          end,
    #{ir => [Ray(left, torobot_geometry:deg_to_rad(Mount)),
             Ray(right, -torobot_geometry:deg_to_rad(Mount))],
      camera => #{fov_deg => Fov, range => Range}}.

%%====================================================================
%% What the library's sensors are made of
%%====================================================================

%% @doc The distance in metres from the robot's rim, at `MountRad' from the
%% heading (counter-clockwise), to the first wall, object or other robot
%% along that direction; `Max' when there is none nearer.
-spec range(#world{}, float(), number()) -> number().
range(W, MountRad, Max) ->
    {Origin, Dir} = beam(W, MountRad),
    torobot_geometry:first_hit(Origin, Dir, shapes(torobot_world_step:obstacles(W)), Max).

%% A unit ray from the robot's rim at `MountRad' from the heading.
-spec beam(#world{}, float()) -> {torobot_geometry:point(), torobot_geometry:point()}.
beam(#world{pos = Pos, theta = Th} = W, MountRad) ->
    Dir = {math:cos(Th + MountRad), math:sin(Th + MountRad)},
    {torobot_geometry:add(Pos, torobot_geometry:scale(Dir, torobot_world_step:radius(W))), Dir}.

%% @doc The bearings (degrees from the heading, counter-clockwise) of the
%% walls, objects and other robots the robot touches now.
-spec contact_bearings(#world{}) -> [float()].
contact_bearings(#world{pos = Pos, theta = Th} = W) ->
    Radius = torobot_world_step:radius(W),
    [torobot_geometry:rad_to_deg(torobot_geometry:normalise_rad(math:atan2(Dy, Dx) - Th))
     || {_, Shape, _} <- torobot_world_step:obstacles(W),
        torobot_geometry:gap(Pos, Radius, Shape) =< ?RELEASE,
        {Dx, Dy} <- [torobot_geometry:sub(case Shape of
                                              {segment, A, B} -> torobot_geometry:closest(Pos, A, B);
                                              {disc, C, _} -> C
                                          end, Pos)]].

%% @doc Whether no wall (the arena's included) crosses the segment between
%% two points.
-spec line_of_sight(#world{}, torobot_geometry:point(), torobot_geometry:point()) -> boolean().
line_of_sight(#world{obstacles = Obstacles}, From, To) ->
    not torobot_geometry:crosses(From, To, [S || {_, {segment, _, _} = S, _} <- Obstacles]).

-spec shapes([torobot_geometry:obstacle()]) -> [torobot_geometry:shape()].
shapes(Obstacles) -> [Shape || {_, Shape, _} <- Obstacles].

%%====================================================================
%% Camera
%%====================================================================

%% @doc What the detector would send for the current camera frame: one JSON
%% datagram for red, then one for blue, each either the largest visible
%% object of that colour or the `none' form.
-spec camera(#world{}) -> [binary()].
camera(W) ->
    Seen = [{Colour, Blob} || {Colour, _, _} = Object <- W#world.objects ++ carried(W),
                              {ok, Blob} <- [project(W, Object)]],
    [datagram(Colour, largest([Blob || {C, Blob} <- Seen, C =:= Colour]), W)
     || Colour <- [red, blue]].

%% The colours the other robots carry, as objects the camera may see.
-spec carried(#world{}) -> [{torobot_world:colour(), torobot_geometry:point(), float()}].
carried(#world{others = Others}) ->
    [{Colour, Pos, R} || {_, Pos, R, Colour} <- Others, Colour =/= none].

-spec project(#world{}, {torobot_world:colour(), torobot_geometry:point(), float()}) ->
          {ok, blob()} | error.
project(#world{pos = Pos, theta = Th, camera = Cam} = W, {Colour, Centre, R}) ->
    #{fov_deg := Fov, frame := {Wpx, Hpx}, range := Range, height := Height,
      min_area := MinArea, noise := Noise} = Cam,
    HalfFov = torobot_geometry:deg_to_rad(Fov) / 2,
    F = Wpx / 2 / math:tan(HalfFov),
    {Dx, Dy} = torobot_geometry:sub(Centre, Pos),
    Ahead = Dx * math:cos(Th) + Dy * math:sin(Th),
    Left = -Dx * math:sin(Th) + Dy * math:cos(Th),
    Dist = torobot_geometry:distance(Pos, Centre),
    Area = min(Wpx * Hpx, round(math:pi() * math:pow(F * R / Dist, 2))),
    Hiding = [S || {_, S, _} <- torobot_world_step:obstacles(W), S =/= {disc, Centre, R}],
    Visible = Ahead > 0
        andalso Dist =< Range
        andalso abs(math:atan2(Left, Ahead)) =< HalfFov
        andalso Area >= MinArea
        andalso not torobot_geometry:crosses(Pos, Centre, Hiding),
    case Visible of
        true ->
            X = round(-F * Left / Ahead + noise(W, {Colour, x}, Noise)),
            Y = round(F * (Height - R) / Ahead + noise(W, {Colour, y}, Noise)),
            {ok, {Area, -Dist, torobot_geometry:clamp(X, -(Wpx div 2), Wpx div 2),
                  torobot_geometry:clamp(Y, -(Hpx div 2), Hpx div 2)}};
        false ->
            error
    end.

-spec largest([blob()]) -> blob() | none.
largest([]) -> none;
largest(Blobs) -> lists:max(Blobs).

%% The detector's datagram (SPEC §7b): keys in the detector's order.
-spec datagram(torobot_world:colour(), blob() | none, #world{}) -> binary().
datagram(Colour, none, _W) ->
    iolist_to_binary(jiffy:encode({[{color, Colour}, {none, true}]}));
datagram(Colour, {Area, _, X, Y}, #world{time_ms = T}) ->
    iolist_to_binary(jiffy:encode({[{color, Colour}, {x, X}, {y, Y}, {area, Area}, {t, T}]})).

%% Gaussian noise that depends only on the seed, the time and the channel.
-spec noise(#world{}, term(), number()) -> float().
noise(_W, _Channel, Sigma) when Sigma == 0 ->
    0.0;
noise(#world{seed = Seed, time_ms = T}, Channel, Sigma) ->
    {N, _} = rand:normal_s(rand:seed_s(exsss, {Seed, T, erlang:phash2(Channel)})),
    N * Sigma.
