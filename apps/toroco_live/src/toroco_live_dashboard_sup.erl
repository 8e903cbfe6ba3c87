%% @doc The dashboard: one hub and one HTTP listener.
%%
%% ```
%% toroco_live_dashboard_sup (rest_for_one)
%%   toroco_live_auth    the token checks of every port, failures per address
%%   toroco_live_hub     the tap's subscriber; builds and pushes the pages' state
%%   toroco_live_http    the port's guard (toroco_live_listener) over mochiweb's
%%                       listener; one process per connection, each bounded
%% '''
%%
%% rest_for_one: every WebSocket connection has joined the hub, so a hub
%% that restarts takes the listener (and its connections) with it and the
%% pages reconnect to the new one; a listener that restarts leaves the hub.
%% The token checks come first: everything after them asks them.
-module(toroco_live_dashboard_sup).
-behaviour(supervisor).

-export([start_link/1, init/1]).

-spec start_link(map()) -> {ok, pid()} | {error, term()}.
start_link(Config) ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, Config).

-spec init(map()) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init(Config) ->
    Flags = #{strategy => rest_for_one, intensity => 5, period => 10},
    {ok, {Flags, [#{id => toroco_live_auth, start => {toroco_live_auth, start_link, []}},
                  #{id => toroco_live_hub, start => {toroco_live_hub, start_link, [Config]}},
                  #{id => toroco_live_http, start => {toroco_live_http, start_link, [Config]}}]}}.
