%% @doc The world file: reading it, checking every term, filling in the
%% defaults and building the world value at its start (one per robot).
%% `torobot_world' exposes this as {@link torobot_world:load/1},
%% {@link torobot_world:from_terms/1}, {@link torobot_world:load_all/1} and
%% {@link torobot_world:from_terms_all/1}; the terms of the library's
%% sensors and fixtures, documented in `torobot_sensors', are checked here
%% too ({@link library_term/1}), so the world is built without calling back
%% into the sensor models.
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
%%     seeing the others as solid discs ({@link torobot_world:set_others/2});
%%     contacts with them are counted per robot as `robot_contacts'.</li>
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
%% the figures a run is measured by are optional terms too; their doc is
%% in `torobot_sensors'.
%%
%% A bad world gives `{error, Reason}' naming the culprit: `{file, Why}',
%% `{bad_term, Term}', `{duplicate, Term}', `{missing, arena | robot |
%% duration_s}', `{outside_arena, Term}' or `{blocked_start, RobotTerm,
%% ObstacleTerm}' (the robot starts overlapping a wall or an object).
-module(torobot_world_file).

-include("torobot_world.hrl").

-export([load/1, from_terms/1, load_all/1, from_terms_all/1]).
-export([library_term/1]).

-define(GEOMETRY, #{radius => 0.12, wheel_base => 0.20, max_wheel_speed => 0.25}).
-define(IR, #{mount_deg => 30, min_range => 0.10, max_range => 0.80,
              curve => {6787, 4, 3}, threshold_high => 240, threshold_low => 200,
              noise => 0}).
-define(CAMERA, #{fov_deg => 60, frame => {320, 240}, range => 4.0,
                  height => 0.20, min_area => 10, noise => 0}).
%% The library's sensors and fixtures (`torobot_sensors').
-define(RANGE, #{sensors => #{front => 0, front_left => 45, front_right => -45,
                              left => 90, right => -90, rear => 180},
                 max_range => 1.5}).
