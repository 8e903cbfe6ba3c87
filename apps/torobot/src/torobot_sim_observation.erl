%% @doc What the properties of the robustness lab judge (SPEC §17), made
%% from a simulated robot's tick: `torobot_sim' hands each tick's world
%% (after the robot moved), the motors it applied, the lines its event
%% path traced and the observation before; this module is pure.
%%
%% Functions: `observation/4' (one tick), `events/1' (the events of trace
%% lines that conditions name), `distance_to_wall/1'.
-module(torobot_sim_observation).

-export([observation/4, events/1, distance_to_wall/1]).

%% @doc The tick's observation: contacts since the last one, red touched,
%% the distance to the nearest wall, the winner, the motors and the events.
-spec observation(torobot_world:world(), {{number(), number()}, atom()}, [iodata()],
                  torobot_props:observation() | none) -> torobot_props:observation().
observation(W, {Wheels, Winner}, Lines, Last) ->
    #{wall_contacts := Wall, blue_contacts := Blue, red_touched_ms := Red} = Summary =
        torobot_world:summary(W),
    {Wall0, Blue0} = case Last of
                         #{walls := W0, blues := B0} -> {W0, B0};
                         none -> {0, 0}
                     end,
    #{t => torobot_world:time_ms(W), wall => Wall > Wall0, blue => Blue > Blue0,
      red => Red =/= none, dist => distance_to_wall(W), winner => Winner,
      motors => Wheels, events => events(Lines), walls => Wall, blues => Blue,
      figures => Summary}.

%% The events of a tick's trace lines that conditions name (a line of a
%% robot over several nodes names its node second: read without it).
-spec events([iodata()]) -> [tuple()].
events(Lines) ->
    lists:filtermap(fun(Line) ->
                            Tokens = binary:split(iolist_to_binary(Line), [<<" ">>, <<"\n">>],
                                                  [global, trim_all]),
                            case unnode(Tokens) of
                                [_, <<"cut">>, N, _] -> {true, {cut, binary_to_atom(N)}};
                                [_, <<"kill">>, N] -> {true, {cut, binary_to_atom(N)}};
                                [_, <<"heal">>, N] -> {true, {healed, binary_to_atom(N)}};
                                [_, Name, <<"restarted">>] ->
                                    {true, {restarted, binary_to_atom(Name)}};
                                [_, <<"layer">>, L, <<"out">>] ->
                                    {true, {layer_out, binary_to_integer(L)}};
                                [_, _, <<"emit">>, Src | _] ->
                                    case binary:split(Src, <<".">>) of
                                        [E, Out] -> {true, {emitted, {binary_to_atom(E),
                                                                      binary_to_atom(Out)}}};
                                        _ -> false
                                    end;
                                _ -> false
                            end
                    end, Lines).

unnode([T, Node | Rest] = Tokens) ->
    case binary:match(Node, <<"@">>) of
        nomatch -> Tokens;
        _ -> [T | Rest]
    end;
unnode(Tokens) ->
    Tokens.

%% From the robot's rim to the nearest wall or arena edge, in metres.
-spec distance_to_wall(torobot_world:world()) -> float().
distance_to_wall(W) ->
    {X, Y, _} = torobot_world:pose(W),
    {Aw, Ah} = torobot_world:arena(W),
    Edges = [{{0.0, 0.0}, {Aw, 0.0}}, {{Aw, 0.0}, {Aw, Ah}}, {{Aw, Ah}, {0.0, Ah}},
             {{0.0, Ah}, {0.0, 0.0}}],
    lists:min([segment_distance({X, Y}, Seg) || Seg <- Edges ++ torobot_world:walls(W)])
        - torobot_world:robot_radius(W).

segment_distance({Px, Py}, {{Ax, Ay}, {Bx, By}}) ->
    {Dx, Dy} = {Bx - Ax, By - Ay},
    L2 = Dx * Dx + Dy * Dy,
    U = case L2 == 0 of
            true -> 0.0;
            false -> max(0.0, min(1.0, ((Px - Ax) * Dx + (Py - Ay) * Dy) / L2))
        end,
    math:sqrt(math:pow(Px - (Ax + U * Dx), 2) + math:pow(Py - (Ay + U * Dy), 2)).
