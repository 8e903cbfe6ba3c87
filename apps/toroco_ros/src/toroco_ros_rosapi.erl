%% @doc The services the rosbridge server answers (`call_service', SPEC
%% §15), as rosapi does, and the robot's own: pure but for reading the
%% server's topics and the runtime's inspection. None of them changes the
%% robot, so none needs the token.
%%
%% | service | args | values |
%% |---------|------|--------|
%% | `/rosapi/topics' | `{}' | `topics', `types' |
%% | `/rosapi/topics_and_raw_types' | `{}' | the same with `typedefs_full_text', each type's definition (`toroco_ros_topics:definition/1'), what Foxglove's Rosbridge connection reads for ROS 2 |
%% | `/rosapi/topic_type' | `{"topic": T}' | `type' (empty for an unknown topic) |
%% | `/rosapi/services' | `{}' | `services' |
%% | `/rosapi/get_ros_version' | `{}' | `version' 2, `distro' `jazzy' (the types' distribution) |
%% | `/toroco/inspect' | `{}' or `{"name": N}' | `toroco:inspect/0,1' as JSON |
-module(toroco_ros_rosapi).

-export([call/2, topic_type/1, slash/1]).

-define(SERVICES, [<<"/rosapi/topics">>, <<"/rosapi/topics_and_raw_types">>,
                   <<"/rosapi/topic_type">>, <<"/rosapi/services">>, <<"/rosapi/get_ros_version">>,
                   <<"/toroco/inspect">>]).

%% @doc Service `Service' (its name with the leading slash) called with
%% `Args': its values, or why not.
-spec call(binary(), term()) -> {ok, term()} | {error, iodata()}.
call(<<"/rosapi/topics">>, _) ->
    Topics = toroco_ros_server:topics(),
    {ok, #{topics => [T || #{topic := T} <- Topics], types => [Ty || #{type := Ty} <- Topics]}};
call(<<"/rosapi/topics_and_raw_types">>, _) ->
    Topics = toroco_ros_server:topics(),
    {ok, #{topics => [T || #{topic := T} <- Topics], types => [Ty || #{type := Ty} <- Topics],
           typedefs_full_text => [toroco_ros_topics:definition(Ty) || #{type := Ty} <- Topics]}};
call(<<"/rosapi/topic_type">>, #{<<"topic">> := T}) when is_binary(T) ->
    case topic_type(slash(T)) of
        {ok, Type} -> {ok, #{type => Type}};
        {error, _} -> {ok, #{type => <<>>}}
    end;
call(<<"/rosapi/topic_type">>, _) ->
    {error, <<"/rosapi/topic_type needs {\"topic\": T}">>};
call(<<"/rosapi/get_ros_version">>, _) ->
    %% The message types are Jazzy's (Range has `variance').
    {ok, #{version => 2, distro => <<"jazzy">>}};
call(<<"/rosapi/services">>, _) ->
    {ok, #{services => ?SERVICES}};
call(<<"/toroco/inspect">>, Args) when Args =:= #{}; Args =:= null; Args =:= [] ->
    {ok, toroco_rec_json:value(toroco:inspect())};
call(<<"/toroco/inspect">>, #{<<"name">> := N}) when is_binary(N) ->
    try binary_to_existing_atom(N) of
        Name ->
            case toroco:inspect(Name) of
                #{} = Info -> {ok, toroco_rec_json:value(Info)};
                {error, _} -> {error, [<<"/toroco/inspect: no behavior or device ">>, N]}
            end
    catch error:badarg -> {error, [<<"/toroco/inspect: no behavior or device ">>, N]}
    end;
call(<<"/toroco/inspect">>, _) ->
    {error, <<"/toroco/inspect takes {} or {\"name\": N}">>};
call(Service, _) ->
    {error, [<<"unknown service ">>, Service, <<" (call /rosapi/services)">>]}.

%% @doc The type of one of the server's topics (the robot's and those
%% relayed).
-spec topic_type(binary()) -> {ok, binary()} | {error, unknown_topic}.
topic_type(Topic) ->
    case [Ty || #{topic := T, type := Ty} <- toroco_ros_server:topics(), T =:= Topic] of
        [Type | _] -> {ok, Type};
        [] -> {error, unknown_topic}
    end.

%% @doc A topic or service name with its leading slash (roslib calls
%% `rosapi/topics').
-spec slash(binary()) -> binary().
slash(<<$/, _/binary>> = Name) -> Name;
slash(Name) -> <<$/, Name/binary>>.
