%% @doc Draws a simulated run of the Torobot as a standalone SVG picture.
%%
%% Reads a `torobot_world' value and draws the arena and its walls, the red
%% and blue objects, the robot at its start (dashed) and final (filled)
%% poses, and the trajectory as polylines coloured by the tag of each step
%% (the behavior that won the motors), with a legend of the tags in the order
%% they first won and a caption with the run's summary. `torobot_sim' calls
%% {@link write/2} at the end of a run; {@link render/1} is the pure part.
%% A world of several robots is one picture too ({@link render_all/1},
%% {@link write_all/2}): each robot's trajectory, start and final pose (its
%% name beside it), one legend, and a caption line per robot.
%%
%% The picture is 100 pixels per metre with y up, as in the world file.
-module(torobot_svg).

-export([render/1, write/2, render_all/1, write_all/2, escape/1]).

-define(SCALE, 100).
-define(MARGIN, 20).
-define(ROW, 18).
%% Wide enough for the caption of a small room.
-define(MIN_WIDTH, 560).
%% Tag colours, avoiding the objects' red and blue; reused in turn when a
%% run has more tags than colours.
-define(PALETTE, ["#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
                  "#17becf", "#bcbd22", "#7f7f7f", "#000000"]).

%% @doc The SVG document for the world's run so far.
-spec render(torobot_world:world()) -> iodata().
render(World) ->
    render_all([World]).

