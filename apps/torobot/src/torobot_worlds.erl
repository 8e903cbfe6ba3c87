%% @doc Seeded worlds for the simulated lab (SPEC §14): random, valid, and
%% the same for the same seed.
%%
%% {@link generate/2} returns the terms of a world file (as
%% `file:consult/1' would read them), which `torobot_sim:run/2' and
%% `torobot_sim:batch/1' take as they are, `torobot_world:from_terms/1'
%% builds, and {@link write/2} saves. A generated world has an arena, a few
%% inner walls (axis-aligned segments), one red object, a few blue ones and
%% the robot, and is valid by construction:
%% <ul>
%% <li>every object is clear of every wall and of every other object;</li>
%% <li>the robot starts clear of everything (not merely not overlapping);</li>
%% <li>red is reachable: a robot-sized disc can drive from the start to
%%     touching it without touching a wall or a blue object (checked on a
%%     10 cm grid of the free space, which only errs towards refusing).</li>
%% </ul>
%% A draw that breaks one of these is thrown away and the next one drawn
%% from the same random stream, so a seed always gives one world.
%%
%% Options (defaults in brackets): `arena' (`random': 4-8 by 3-6 m in half
%% metres; or `{W, H}'), `walls' (at most 3 inner walls), `blue' (at most 3
%% blue objects), `duration_s' (60), `stop_on_red' (`true').
%% {@link reachable/1} is the reachability check, for tests.
-module(torobot_worlds).

-export([generate/2, reachable/1, write/2]).

-export_type([opts/0]).

-type opts() :: #{arena => random | {number(), number()}, walls => non_neg_integer(),
                  blue => non_neg_integer(), duration_s => pos_integer(),
                  stop_on_red => boolean()}.

-define(ROBOT_RADIUS, 0.12).
-define(OBJECT_RADIUS, 0.10).
%% Gaps, in metres, kept free around what is placed.
-define(OBJECT_GAP, 0.30).
-define(START_GAP, 0.25).
-define(GRID, 0.10).
-define(TRIES, 50).

