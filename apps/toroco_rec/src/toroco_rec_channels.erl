%% @doc (API) The channels of SPEC §12, shared by the Foxglove bridge, the
%% recorder, the flight recorder and replay: their topics, their JSON
%% Schemas, and the JSON message each event of the observer tap (SPEC §10)
%% becomes. Pure except {@link from_wiring/0}, which reads the running
%% wiring with `toroco:inspect/0,1'.
%%
%% | channel key          | topic                            | schema                    |
%% |----------------------|----------------------------------|---------------------------|
%% | `{out, E, O}'        | `/toroco/out/E/O'                | `toroco.Output'           |
%% | `{in, R, I}'         | `/toroco/in/R/I' (deliveries)    | `toroco.Delivery'         |
%% | `{router, R, I}'     | `/toroco/router/R/I'             | `toroco.Router'           |
%% | `lifecycle'          | `/toroco/lifecycle'              | `toroco.Lifecycle'        |
%% | `pose'               | `/toroco/sim/pose'               | `foxglove.FrameTransform' |
%% | `scene'              | `/toroco/sim/scene'              | `foxglove.SceneUpdate'    |
%%
%% Every message that carries a value has `"value"' and `"term"' from
%% `toroco_rec_json:carry/1'. The last two channels exist while a
%% simulated world runs; their messages come from {@link world/2}.
-module(toroco_rec_channels).

-export([topic/1, key/1, schema/1, of_event/1, event_key/1, from_wiring/0, graph/1, world/3,
         event_names/1, event_time/1]).

-export_type([key/0, wiring/0, scene_sent/0]).

%% The arena changes seldom; its scene is sent again at least this often.
-define(SCENE_EVERY_NS, 1000000000).

%% The last scene sent and when, for {@link world/3}.
-type scene_sent() :: none | {term(), integer()}.
-type key() :: {out | in | router, atom(), atom()} | lifecycle | pose | scene.
%% The channels a wiring has, and who emits to and receives from each output.
-type wiring() :: #{keys := [key()],
                    receivers := #{{atom(), atom()} => [atom()]}}.

%%====================================================================
%% Topics
%%====================================================================

-spec topic(key()) -> binary().
topic({Kind, A, B}) ->
    iolist_to_binary(["/toroco/", atom_to_binary(Kind), $/, atom_to_binary(A, utf8), $/,
                      atom_to_binary(B, utf8)]);
topic(lifecycle) -> <<"/toroco/lifecycle">>;
topic(pose) -> <<"/toroco/sim/pose">>;
topic(scene) -> <<"/toroco/sim/scene">>.

%% @doc The channel a topic names. Names are read as existing atoms only,
%% so a topic from outside cannot grow the atom table.
-spec key(binary()) -> {ok, key()} | error.
key(<<"/toroco/lifecycle">>) -> {ok, lifecycle};
key(<<"/toroco/sim/pose">>) -> {ok, pose};
key(<<"/toroco/sim/scene">>) -> {ok, scene};
key(Topic) when is_binary(Topic) ->
    case binary:split(Topic, <<"/">>, [global]) of
        [<<>>, <<"toroco">>, Kind, A, B] when Kind =:= <<"out">>; Kind =:= <<"in">>;
                                              Kind =:= <<"router">> ->
            try {ok, {binary_to_existing_atom(Kind), binary_to_existing_atom(A, utf8),
                      binary_to_existing_atom(B, utf8)}}
            catch error:badarg -> error
            end;
        _ -> error
    end;
key(_) -> error.

%%====================================================================
%% Schemas
%%====================================================================

%% @doc The schema name and its JSON Schema text.
-spec schema(key()) -> {binary(), binary()}.
schema({out, _, _}) ->
    {<<"toroco.Output">>,
     object(<<"An emission on an output">>,
            [{kind, #{type => string, enum => [send, set, unset]}} | carried()])};
schema({in, _, _}) ->
    {<<"toroco.Delivery">>, object(<<"What an input's receiver got">>, carried())};
schema({router, _, _}) ->
    Source = #{type => string, description => <<"emitter/output">>},
    {<<"toroco.Router">>,
     object(<<"An input's winner, holds and latches">>,
            [{winner, #{type => [string, null]}},
             {holds, #{type => array,
                       items => obj([{source, Source},
                                     {remaining_ms, #{type => [number, string]}}])}},
             {latches, #{type => array, items => obj([{source, Source} | carried()])}},
             {term, #{type => string}}])};
schema(lifecycle) ->
    {<<"toroco.Lifecycle">>,
     object(<<"A behavior or device started, stopped, restarted, ...">>,
            [{name, #{type => string}}, {event, #{type => string}},
             {layer, #{type => integer}}, {term, #{type => string}}])};
schema(pose) ->
    {<<"foxglove.FrameTransform">>,
     object(<<"The robot's pose in the arena">>,
            [{timestamp, stamp()}, {parent_frame_id, #{type => string}},
             {child_frame_id, #{type => string}}, {translation, vector3()},
             {rotation, quaternion()}])};
schema(scene) ->
    Pose = obj([{position, vector3()}, {orientation, quaternion()}]),
    Colour = obj([{r, num()}, {g, num()}, {b, num()}, {a, num()}]),
    Prim = fun(Extra) -> #{type => array, items => obj([{pose, Pose}, {color, Colour} | Extra])} end,
    Entity = obj([{timestamp, stamp()}, {frame_id, #{type => string}}, {id, #{type => string}},
                  {lifetime, stamp()}, {frame_locked, #{type => boolean}},
                  {cubes, Prim([{size, vector3()}])},
                  {cylinders, Prim([{size, vector3()}, {bottom_scale, num()}, {top_scale, num()}])},
                  {arrows, Prim([{shaft_length, num()}, {shaft_diameter, num()},
                                 {head_length, num()}, {head_diameter, num()}])}]),
    {<<"foxglove.SceneUpdate">>,
     object(<<"The arena: walls, objects and the robot">>,
            [{deletions, #{type => array, items => #{type => object}}},
             {entities, #{type => array, items => Entity}}])}.

carried() ->
    [{value, #{description => <<"the term as JSON (SPEC 11)">>}},
     {term, #{type => string, description => <<"the Erlang literal">>}}].

object(Title, Props) ->
    toroco_rec_json:encode((obj(Props))#{title => Title, '$schema' =>
                                              <<"https://json-schema.org/draft/2020-12/schema">>}).

obj(Props) -> #{type => object, properties => maps:from_list(Props)}.
num() -> #{type => number}.
stamp() -> obj([{sec, #{type => integer}}, {nsec, #{type => integer}}]).
vector3() -> obj([{x, num()}, {y, num()}, {z, num()}]).
quaternion() -> obj([{x, num()}, {y, num()}, {z, num()}, {w, num()}]).

%%====================================================================
%% Messages
%%====================================================================

%% @doc The channel, time (ns) and JSON text of one tap event; `none' for
%% events that are not messages (`{dropped, N}').
-spec of_event(tuple()) -> {key(), integer(), binary()} | none.
%% Emissions and deliveries are most of the traffic: their text is put
%% together directly, the same JSON a map of the fields would give.
of_event({emit, T, {E, O}, Kind, Value}) ->
    {{out, E, O}, T, iolist_to_binary([<<"{\"kind\":\"">>, atom_to_binary(Kind),
                                       <<"\",">>, carried(Value), $}])};
of_event({deliver, T, {R, I}, Value}) ->
    {{in, R, I}, T, iolist_to_binary([${, carried(Value), $}])};
of_event({router, T, {R, I}, State}) ->
    {{router, R, I}, T, json(router(State))};
of_event({lifecycle, T, Name, What}) ->
    Base = #{<<"name">> => Name, <<"term">> => toroco_rec_json:term_text(What)},
    Msg = case What of
              {layer_removed, L} -> Base#{<<"event">> => layer_removed, <<"layer">> => L};
              _ when is_atom(What) -> Base#{<<"event">> => What};
              _ -> Base#{<<"event">> => toroco_rec_json:term_text(What)}
          end,
    {lifecycle, T, json(Msg)};
of_event(_) ->
    none.

carried(Value) ->
    [<<"\"value\":">>, toroco_rec_json_text:encode(toroco_rec_json:value(Value)),
     <<",\"term\":">>, toroco_rec_json_text:encode(toroco_rec_json:term_text(Value))].

router(State) ->
    #{<<"winner">> => source(maps:get(winner, State, none)),
      <<"holds">> => [#{<<"source">> => source(S), <<"remaining_ms">> => R}
                      || {S, R} <- maps:get(holds, State, [])],
      <<"latches">> => [(toroco_rec_json:carry(V))#{<<"source">> => source(S)}
                        || {S, V} <- maps:get(latches, State, [])],
      <<"term">> => toroco_rec_json:term_text(State)}.

source(none) -> null;
source({E, O}) -> <<(atom_to_binary(E, utf8))/binary, $/, (atom_to_binary(O, utf8))/binary>>;
source(Other) -> toroco_rec_json:term_text(Other).

%% Maps here hold JSON values already (carried values among them), so they
%% are encoded as they are.
json(Map) -> iolist_to_binary(toroco_rec_json_text:encode(Map)).

%% @doc The channel of a tap event without making its message (cheap);
%% `none' for `{dropped, N}'.
-spec event_key(tuple()) -> key() | none.
event_key({emit, _, {E, O}, _, _}) -> {out, E, O};
event_key({deliver, _, {R, I}, _}) -> {in, R, I};
event_key({router, _, {R, I}, _}) -> {router, R, I};
event_key({lifecycle, _, _, _}) -> lifecycle;
event_key(_) -> none.

%% @doc The names an event is about (for `names' filters).
-spec event_names(tuple()) -> [atom()].
event_names({emit, _, {E, _}, _, _}) -> [E];
event_names({deliver, _, {R, _}, _}) -> [R];
event_names({router, _, {R, _}, _}) -> [R];
event_names({lifecycle, _, Name, _}) -> [Name];
event_names(_) -> [].

%% @doc The time (ns) of an event, `none' for `{dropped, N}'.
-spec event_time(tuple()) -> integer() | none.
event_time({_, T, _, _, _}) -> T;
event_time({_, T, _, _}) -> T;
event_time(_) -> none.

%%====================================================================
%% The running wiring
%%====================================================================

%% @doc The channels of the running wiring: an out channel per declared
%% output, an in and a router channel per wired input, the lifecycle
%% channel; and for each output, the receivers wired to it.
-spec from_wiring() -> wiring().
from_wiring() ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    Infos = [I || N <- Bs ++ Ds, #{} = I <- [catch toroco:inspect(N)]],
    Keys = lists:append(
             [[{out, N, O} || O <- lists:sort(maps:keys(Outs))] ++
              lists:append([[{in, N, I}, {router, N, I}]
                            || {I, #{sources := [_ | _]}} <- lists:sort(maps:to_list(Ins))])
              || #{name := N, inputs := Ins, outputs := Outs} <- Infos]),
    Receivers = lists:foldl(
                  fun(#{name := N, inputs := Ins}, Acc) ->
                          lists:foldl(fun(Src, A) -> maps:update_with(Src, fun(L) -> lists:usort([N | L]) end, [N], A) end,
                                      Acc, lists:append([S || #{sources := S} <- maps:values(Ins)]))
                  end, #{}, Infos),
    #{keys => [lifecycle | Keys], receivers => Receivers}.

%% @doc The connection graph of a wiring (Foxglove's `connectionGraph'):
%% each output's topic is published by its emitter and subscribed by the
%% receivers wired to it; each input's topics by its receiver.
-spec graph(wiring()) -> {Published :: [{binary(), [binary()]}], Subscribed :: [{binary(), [binary()]}]}.
graph(#{keys := Keys, receivers := Receivers}) ->
    Name = fun(A) -> atom_to_binary(A, utf8) end,
    Published = [{topic(K), [Name(E)]} || {out, E, _} = K <- Keys],
    Subscribed = [{topic(K), [Name(R) || R <- maps:get({E, O}, Receivers)]}
                  || {out, E, O} = K <- Keys, maps:is_key({E, O}, Receivers)]
        ++ [{topic(K), [Name(R)]} || {Kind, R, _} = K <- Keys, Kind =:= in],
    {Published, Subscribed}.

%%====================================================================
%% The simulated world
%%====================================================================

%% @doc The pose and scene messages of a world snapshot at `T' (ns), a
%% snapshot as `toroco_live_world' (`toroco_rec_world''s source) keeps it
%% (`arena', `walls', `objects', `robots' with each robot's `name' and
%% `pose' `{X, Y, HeadingDeg}';
%% metres and degrees; `none' before any): one `foxglove.FrameTransform'
%% per robot and step (frame `arena' to the robot's name), and a
%% `foxglove.SceneUpdate' (the walls as cubes, the objects as cylinders,
%% each robot as an arrow in its own frame, so it moves with its
%% transform) when the scene changed or `?SCENE_EVERY_NS' after the last,
%% for a viewer that comes late. `Last' is what the previous call returned
%% (`none' at first).
-spec world(map() | none, integer(), scene_sent()) -> {[{key(), integer(), binary()}], scene_sent()}.
world(none, _T, Last) ->
    {[], Last};
world(Snapshot, T, Last) ->
    Stamp = stamp(T),
    Robots = [{Name, Pose} || #{name := Name, pose := Pose} <- maps:get(robots, Snapshot, [])],
    Poses = [{pose, T, json(#{timestamp => Stamp, parent_frame_id => <<"arena">>,
                              child_frame_id => Name,
                              translation => #{x => X, y => Y, z => 0.0},
                              rotation => yaw(H)})}
             || {Name, {X, Y, H}} <- Robots],
    Scene = {maps:get(arena, Snapshot, none), maps:get(walls, Snapshot, []),
             maps:get(objects, Snapshot, []), [N || {N, _} <- Robots]},
    case Last of
        {Scene, Sent} when T - Sent < ?SCENE_EVERY_NS -> {Poses, Last};
        _ -> {Poses ++ [{scene, T, scene(Snapshot, Scene, Stamp)}], {Scene, T}}
    end.

scene(Snapshot, {_, Walls0, Objects0, Names}, Stamp) ->
    Walls = [wall(P1, P2) || {P1, P2} <- arena_walls(Snapshot) ++ Walls0],
    Objects = [cylinder(At, R, colour(C)) || {C, At, R} <- Objects0],
    Arena = (entity(Stamp, <<"arena">>, <<"arena">>, false))#{cubes => Walls, cylinders => Objects},
    Robots = [(entity(Stamp, Name, Name, true))#{
                arrows => [#{pose => #{position => #{x => 0.0, y => 0.0, z => 0.05},
                                       orientation => yaw(0)},
                             color => #{r => 0.2, g => 0.8, b => 0.2, a => 1.0},
                             shaft_length => 0.15, shaft_diameter => 0.04,
                             head_length => 0.06, head_diameter => 0.08}]}
              || Name <- Names],
    json(#{deletions => [], entities => [Arena | Robots]}).

%% Every field of foxglove.SceneEntity, so a viewer finds each list it looks for.
entity(Stamp, Frame, Id, Locked) ->
    #{timestamp => Stamp, frame_id => Frame, id => Id, lifetime => #{sec => 0, nsec => 0},
      frame_locked => Locked, metadata => [], arrows => [], cubes => [], spheres => [],
      cylinders => [], lines => [], triangles => [], texts => [], models => []}.

stamp(T) -> #{sec => T div 1000000000, nsec => T rem 1000000000}.

arena_walls(#{arena := {W, H}}) ->
    [{{0.0, 0.0}, {W, 0.0}}, {{W, 0.0}, {W, H}}, {{W, H}, {0.0, H}}, {{0.0, H}, {0.0, 0.0}}];
arena_walls(#{}) -> [].

wall({X1, Y1}, {X2, Y2}) ->
    Len = math:sqrt((X2 - X1) * (X2 - X1) + (Y2 - Y1) * (Y2 - Y1)),
    #{pose => #{position => #{x => (X1 + X2) / 2, y => (Y1 + Y2) / 2, z => 0.1},
                orientation => yaw(math:atan2(Y2 - Y1, X2 - X1) * 180 / math:pi())},
      size => #{x => Len, y => 0.02, z => 0.2},
      color => #{r => 0.5, g => 0.5, b => 0.5, a => 1.0}}.

cylinder({X, Y}, R, Colour) ->
    #{pose => #{position => #{x => X, y => Y, z => 0.1}, orientation => yaw(0)},
      size => #{x => 2 * R, y => 2 * R, z => 0.2}, bottom_scale => 1.0, top_scale => 1.0,
      color => Colour}.

colour(red) -> #{r => 0.9, g => 0.1, b => 0.1, a => 1.0};
colour(blue) -> #{r => 0.1, g => 0.2, b => 0.9, a => 1.0};
colour(_) -> #{r => 0.8, g => 0.8, b => 0.8, a => 1.0}.

yaw(Deg) ->
    Half = Deg * math:pi() / 360,
    #{x => 0.0, y => 0.0, z => math:sin(Half), w => math:cos(Half)}.
