%% @doc Plane geometry for the simulated world, pure: points as `{X, Y}'
%% tuples, segments (walls) and discs (objects, robots), rays cast from a
%% point, and the angles of headings. `torobot_world_step' pushes the robot
%% out of shapes and measures contacts with {@link gap/3}; 
%% `torobot_world_sensing' casts IR and range rays with {@link first_hit/4}
%% and finds what hides an object or a lamp with {@link crosses/3};
%% `torobot_worlds' keeps generated objects clear of walls with
%% {@link closest/3}.
%%
%% Functions by purpose: vectors ({@link add/2}, {@link sub/2},
%% {@link scale/2}, {@link dot/2}, {@link cross/2}, {@link distance/2});
%% shapes ({@link closest/3}, {@link gap/3}, {@link ray/3},
%% {@link first_hit/4}, {@link crosses/3}); numbers and angles
%% ({@link clamp/3}, {@link deg_to_rad/1}, {@link rad_to_deg/1},
%% {@link normalise_rad/1}, {@link normalise_deg/1}).
-module(torobot_geometry).

-export([add/2, sub/2, scale/2, dot/2, cross/2, distance/2]).
-export([closest/3, gap/3, ray/3, first_hit/4, crosses/3]).
-export([clamp/3, deg_to_rad/1, rad_to_deg/1, normalise_rad/1, normalise_deg/1]).

-export_type([point/0, shape/0, obstacle/0]).

-type point() :: {X :: float(), Y :: float()}.
-type shape() :: {segment, point(), point()} | {disc, point(), float()}.
%% A shape with the key the world counts contacts by and the world-file
%% term it came from (to name it in errors).
-type obstacle() :: {Key :: term(), shape(), Source :: term()}.

%%====================================================================
%% Vectors
%%====================================================================

%% @doc `P + Q'.
-spec add(point(), point()) -> point().
add({X1, Y1}, {X2, Y2}) -> {X1 + X2, Y1 + Y2}.

%% @doc `P - Q'.
-spec sub(point(), point()) -> point().
sub({X1, Y1}, {X2, Y2}) -> {X1 - X2, Y1 - Y2}.

%% @doc `K P'.
-spec scale(point(), number()) -> point().
scale({X, Y}, K) -> {X * K, Y * K}.

%% @doc The dot product.
-spec dot(point(), point()) -> float().
dot({X1, Y1}, {X2, Y2}) -> X1 * X2 + Y1 * Y2.

%% @doc The z component of the cross product.
-spec cross(point(), point()) -> float().
cross({X1, Y1}, {X2, Y2}) -> X1 * Y2 - Y1 * X2.

%% @doc The Euclidean distance.
-spec distance(point(), point()) -> float().
distance(P, Q) -> {Dx, Dy} = sub(P, Q), math:sqrt(Dx * Dx + Dy * Dy).

%%====================================================================
%% Shapes
%%====================================================================

%% @doc The point of the segment `A'-`B' closest to `P'.
-spec closest(point(), point(), point()) -> point().
closest(P, A, B) ->
    Edge = sub(B, A),
    T = clamp(dot(sub(P, A), Edge) / dot(Edge, Edge), 0.0, 1.0),
    add(A, scale(Edge, T)).

%% @doc The clearance between a disc of `Radius' at `Pos' and a shape:
%% negative when they overlap.
-spec gap(point(), float(), shape()) -> float().
gap(Pos, Radius, {segment, A, B}) -> distance(Pos, closest(Pos, A, B)) - Radius;
gap(Pos, Radius, {disc, C, R}) -> distance(Pos, C) - Radius - R.

%% @doc Where the ray `Origin + T * Dir' (`T >= 0') first meets a shape,
%% `T' in units of `Dir'. Parallel segments are missed: a ray grazing a
%% wall end-on sees the walls it meets next. A ray starting inside a disc
%% hits it at 0.
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

%% @doc How far along the ray `Origin + T * Dir' the first of the shapes
%% is met, `Max' when none is nearer.
-spec first_hit(point(), point(), [shape()], number()) -> number().
first_hit(Origin, Dir, Shapes, Max) ->
    lists:min([Max | [T || Shape <- Shapes, {hit, T} <- [ray(Origin, Dir, Shape)]]]).

%% @doc Whether any of the shapes stands on the segment from `From' to
%% `To': a segment crossing it, or a disc reaching it.
-spec crosses(point(), point(), [shape()]) -> boolean().
crosses(From, To, Shapes) ->
    Sight = sub(To, From),
    lists:any(fun({segment, _, _} = Wall) ->
                      case ray(From, Sight, Wall) of
                          {hit, T} -> T < 1;
                          miss -> false
                      end;
                 ({disc, C, R}) ->
                      distance(C, closest(C, From, To)) < R
              end, Shapes).

%%====================================================================
%% Numbers and angles
%%====================================================================

%% @doc `V' limited to `[Low, High]'.
-spec clamp(number(), number(), number()) -> number().
clamp(V, Low, High) -> max(Low, min(High, V)).

%% @doc Degrees to radians.
-spec deg_to_rad(number()) -> float().
deg_to_rad(D) -> D * math:pi() / 180.

%% @doc Radians to degrees.
-spec rad_to_deg(number()) -> float().
rad_to_deg(R) -> R * 180 / math:pi().

%% @doc The same angle in (-pi, pi].
-spec normalise_rad(number()) -> float().
normalise_rad(R) -> math:atan2(math:sin(R), math:cos(R)).

%% @doc The same angle in (-180, 180] degrees.
-spec normalise_deg(number()) -> float().
normalise_deg(D) -> rad_to_deg(normalise_rad(deg_to_rad(D))).
