%% @doc A recording profile (API, a behaviour): how another application's
%% typed topics are written to an MCAP file by `toroco_rec:record/2'
%% (`profile => Name') and read back by `toroco_rec:replay/2'.
%%
%% The profile `foxglove' (the default) is `toroco_rec''s own: the
%% Foxglove bridge's JSON channels. Any other is a module of this
%% behaviour added with `toroco_rec:add_profile(Name, Module)'
%% (`toroco_ros' adds `ros2', SPEC §15); the profiles are kept in
%% `persistent_term' (written when an application starts or stops, read
%% when a recording opens or a replay reads a file). A recording in such a
%% profile (`toroco_rec_recorder') writes:
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
-module(toroco_rec_profile).

-export([add/2, remove/1, find/1, all/0]).

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

-define(KEY, {?MODULE, profiles}).

%% @doc Adds (or replaces) profile `Name'.
-spec add(atom(), module()) -> ok.
add(Name, Module) when is_atom(Name), is_atom(Module) ->
    persistent_term:put(?KEY, maps:put(Name, Module, profiles())).

%% @doc Removes profile `Name'; `ok' also when there is none.
-spec remove(atom()) -> ok.
remove(Name) ->
    case profiles() of
        #{Name := _} = M -> persistent_term:put(?KEY, maps:remove(Name, M));
        #{} -> ok
    end.

%% @doc The module of profile `Name', `error' for one nobody added.
-spec find(atom()) -> {ok, module()} | error.
find(Name) ->
    maps:find(Name, profiles()).

%% @doc Every profile added, by name.
-spec all() -> [{atom(), module()}].
all() ->
    lists:sort(maps:to_list(profiles())).

profiles() ->
    persistent_term:get(?KEY, #{}).