%% @doc The SVG document for the run so far of the robots of one world (the
%% worlds `torobot_sim:simulate/2' returns for named robots).
-spec render_all([torobot_world:world(), ...]) -> iodata().
render_all([World | _] = Worlds) ->
    {W, H} = torobot_world:arena(World),
    Tags = lists:foldr(fun(Tag, Acc) -> [Tag | lists:delete(Tag, Acc)] end, [],
                       lists:append([tags(torobot_world:trajectory(R)) || R <- Worlds])),
    Colours = lists:zip(Tags, palette(length(Tags))),
    %% a caption line per robot, and one for its figures (torobot_sensors)
    Rows = [1 + min(1, map_size(torobot_sensors:figures(R))) || R <- Worlds],
    Width = max(px(W) + 2 * ?MARGIN, ?MIN_WIDTH),
    Bottom = px(H) + 2 * ?MARGIN,
    Height = Bottom + ?ROW * (lists:sum(Rows) + length(Tags)) + ?MARGIN div 2,
    Svg = ["<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n",
           "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\"",
           attrs([{width, Width}, {height, Height},
                  {viewBox, ["0 0 ", integer_to_list(Width), " ", integer_to_list(Height)]},
                  {'font-family', "sans-serif"}, {'font-size', 12}]), ">\n",
           "<title>Torobot run</title>\n",
           "<rect", attrs([{x, 0}, {y, 0}, {width, Width}, {height, Height},
                           {fill, "#ffffff"}]), "/>\n",
           "<rect", attrs([{x, ?MARGIN}, {y, ?MARGIN}, {width, px(W)}, {height, px(H)},
                           {fill, "#f7f7f2"}, {stroke, "#222222"}, {'stroke-width', 3}]),
           "/>\n",
           walls(World, H),
           objects(World, H),
           fixtures(World, H),
           [[trajectory(R, H, Colours),
             robot(torobot_world:start_pose(R), R, H, start),
             robot(torobot_world:pose(R), R, H, final)] || R <- Worlds],
           legend(Colours, Bottom + ?ROW * (lists:sum(Rows) - 1)),
           [caption(R, Bottom + ?ROW * Before)
            || {R, Before} <- lists:zip(Worlds, lists:droplast([0 | cumulative(Rows, 0)]))],
           "</svg>\n"],
    unicode:characters_to_binary(Svg).

%% @doc Writes the picture to `Path', through a temporary file renamed into
%% place so a reader never sees half a picture.
-spec write(torobot_world:world(), file:name_all()) -> ok | {error, term()}.
write(World, Path) ->
    write_all([World], Path).

%% @doc {@link write/2} for the robots of one world.
-spec write_all([torobot_world:world(), ...], file:name_all()) -> ok | {error, term()}.
write_all(Worlds, Path) ->
    Tmp = unicode:characters_to_list([Path, ".tmp"]),
    case file:write_file(Tmp, render_all(Worlds)) of
        ok -> file:rename(Tmp, Path);
        {error, _} = Error -> Error
    end.

-spec walls(torobot_world:world(), float()) -> iodata().
walls(World, H) ->
    ["<g id=\"walls\" stroke=\"#222222\" stroke-width=\"4\" stroke-linecap=\"round\">\n",
     [["<line", attrs([{x1, x(X1)}, {y1, y(Y1, H)}, {x2, x(X2)}, {y2, y(Y2, H)}]), "/>\n"]
      || {{X1, Y1}, {X2, Y2}} <- torobot_world:walls(World)],
     "</g>\n"].

-spec objects(torobot_world:world(), float()) -> iodata().
objects(World, H) ->
    ["<g id=\"objects\">\n",
     [["<circle", attrs([{cx, x(X)}, {cy, y(Y, H)}, {r, fmt(R * ?SCALE)},
                         {fill, object_colour(Colour)}]), "/>\n"]
      || {Colour, {X, Y}, R} <- torobot_world:objects(World)],
     "</g>\n"].

%% The library's floor lines (dark tape), lamps (yellow) and dock (a green
%% square), when the world has them.
-spec fixtures(torobot_world:world(), float()) -> iodata().
fixtures(World, H) ->
    Lamps = [["<circle", attrs([{cx, x(X)}, {cy, y(Y, H)}, {r, 8}, {fill, "#ffd700"},
                                {stroke, "#b8860b"}]), "/>\n"]
             || {{X, Y}, _} <- torobot_sensors:lights(World)],
    Dock = case torobot_sensors:dock(World) of
               none -> [];
               {X, Y} -> ["<rect", attrs([{x, x(X - 0.1)}, {y, y(Y + 0.1, H)}, {width, 20},
                                          {height, 20}, {fill, "none"}, {stroke, "#2ca02c"},
                                          {'stroke-width', 3}]), "/>\n"]
           end,
    Tape = [["<polyline", attrs([{points, lists:join(" ", [[x(X), ",", y(Y, H)] || {X, Y} <- Pts])},
                                 {fill, "none"}, {stroke, "#555555"}, {'stroke-width', 4},
                                 {'stroke-linejoin', "round"}]), "/>
"]
            || Pts <- torobot_sensors:floor_lines(World)],
    case Tape ++ Lamps ++ Dock of
        [] -> [];
        Drawn -> ["<g id=\"fixtures\">\n", Drawn, "</g>\n"]
    end.

-spec object_colour(torobot_world:colour()) -> string().
object_colour(red) -> "#d62728";
object_colour(blue) -> "#1f77b4".

%% One polyline per run of steps with the same tag, each starting where the
%% previous one ended so the path is unbroken.
-spec trajectory(torobot_world:world(), float(), [{term(), string()}]) -> iodata().
trajectory(World, H, Colours) ->
    Runs = case torobot_world:trajectory(World) of
               [{_, X0, Y0, _} | Steps] -> runs(Steps, {X0, Y0}, []);
               [] -> []
           end,
    ["<g id=\"", id("trajectory", World), "\" fill=\"none\" stroke-width=\"2\" stroke-linejoin=\"round\">\n",
     [["<polyline", attrs([{points, lists:join(" ", [[x(X), ",", y(Y, H)] || {X, Y} <- Points])},
                           {stroke, element(2, lists:keyfind(Tag, 1, Colours))}]), "/>\n"]
      || {Tag, Points} <- Runs],
     "</g>\n"].

-spec runs([torobot_world:sample()], {float(), float()}, [{term(), [{float(), float()}]}]) ->
          [{term(), [{float(), float()}]}].
runs([], _Last, Acc) ->
    lists:reverse([{Tag, lists:reverse(Points)} || {Tag, Points} <- Acc]);
runs([{_, X, Y, Tag} | Steps], _Last, [{Tag, Points} | Acc]) ->
    runs(Steps, {X, Y}, [{Tag, [{X, Y} | Points]} | Acc]);
runs([{_, X, Y, Tag} | Steps], Last, Acc) ->
    runs(Steps, {X, Y}, [{Tag, [{X, Y}, Last]} | Acc]).

%% The tags that coloured at least one step, in the order they first did.
-spec tags([torobot_world:sample()]) -> [term()].
tags([]) ->
    [];
tags([_Start | Steps]) ->
    lists:foldr(fun(Tag, Acc) -> [Tag | lists:delete(Tag, Acc)] end, [],
                [Tag || {_, _, _, Tag} <- Steps]).

-spec palette(non_neg_integer()) -> [string()].
palette(N) ->
    [lists:nth(I rem length(?PALETTE) + 1, ?PALETTE) || I <- lists:seq(0, N - 1)].

-spec robot(torobot_world:pose(), torobot_world:world(), float(), start | final) -> iodata().
robot({X, Y, Heading}, World, H, Which) ->
    R = torobot_world:robot_radius(World),
    Rad = Heading * math:pi() / 180,
    Nose = {X + R * math:cos(Rad), Y + R * math:sin(Rad)},
    Body = case Which of
               start -> [{fill, "none"}, {stroke, "#555555"}, {'stroke-dasharray', "4 3"}];
               final -> [{fill, "#555555"}, {'fill-opacity', "0.35"}, {stroke, "#222222"}]
           end,
    ["<g id=\"", id(atom_to_list(Which), World), "\" stroke-width=\"1.5\">\n",
     "<circle", attrs([{cx, x(X)}, {cy, y(Y, H)}, {r, fmt(R * ?SCALE)} | Body]), "/>\n",
     "<line", attrs([{x1, x(X)}, {y1, y(Y, H)}, {x2, x(element(1, Nose))},
                     {y2, y(element(2, Nose), H)}, {stroke, "#222222"}]), "/>\n",
     case {Which, torobot_world:name(World)} of
         {final, Name} when Name =/= undefined ->
             ["<text", attrs([{x, x(X + R)}, {y, y(Y + R, H)}]), ">",
              escape(atom_to_list(Name)), "</text>\n"];
         _ ->
             []
     end,
     "</g>\n"].

%% An element's id, the robot's name added in a world of named robots.
-spec id(string(), torobot_world:world()) -> iodata().
id(Base, World) ->
    case torobot_world:name(World) of
        undefined -> Base;
        Name -> escape([Base, "-", atom_to_list(Name)])
    end.

-spec legend([{term(), string()}], integer()) -> iodata().
legend(Colours, Top) ->
    ["<g id=\"legend\">\n",
     [begin
          Base = Top + ?ROW * I,
          ["<line", attrs([{x1, ?MARGIN}, {y1, Base - 4}, {x2, ?MARGIN + 24}, {y2, Base - 4},
                           {stroke, Colour}, {'stroke-width', 3}]), "/>\n",
           "<text", attrs([{x, ?MARGIN + 32}, {y, Base}]), ">",
           escape(io_lib:format("~tp", [Tag])), "</text>\n"]
      end || {I, {Tag, Colour}} <- lists:enumerate(Colours)],
     "</g>\n"].

-spec caption(torobot_world:world(), integer()) -> iodata().
caption(World, Top) ->
    #{red_touched_ms := Red, wall_contacts := Walls, blue_contacts := Blue,
      distance_m := Distance} = Summary = torobot_world:summary(World),
    Touched = case Red of
                  none -> "red not touched";
                  Ms -> ["red touched at ", fmt(Ms / 1000), " s"]
              end,
    Who = case torobot_world:name(World) of
              undefined -> "";
              Name -> [atom_to_list(Name), ": "]
          end,
    Figures = lists:join("; ", [[atom_to_list(K), " ", io_lib:format("~0p", [V])]
                               || {K, V} <- lists:sort(maps:to_list(torobot_sensors:figures(World)))]),
    Robots = case Summary of
                 #{robot_contacts := N} -> ["; robot contacts ", integer_to_list(N)];
                 #{} -> ""
             end,
    ["<text id=\"", id("caption", World), "\"", attrs([{x, ?MARGIN}, {y, Top}]), ">",
     escape([Who, Touched, Robots, "; wall contacts ", integer_to_list(Walls),
             "; blue contacts ", integer_to_list(Blue),
             "; distance ", fmt(Distance), " m; time ",
             fmt(torobot_world:time_ms(World) / 1000), " s"]),
     "</text>\n",
     case Figures of
         [] -> [];
         _ -> ["<text id=\"", id("figures", World), "\"", attrs([{x, ?MARGIN}, {y, Top + ?ROW}]), ">",
               escape(Figures), "</text>\n"]
     end].

