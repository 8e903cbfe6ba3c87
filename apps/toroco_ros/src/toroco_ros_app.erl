%% @doc The `toroco_ros' application. It depends on `toroco_live' (and
%% through it on the runtime); neither depends on it. Started, it adds to
%% `toroco_live' (`toroco_live_extensions'): the rosbridge server as the
%% bridge of the option `rosbridge', the client mode and its `/metrics'
%% families; and to `toroco_rec' the recording profile `ros2'
%% (`toroco_rec:add_profile/2'); stopped, it takes them away.
-module(toroco_ros_app).
-behaviour(application).

-export([start/2, prep_stop/1, stop/1]).

-define(BRIDGE, #{supervisor => toroco_ros_sup, id => toroco_ros_server,
                  listener => toroco_ros_server_listener}).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    case toroco_ros_sup:start_link() of
        {ok, Sup} ->
            ok = toroco_rec:add_profile(ros2, toroco_ros_profile),
            ok = toroco_live_extensions:add(metrics, toroco_ros, {toroco_ros_metrics, families}),
            ok = toroco_live_extensions:add(client, rosbridge, toroco_ros),
            ok = toroco_live_extensions:add(bridge, rosbridge, ?BRIDGE),
            listen(),
            lists:foreach(fun dial/1, connects()),
            {ok, Sup};
        Error ->
            Error
    end.

%% The server listens from now on if the dashboard runs and asks for it.
%% A port already taken is logged; the application stays up
%% (`toroco_live:start/1' may be called again).
listen() ->
    case toroco_live_bridge:open(rosbridge) of
        {ok, off} -> ok;
        {ok, Port} ->
            logger:notice("toroco_ros: rosbridge server on port ~b", [Port],
                          #{domain => [toroco, ros]});
        {error, Reason} ->
            logger:error("toroco_ros: the rosbridge server did not start: ~0p", [Reason],
                         #{domain => [toroco, ros]})
    end.

%% Client mode from the app env (this application's, and toroco_live's key
%% of the same name): a URL, {Url, Opts}, or a list of them. A URL that
%% cannot be used is logged; the application stays up.
connects() ->
    lists:append([as_list(application:get_env(App, rosbridge_connect, []))
                   || App <- [toroco_ros, toroco_live]]).

as_list([]) -> [];
as_list(L) when is_list(L) ->
    case io_lib:printable_unicode_list(L) of
        true -> [L];
        false -> L
    end;
as_list(One) -> [One].

dial({Url, Opts}) ->
    case toroco_ros:connect(Url, Opts) of
        {ok, _} -> ok;
        {error, Reason} ->
            logger:error("toroco_ros: rosbridge_connect ~0p: ~0p", [Url, Reason],
                         #{domain => [toroco, ros]})
    end;
dial(Url) when is_list(Url); is_binary(Url) ->
    dial({Url, #{}});
dial(Other) ->
    logger:error("toroco_ros: rosbridge_connect ~0p: not a URL or {Url, Opts}", [Other],
                 #{domain => [toroco, ros]}).

%% Taken away before the tree stops: toroco_live no longer reaches in.
-spec prep_stop(term()) -> term().
prep_stop(State) ->
    _ = [toroco_live_extensions:remove(Kind, Name)
         || {Kind, Name} <- [{bridge, rosbridge}, {client, rosbridge}, {metrics, toroco_ros}]],
    ok = toroco_rec:remove_profile(ros2),
    State.

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
