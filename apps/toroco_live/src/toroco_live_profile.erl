%% @doc A recording profile (API, a behaviour): how another application's
%% typed topics are written to an MCAP file by `toroco_live:record/2'
%% (`profile => Name') and read back by `toroco_live:replay/2'.
%%
%% The profile `foxglove' (the default) is `toroco_live''s own: the
%% Foxglove bridge's JSON channels. Any other is a module of this
%% behaviour added with `toroco_live_extensions:add(profile, Name,
%% Module)' (`toroco_ros' adds `ros2', SPEC §15). A recording in such a
%% profile (`toroco_live_recorder') writes:
%% <ul>
%% <li>the MCAP header's profile, {@link mcap_profile/0};</li>
%% <li>an emission as the messages {@link of_event/1} makes of it, each on
%%   its topic with its type's schema ({@link schema/1}) and its bytes
%%   ({@link encode/2});</li>
%% <li>every other event (deliveries, routers, lifecycle) as its SPEC §12
%%   JSON on its §12 topic, in a message of type `text_type()' made by
%%   `text(Json)';</li>
%% <li>a world snapshot as the messages {@link of_world/2} makes of it.</li>
%% </ul>
%% Replay reads back the JSON of a channel of type `text_type()' with
%% `text_json(Bytes)'.
-module(toroco_live_profile).

-export([find/1]).

-export_type([message/0]).

%% A message on a topic: topic, type name, the message as a map.
-type message() :: {Topic :: binary(), Type :: binary(), Msg :: map()}.

%% The MCAP header's profile (`<<"ros2">>').
-callback mcap_profile() -> binary().
%% The messages an emission event (SPEC §10) makes.
-callback of_event(Event :: tuple()) -> [message()].
%% The messages a world snapshot at `T' (ns) makes.
-callback of_world(Snapshot :: map() | none, T :: integer()) -> [message()].
%% A message's bytes in its type's encoding; an error names what did not fit.
-callback encode(Type :: binary(), Msg :: map()) -> {ok, binary()} | {error, term()}.
%% A type's schema: `{SchemaEncoding, Schema, MessageEncoding}'.
-callback schema(Type :: binary()) -> {ok, {binary(), binary(), binary()}} | {error, term()}.
%% The type that carries an event's JSON (`std_msgs/msg/String').
-callback text_type() -> binary().
%% The message of that type carrying `Json'.
-callback text(Json :: binary()) -> map().
%% The JSON an encoded message of that type carries.
-callback text_json(Bytes :: binary()) -> {ok, binary()} | error.

%% @doc The module of profile `Name', `error' for one nobody added.
-spec find(atom()) -> {ok, module()} | error.
find(Name) ->
    toroco_live_extensions:find(profile, Name).
