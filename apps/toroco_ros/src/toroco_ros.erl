%% @doc The public API of `toroco_ros' (SPEC §15): the robot as ROS 2
%% topics through the rosbridge v2 protocol, an application built on
%% `toroco_live''s documented API.
%%
%% <b>The server.</b> The rosbridge v2 server (`toroco_ros_server') is a
%% bridge of `toroco_live' (`toroco_live_bridge'): it listens on the option
%% `rosbridge' of `toroco_live:start/1' (a port, 0 for any free one, or
%% `off', the default) while this application runs, and {@link port/0}
%% says where. `toroco_live:start(#{rosbridge => Port})' is how it is
%% asked for.
%%
%% <b>Client mode.</b> {@link connect/2} dials a rosbridge server and keeps
%% the robot's topics there (`toroco_ros_client', under
%% `toroco_ros_client_sup'), {@link disconnect/1} ends it, {@link
%% clients/0} says how each is doing. `toroco_live:rosbridge_connect/2',
%% `rosbridge_disconnect/1' and `rosbridge_clients/0' are the same calls
%% (SPEC §15 names them). The app env `rosbridge_connect' (a URL, `{Url,
%% Opts}', or a list of them; `toroco_live''s key of the same name is read
%% too) dials when the application starts.
%%
%% <b>Recording.</b> `toroco_live:record(Path, #{profile => ros2})' writes
%% the ROS 2 topics as CDR (`toroco_ros_profile').
%%
%% <b>The `ros' device</b> (`toroco_ros_device'): what clients publish on
%% the robot's inbound topics (`/cmd_vel') becomes a source of the wiring.
%%
%% App env: `ros_geometry' and `ros_range' (`toroco_ros_topics'),
%% `rosbridge_max_message' and `rosbridge_fragment_ms'
%% (`toroco_ros_server_conn'), `rosbridge_connect'.
-module(toroco_ros).

-export([port/0, connect/2, disconnect/1, clients/0]).

-export_type([connect_opts/0, client_info/0]).

-type connect_opts() :: toroco_ros_client:opts().
-type client_info() :: toroco_ros_client:info().

%% @doc The port the rosbridge server listens on, `off' when it does not run.
-spec port() -> inet:port_number() | off.
port() ->
    toroco_ros_server:port().

%% @doc Dials the rosbridge v2 server at `Url' (`ws://host:port/path' or
%% `wss://...' with `cacertfile' or a pinned `fingerprint' to check the
%% server's certificate; `?token=T' for a server that asks for one, never
%% shown), advertises the robot's topics there, publishes its messages,
%% subscribes to its inbound topics (`/cmd_vel') and reconnects with
%% backoff when the connection goes. `{ok, Pid}' at once, connected or not
%% (see {@link clients/0}); `{error, {bad_url, Url}}', `{error,
%% {unsupported_scheme, S}}', `{error, {unverified_wss, Why}}' or `{error,
%% {bad_option, {Key, Value}}}' (options: `max_queue', `backoff_min',
%% `backoff_max', `connect_timeout', `max_message', `cacertfile',
%% `fingerprint', see `toroco_ros_client'); `{error, not_started}' when
%% the application does not run. A server whose certificate does not match
%% is never sent a byte: `last_error' says `{tls, Why}'.
-spec connect(binary() | string(), connect_opts()) -> {ok, pid()} | {error, term()}.
connect(Url, Opts) ->
    case toroco_ros_client_opts:options(Url, Opts) of
        {ok, _, _} when is_map(Opts) ->
            try toroco_ros_client_sup:start_client(Url, Opts)
            catch exit:{noproc, _} -> {error, not_started}
            end;
        {error, _} = E -> E
    end.

%% @doc Ends a client: it closes its connection and is not dialled again.
-spec disconnect(pid()) -> ok | {error, not_found}.
disconnect(Pid) ->
    try toroco_ros_client_sup:stop_client(Pid)
    catch exit:{noproc, _} -> {error, not_found}
    end.

%% @doc Each client: its URL, `state' (`connected', `connecting' or
%% `waiting' to dial again), `attempts' since it was last connected,
%% `connects', messages `sent' and `received', `dropped' (the robot's
%% messages it could not send), `refused' (the server's messages that did
%% not fit their type or the `ros' device could not take), `refused_topics'
%% (the topics the server said it does not take, on this connection),
%% `last_error'.
-spec clients() -> [client_info()].
clients() ->
    [I || Pid <- toroco_ros_client_sup:clients(),
          I <- [try toroco_ros_client:info(Pid) catch exit:_ -> none end], I =/= none].