%% @doc The world of `Seed': terms of a world file, valid (see the module
%% doc); the same seed and options give the same terms.
-spec generate(integer(), opts()) -> [tuple()].
generate(Seed, Opts) when is_integer(Seed), is_map(Opts) ->
    attempt(rand:seed_s(exsss, Seed), Seed, Opts).

%% @doc Whether a robot of the Torobot's size can drive from the start to
%% touching a red object without touching a wall or a blue object.
-spec reachable([tuple()]) -> boolean().
reachable(Terms) ->
    {arena, {W, H}} = lists:keyfind(arena, 1, Terms),
    {robot, {X, Y, _}} = lists:keyfind(robot, 1, Terms),
    Walls = arena_walls(W, H) ++ [S || {wall, S} <- Terms],
    Blocks = [{C, R} || {object, blue, C, R} <- Terms],
    Reds = [{C, R} || {object, red, C, R} <- Terms],
    Free = fun(P) -> clear(P, ?ROBOT_RADIUS + 0.01, Walls, Blocks ++ Reds) end,
    Goal = fun(P) -> lists:any(fun({C, R}) ->
                                       torobot_geometry:distance(P, C) =< ?ROBOT_RADIUS + R + ?GRID
                               end, Reds) end,
    Start = cell({X, Y}),
    search([Start], #{Start => true}, Free, Goal, {W, H}).

%% @doc Writes world terms as a world file.
-spec write([tuple()], file:name_all()) -> ok | {error, term()}.
write(Terms, Path) ->
    file:write_file(Path, [io_lib:format("~tp.~n", [T]) || T <- Terms]).

%%====================================================================
%% Drawing
%%====================================================================

attempt(R0, Seed, Opts) ->
    {{W, H}, R1} = arena(maps:get(arena, Opts, random), R0),
    {NWalls, R2} = upto(maps:get(walls, Opts, 3), R1),
    {Walls, R3} = repeat(NWalls, fun(Acc, R) -> wall(W, H, Acc, R) end, [], R2),
    Segments = arena_walls(W, H) ++ Walls,
    {Red, R4} = place(fun(R) -> object(W, H, Segments, [], R) end, R3),
    {NBlue, R5} = upto(maps:get(blue, Opts, 3), R4),
    {Blues, R6} = repeat(NBlue, fun(Acc, R) -> object(W, H, Segments, [Red | Acc], R) end,
                         [], R5),
    Objects = [Red | Blues],
    {Start, R7} = place(fun(R) -> start(W, H, Segments, Objects, R) end, R6),
    case {Red, Start} of
        {none, _} ->
            attempt(R7, Seed, Opts);
        {_, none} ->
            attempt(R7, Seed, Opts);
        {{Rc, Rr}, {Sx, Sy, Sh}} ->
            Terms = [{arena, {W, H}}]
                ++ [{wall, S} || S <- Walls]
                ++ [{object, red, Rc, Rr}]
                ++ [{object, blue, C, Rad} || {C, Rad} <- Blues]
                ++ [{robot, {Sx, Sy, Sh}},
                    {duration_s, maps:get(duration_s, Opts, 60)},
                    {stop_on_red, maps:get(stop_on_red, Opts, true)},
                    {seed, Seed}],
            case reachable(Terms) andalso torobot_world:from_terms(Terms) of
                {ok, _} -> Terms;
                _ -> attempt(R7, Seed, Opts)
            end
    end.

arena(random, R0) ->
    {A, R1} = rand:uniform_s(9, R0),
    {B, R2} = rand:uniform_s(7, R1),
    {{3.5 + A * 0.5, 2.5 + B * 0.5}, R2};
arena({W, H}, R) when is_number(W), is_number(H), W > 1, H > 1 ->
    {{float(W), float(H)}, R}.

upto(Max, R0) ->
    {N, R1} = rand:uniform_s(Max + 1, R0),
    {N - 1, R1}.

repeat(0, _Fun, Acc, R) ->
    {lists:reverse(Acc), R};
repeat(N, Fun, Acc, R0) ->
    case place(fun(R) -> Fun(Acc, R) end, R0) of
        {none, R1} -> repeat(N - 1, Fun, Acc, R1);
        {Thing, R1} -> repeat(N - 1, Fun, [Thing | Acc], R1)
    end.

%% Draws until the candidate fits, at most ?TRIES times.
place(Draw, R) ->
    place(Draw, R, ?TRIES).

place(_Draw, R, 0) ->
    {none, R};
place(Draw, R0, Tries) ->
    case Draw(R0) of
        {ok, Thing, R1} -> {Thing, R1};
        {no, R1} -> place(Draw, R1, Tries - 1)
    end.

%% An axis-aligned inner wall, 0.8 m up to half the arena's shorter side
%% long, kept 0.6 m off the arena's walls so the robot can go round it.
wall(W, H, _Walls, R0) ->
    {Vertical, R1} = rand:uniform_s(2, R0),
    {L, R2} = uniform(0.8, max(0.9, min(W, H) / 2), R1),
    {X, R3} = uniform(0.6, W - 0.6, R2),
    {Y, R4} = uniform(0.6, H - 0.6, R3),
    Segment = case Vertical of
                  1 -> {{round2(X), round2(Y)}, {round2(X), round2(min(H - 0.6, Y + L))}};
                  2 -> {{round2(X), round2(Y)}, {round2(min(W - 0.6, X + L)), round2(Y)}}
              end,
    case Segment of
        {P, P} -> {no, R4};
        {{X1, Y1}, {X2, Y2}} when abs(X2 - X1) + abs(Y2 - Y1) < 0.5 -> {no, R4};
        _ -> {ok, Segment, R4}
    end.

object(W, H, Walls, Objects, R0) ->
    {X, R1} = uniform(0.3, W - 0.3, R0),
    {Y, R2} = uniform(0.3, H - 0.3, R1),
    C = {round2(X), round2(Y)},
    case clear(C, ?OBJECT_RADIUS + ?OBJECT_GAP, Walls, Objects) of
        true -> {ok, {C, ?OBJECT_RADIUS}, R2};
        false -> {no, R2}
    end.

start(W, H, Walls, Objects, R0) ->
    {X, R1} = uniform(0.4, W - 0.4, R0),
    {Y, R2} = uniform(0.4, H - 0.4, R1),
    {Heading, R3} = rand:uniform_s(360, R2),
    C = {round2(X), round2(Y)},
    case clear(C, ?ROBOT_RADIUS + ?START_GAP, Walls, Objects) of
        true -> {ok, {element(1, C), element(2, C), float(Heading - 180)}, R3};
        false -> {no, R3}
    end.

uniform(Low, High, R0) ->
    {U, R1} = rand:uniform_s(R0),
    {Low + U * (High - Low), R1}.

round2(V) -> round(V * 100) / 100.

%%====================================================================
%% Geometry and the reachability search
%%====================================================================

arena_walls(W, H) ->
    [{{0.0, 0.0}, {W, 0.0}}, {{W, 0.0}, {W, H}}, {{W, H}, {0.0, H}}, {{0.0, H}, {0.0, 0.0}}].

%% Whether a disc of radius Gap at P keeps off every wall and object.
clear(P, Gap, Walls, Objects) ->
    lists:all(fun({A, B}) -> torobot_geometry:distance(P, torobot_geometry:closest(P, A, B)) >= Gap
              end, Walls)
        andalso lists:all(fun({C, R}) -> torobot_geometry:distance(P, C) >= Gap + R end, Objects).

search([], _Seen, _Free, _Goal, _Size) ->
    false;
search([Cell | Queue], Seen, Free, Goal, Size) ->
    P = centre(Cell),
    case Goal(P) of
        true ->
            true;
        false ->
            Next = [N || N <- neighbours(Cell, Size), not is_map_key(N, Seen),
                         Free(centre(N))],
            search(Next ++ Queue, lists:foldl(fun(N, S) -> S#{N => true} end, Seen, Next),
                   Free, Goal, Size)
    end.

cell({X, Y}) -> {round(X / ?GRID), round(Y / ?GRID)}.
centre({I, J}) -> {I * ?GRID, J * ?GRID}.

neighbours({I, J}, {W, H}) ->
    [{I + Di, J + Dj} || {Di, Dj} <- [{1, 0}, {-1, 0}, {0, 1}, {0, -1}],
                         I + Di >= 0, J + Dj >= 0,
                         (I + Di) * ?GRID =< W, (J + Dj) * ?GRID =< H].
