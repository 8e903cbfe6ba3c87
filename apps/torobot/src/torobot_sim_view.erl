%% @doc What a simulated run shows while it runs, made from its robots'
%% worlds: the snapshot a world publishes for whoever draws it
%% (`toroco:publish_world/1', SPEC §14; its keys in `toroco_live_world''s
%% module doc) and the status line of each world second (`torobot_sim''s
%% option `status'); and at its end the summary as the run command prints
%% it.
%%
%% Functions: `snapshot/4', `status_line/3', `summary_json/1'.
-module(torobot_sim_view).

-export([snapshot/4, status_line/3, summary_json/1]).

%% @doc The snapshot of a run (`Run' names it: a new one starts new
%% trajectories) at this tick: the arena of the first robot's world, and
%% each robot with the behavior winning its motors. A robot of the
%% one-robot form is named `torobot'.
-spec snapshot(term(), boolean(), [map()], [{torobot_world:world(), atom()}]) ->
          toroco:world_snapshot().
snapshot(Run, Lockstep, Marks, [{W, _} | _] = Bots) ->
    Robots = [begin
                  #{ir := Ir, camera := Camera} = torobot_world:view(R),
                  #{name => case torobot_world:name(R) of
                                undefined -> torobot;
                                Name -> Name
                            end,
                    pose => torobot_world:pose(R),
                    radius => torobot_world:robot_radius(R), winner => Winner,
                    ir => Ir, camera => Camera}
              end || {R, Winner} <- Bots],
    #{run => Run,
      t_ms => lists:max([torobot_world:time_ms(R) || {R, _} <- Bots]),
      lockstep => Lockstep,
      timeline => #{duration_ms => torobot_world:duration_ms(W), marks => Marks},
      arena => torobot_world:arena(W), walls => torobot_world:walls(W),
      objects => torobot_world:objects(W), robots => Robots}.

%% @doc One robot's status line, printed (`true': a line each; `tty': one
%% line rewritten in place) or handed to the caller's fun.
-spec status_line(true | tty | fun((iodata()) -> any()), torobot_world:world(), atom()) -> any().
status_line(How, W, Winner) ->
    {X, Y, H} = torobot_world:pose(W),
    Name = case torobot_world:name(W) of
               undefined -> "";
               N -> io_lib:format("~s  ", [N])
           end,
    Line = io_lib:format("~st ~5.1f s  ~-13s x ~4.2f  y ~4.2f  heading ~4b",
                         [Name, torobot_world:time_ms(W) / 1000, Winner, X, Y, round(H)]),
    case How of
        true -> io:put_chars([Line, "\n"]);
        tty -> io:put_chars(["\r", Line]);
        Fun when is_function(Fun, 1) -> Fun(Line)
    end.

%% @doc The summary as one JSON object (`torobot_sim:summary_json/1').
-spec summary_json(torobot_sim:summary()) -> binary().
summary_json(Summary) ->
    iolist_to_binary(jiffy:encode(summary_value(Summary))).

-define(TOROBOT_KEYS, [red_touched_ms, wall_contacts, blue_contacts, distance_m]).

%% The summary for `jiffy', its keys in order; floats with three decimals.
-spec summary_value(torobot_sim:summary()) -> jiffy:json_value().
summary_value(#{red_touched_ms := _, wall_contacts := _, blue_contacts := _,
                distance_m := Distance} = Summary) ->
    {[{K, figure_value(maps:get(K, Summary))} || K <- ?TOROBOT_KEYS, K =/= distance_m]
     ++ [{distance_m, figure_value(float(Distance))}
         | [{K, figure_value(V)}
            || {K, V} <- lists:sort(maps:to_list(maps:without(?TOROBOT_KEYS, Summary)))]]};
summary_value(PerRobot) when is_map(PerRobot) ->
    {[{Name, summary_value(S)} || {Name, S} <- lists:sort(maps:to_list(PerRobot))]}.

-spec figure_value(term()) -> jiffy:json_value().
figure_value(none) -> null;
figure_value(V) when is_integer(V) -> V;
figure_value(V) when is_float(V) -> binary_to_float(float_to_binary(V, [{decimals, 3}]));
figure_value(V) -> iolist_to_binary(io_lib:format("~0p", [V])).
