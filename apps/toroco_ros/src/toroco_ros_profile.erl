%% @doc The recording profile `ros2' (a `toroco_rec_profile', SPEC §15):
%% `toroco_live:record(Path, #{profile => ros2})' writes the header's
%% profile `ros2', one channel per ROS topic (`toroco_ros_topics:of_event/1'
%% and, for the simulated world's `/odom', `toroco_ros_topics:of_world/2'),
%% each with its type's `ros2msg' schema and `cdr' messages
%% (`toroco_ros_msgs'); the other events go on their SPEC §12 topics as
%% `std_msgs/msg/String' carrying their JSON, which replay reads back.
-module(toroco_ros_profile).
-behaviour(toroco_rec_profile).

-export([mcap_profile/0, of_event/1, of_world/2, encode/2, schema/1]).
-export([text_type/0, text/1, text_json/1]).

-spec mcap_profile() -> binary().
mcap_profile() -> <<"ros2">>.

-spec of_event(tuple()) -> [toroco_rec_profile:message()].
of_event(Event) -> toroco_ros_topics:of_event(Event).

-spec of_world(map() | none, integer()) -> [toroco_rec_profile:message()].
of_world(Snapshot, T) -> toroco_ros_topics:of_world(Snapshot, T).

-spec encode(binary(), map()) -> {ok, binary()} | {error, term()}.
encode(Type, Msg) -> toroco_ros_msgs:cdr(Type, Msg).

-spec schema(binary()) -> {ok, {binary(), binary(), binary()}} | {error, term()}.
schema(Type) ->
    case toroco_ros_msgs:definition(Type) of
        {ok, Definition} -> {ok, {<<"ros2msg">>, Definition, <<"cdr">>}};
        {error, _} = E -> E
    end.

-spec text_type() -> binary().
text_type() -> <<"std_msgs/msg/String">>.

-spec text(binary()) -> map().
text(Json) -> #{data => Json}.

-spec text_json(binary()) -> {ok, binary()} | error.
text_json(Bytes) -> toroco_ros_msgs:string_data(Bytes).
