%% @doc The arena frame the page draws: a `toroco_live_world' snapshot
%% (walls, objects, robots with IR rays and camera, trajectories) as JSON
%% through `toroco_rec_json', points as `[X, Y]' arrays.
-module(toroco_live_world_json).

-export([frame/1]).

%% @doc `{"type": "world", ...}' for a snapshot with its trajectories.
-spec frame(toroco_live_world:snapshot()) -> jiffy:json_value().
frame(Snap = #{arena := {W, H}, walls := Walls, objects := Objects, robots := Robots}) ->
    Trajectories = maps:get(trajectories, Snap, #{}),
    #{<<"type">> => <<"world">>,
      <<"t_ms">> => maps:get(t_ms, Snap, 0),
      <<"arena">> => [W, H],
      <<"walls">> => [[pt(A), pt(B)] || {A, B} <- Walls],
      <<"objects">> => [#{<<"color">> => toroco_rec_json:value(C), <<"at">> => pt(P),
                          <<"r">> => R} || {C, P, R} <- Objects],
      <<"robots">> => [robot(Rb, Trajectories) || Rb <- Robots],
      <<"timeline">> => timeline(maps:get(timeline, Snap, none))}.

%% The run's length and what to mark on it (a fault, a violation), if the
%% simulator says.
timeline(#{duration_ms := D, marks := Marks}) ->
    #{<<"duration_ms">> => D,
      <<"marks">> => [#{<<"t_ms">> => T, <<"kind">> => toroco_rec_json:value(K),
                        <<"text">> => toroco_rec_json:value(Text)}
                      || #{t_ms := T, kind := K, text := Text} <- Marks]};
timeline(_) ->
    null.

robot(Rb = #{name := Name, pose := {X, Y, Heading}}, Trajectories) ->
    #{<<"name">> => toroco_rec_json:value(Name),
      <<"pose">> => [X, Y, Heading],
      <<"radius">> => maps:get(radius, Rb, 0.12),
      <<"winner">> => toroco_rec_json:value(maps:get(winner, Rb, none)),
      <<"ir">> => [#{<<"side">> => toroco_rec_json:value(maps:get(side, Ray, unknown)),
                     <<"from">> => pt(maps:get(from, Ray)), <<"to">> => pt(maps:get(to, Ray)),
                     <<"adc">> => maps:get(adc, Ray, null)}
                   || Ray <- maps:get(ir, Rb, [])],
      <<"camera">> => toroco_rec_json:value(maps:get(camera, Rb, #{})),
      <<"trajectory">> => [[Px, Py, toroco_rec_json:value(Tag)]
                           || {Px, Py, Tag} <- maps:get(Name, Trajectories, [])]}.

pt({X, Y}) -> [X, Y].
