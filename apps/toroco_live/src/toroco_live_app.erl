%% @doc The `toroco_live' application: what a person looks at. It depends on
%% the runtime (`toroco'); the runtime never depends on it, and it never
%% depends on the applications built on it (`toroco_ros' adds itself
%% through `toroco_live_extensions').
-module(toroco_live_app).
-behaviour(application).

-export([start/2, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    %% A configuration left by a node that lost the application without
    %% stopping it would start the dashboard before its options are read.
    ok = toroco_live_config:clear(),
    case toroco_live_sup:start_link() of
        {ok, Sup} ->
            Env = maps:from_list(application:get_all_env(toroco_live)),
            case maps:get(enabled, Env, true) of
                true -> start_dashboard(maps:with([ip, http, foxglove, rosbridge, token, max_clients,
                                                   max_body, request_timeout, idle_timeout,
                                                   max_connections, max_per_peer, min_age,
                                                   tls, insecure],
                                                  Env));
                false -> ok
            end,
            {ok, Sup};
        Error ->
            Error
    end.

%% The robot runs without its dashboard: a port already taken is logged,
%% and the application stays up (toroco_live:start/1 may be called again).
%% The log says where, never the token (toroco_live:url/0 is for a person).
start_dashboard(Opts) ->
    case toroco_live:start(Opts) of
        {ok, #{http := Port}} ->
            logger:notice("toroco_live: dashboard on port ~b~ts", [Port, case Opts of
                                                                     #{tls := _} -> " (TLS)";
                                                                     #{} -> ""
                                                                 end],
                          #{domain => [toroco, live]});
        {error, Reason} ->
            logger:error("toroco_live: the dashboard did not start: ~0p", [Reason],
                         #{domain => [toroco, live]})
    end.

-spec stop(term()) -> ok.
stop(_State) ->
    toroco_live_config:clear().