-define(BUMPER, #{front_deg => 25, side_deg => 110}).
-define(LIGHT_SENSOR, #{mount_deg => 45, half_distance => 0.5}).
-define(BEACON, #{range => 6.0, dock_radius => 0.10}).
-define(GREY_SENSOR, #{offset => 0.06, spread => 0.03, width => 0.02, dark => 900, light => 100}).
-define(FIGURES, [laps, coverage, docked_ms, light_distance_m, light_mean_m]).
-define(SINGLE, [arena, robot, duration_s, robot_geometry, ir, camera, seed,
                 tick_ms, stop_on_red,
                 range, bumper, light_sensor, dock, beacon, figures, lap_centre, grey_sensor]).

%%====================================================================
%% Reading
%%====================================================================

%% @doc Reads a world file (`file:consult/1' terms, see the module doc).
-spec load(file:name_all()) -> {ok, #world{}} | {error, torobot_world:reason()}.
load(File) ->
    case load_all(File) of
        {ok, _} = Loaded -> one(Loaded);
        {error, _} = Error -> Error
    end.

%% @doc Builds a world from the terms of a world file. A world of several
%% robots is refused as `{several_robots, Names}': see {@link from_terms_all/1}.
-spec from_terms([term()]) -> {ok, #world{}} | {error, torobot_world:reason()}.
from_terms(Terms) ->
    one(from_terms_all(Terms)).

-spec one({ok, [#world{}, ...]} | {error, torobot_world:reason()}) ->
          {ok, #world{}} | {error, torobot_world:reason()}.
one({ok, [World]}) -> {ok, World};
one({ok, Worlds}) -> {error, {several_robots, [W#world.name || W <- Worlds]}};
one({error, _} = Error) -> Error.

%% @doc Reads a world file of any number of robots: one world per robot,
%% in file order (see {@link from_terms_all/1}).
-spec load_all(file:name_all()) -> {ok, [#world{}, ...]} | {error, torobot_world:reason()}.
load_all(File) ->
    case file:consult(File) of
        {ok, Terms} -> from_terms_all(Terms);
        {error, Why} -> {error, {file, Why}}
    end.

%% @doc Builds one world per robot of a world file: the same scene, each
%% with its own robot and the others as bodies.
%% Robots are either the one `{robot, Pose}' or any number of
%% `{robot, Name, Pose}' / `{robot, Name, Pose, #{colour => red | blue}}'
%% with distinct names; mixing the forms or repeating a name is
%% `{duplicate, Term}', robots starting on each other `{blocked_start,
%% RobotTerm, OtherRobotTerm}'.
-spec from_terms_all([term()]) -> {ok, [#world{}, ...]} | {error, torobot_world:reason()}.
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

%%====================================================================
%% Checking the terms
%%====================================================================

-spec fleet([{{atom(), torobot_world:pose(), torobot_world:colour() | none}, term()}], map()) ->
          {ok, [#world{}, ...]} | {error, torobot_world:reason()}.
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
                [] -> {ok, [W#world{others = [torobot_world_step:body(O) || O <- Worlds, O =/= W]}
                             || W <- Worlds]}
            end
    end.

-spec overlapping(#world{}, #world{}) -> boolean().
overlapping(A, B) ->
    {_, Pa, Ra, _} = torobot_world_step:body(A),
    {_, Pb, Rb, _} = torobot_world_step:body(B),
    torobot_geometry:distance(Pa, Pb) - Ra - Rb < -?SLACK.

-spec parse([term()] | term(), map()) -> {ok, map()} | {error, torobot_world:reason()}.
parse([], Acc) ->
    {ok, Acc};
parse([Term | Terms], Acc) ->
    case term(Term) of
        {ok, Key, Value} ->
            case lists:member(Key, ?SINGLE) of
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
    case options(Section, Opts, fun(K, V) -> option(Section, K, V) end) of
        {ok, Section, Merged} = Checked ->
            case consistent(Section, Merged) of
                true -> Checked;
                false -> error
            end;
        error ->
            error
    end;
term(Other) ->
    library_term(Other).

-spec point(term()) -> {ok, torobot_geometry:point()} | error.
point({X, Y}) when is_number(X), is_number(Y) -> {ok, {float(X), float(Y)}};
point(_) -> error.

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

-spec build(map()) -> {ok, #world{}} | {error, torobot_world:reason()}.
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
    Blocking = [T || {_, Shape, T} <- Obstacles,
                      torobot_geometry:gap(Pos, Radius, Shape) < -?SLACK],
    case {Outside, Inside(Pos), Blocking} of
        {[Culprit | _], _, _} ->
            {error, {outside_arena, Culprit}};
        {[], false, _} ->
            {error, {outside_arena, RobotTerm}};
        {[], true, [Obstacle | _]} ->
            {error, {blocked_start, RobotTerm, Obstacle}};
        {[], true, []} ->
            Start = {X, Y, torobot_geometry:normalise_deg(Hd)},
            World = #world{arena = {W, H},
                           walls = [Wall || {Wall, _} <- Walls],
                           objects = [O || {O, _} <- Objects],
                           obstacles = Obstacles,
                           start = Start,
                           pos = Pos,
                           theta = torobot_geometry:deg_to_rad(Hd),
                           duration_ms = max(1, round(S * 1000)),
                           geometry = Geometry,
                           ir = value(ir, P),
                           camera = value(camera, P),
                           seed = value(seed, P),
                           tick_ms = value(tick_ms, P),
                           stop_on_red = value(stop_on_red, P),
                           trajectory = [{0, X, Y, start}],
                           extras = library(P)},
            {ok, World#world{touching = torobot_world_step:contacts(World, Pos, [])}}
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
default(stop_on_red) -> true;
default(range) -> ?RANGE;
default(bumper) -> ?BUMPER;
default(light_sensor) -> ?LIGHT_SENSOR;
default(beacon) -> ?BEACON;
default(grey_sensor) -> none;
default(dock) -> none;
default(figures) -> [];
default(lap_centre) -> none.

%%====================================================================
%% The library's sensors and fixtures (torobot_sensors)
%%====================================================================

%% @doc Checks one world-file term of the library's sensors and fixtures
%% (`torobot_sensors'); `{ok, Key, Value}' or `error'.
-spec library_term(term()) -> {ok, atom(), term()} | error.
library_term({range, #{} = Opts}) ->
    options(range, Opts, fun(sensors, M) when is_map(M) ->
                                 lists:all(fun({K, V}) -> is_atom(K) andalso is_number(V) end,
                                           maps:to_list(M));
                            (max_range, V) -> positive(V);
                            (_, _) -> false
                         end);
library_term({bumper, #{} = Opts}) ->
    options(bumper, Opts, fun(_, V) -> positive(V) andalso V =< 180 end);
library_term({light_sensor, #{} = Opts}) ->
    options(light_sensor, Opts, fun(mount_deg, V) -> is_number(V) andalso V >= 0 andalso V < 180;
                                   (half_distance, V) -> positive(V)
                                end);
library_term({grey_sensor, #{} = Opts}) ->
    Valid = fun(K, V) when K =:= dark; K =:= light -> is_integer(V) andalso V >= 0 andalso V =< 1023;
               (spread, V) -> is_number(V) andalso V >= 0;
               (_, V) -> positive(V)
            end,
    case lists:all(fun({K, V}) -> is_map_key(K, ?GREY_SENSOR) andalso Valid(K, V) end,
                   maps:to_list(Opts)) of
        true -> {ok, grey_sensor, maps:merge(?GREY_SENSOR, Opts)};
        false -> error
    end;
library_term({floor_line, [_, _ | _] = Ps}) ->
    case [Pt || P <- Ps, {ok, Pt} <- [point(P)]] of
        Pts when length(Pts) =:= length(Ps) -> {ok, floor_line, Pts};
        _ -> error
    end;
library_term({beacon, #{} = Opts}) ->
    options(beacon, Opts, fun(_, V) -> positive(V) end);
library_term({light, P, Power}) when is_number(Power), Power >= 0 ->
    case point(P) of
        {ok, Pt} -> {ok, light, {Pt, float(Power)}};
        error -> error
    end;
library_term({Key, P}) when Key =:= dock; Key =:= lap_centre ->
    case point(P) of
        {ok, Pt} -> {ok, Key, Pt};
        error -> error
    end;
library_term({figures, L}) when is_list(L) ->
    case lists:all(fun(F) -> lists:member(F, ?FIGURES) end, L) of
        true -> {ok, figures, L};
        false -> error
    end;
library_term(_) ->
    error.

-spec options(atom(), map(), fun((atom(), term()) -> boolean())) -> {ok, atom(), map()} | error.
options(Key, Opts, Valid) ->
    Defaults = default(Key),
    case lists:all(fun({K, V}) -> is_map_key(K, Defaults) andalso Valid(K, V) end,
                   maps:to_list(Opts)) of
        true -> {ok, Key, maps:merge(Defaults, Opts)};
        false -> error
    end.

%% The library's part of a world (`torobot_world:extras/1').
-spec library(map()) -> map().
library(Parsed) ->
    Lights = lists:reverse([L || {L, _} <- maps:get(light, Parsed, [])]),
    Lines = lists:reverse([L || {L, _} <- maps:get(floor_line, Parsed, [])]),
    maps:from_list([{lights, Lights}, {floor_lines, Lines}
                    | [{Key, value(Key, Parsed)}
                       || Key <- [range, bumper, light_sensor, beacon, dock, figures, lap_centre,
                                  grey_sensor]]]).