%% Running sums: the row each robot's caption ends before.
-spec cumulative([non_neg_integer()], non_neg_integer()) -> [non_neg_integer()].
cumulative([], _Sum) -> [];
cumulative([N | Ns], Sum) -> [Sum + N | cumulative(Ns, Sum + N)].

-spec attrs([{atom(), iodata() | number()}]) -> iodata().
attrs(Attrs) ->
    [[" ", atom_to_list(Name), "=\"", value(Value), "\""] || {Name, Value} <- Attrs].

-spec value(iodata() | number()) -> iodata().
value(V) when is_integer(V) -> integer_to_list(V);
value(V) when is_float(V) -> fmt(V);
value(V) -> escape(V).

-spec x(float()) -> string().
x(X) -> fmt(?MARGIN + X * ?SCALE).

-spec y(float(), float()) -> string().
y(Y, H) -> fmt(?MARGIN + (H - Y) * ?SCALE).

-spec px(float()) -> integer().
px(Metres) -> round(Metres * ?SCALE).

-spec fmt(number()) -> string().
fmt(N) -> float_to_list(float(N), [{decimals, 2}, compact]).

%% @doc Text made safe for SVG (XML) content and attribute values.
-spec escape(unicode:chardata()) -> string().
escape(Text) ->
    lists:flatmap(fun($&) -> "&amp;";
                     ($<) -> "&lt;";
                     ($>) -> "&gt;";
                     ($") -> "&quot;";
                     (C) -> [C]
                  end, unicode:characters_to_list(Text)).
