%% @doc The dashboard: one hub and one HTTP listener, a child of
%% `toroco_live_sup' with a process while the dashboard runs.
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

-export([start_link/0, init/1]).

%% @doc The dashboard with the configuration `toroco_live:start/1' set;
%% `ignore' (no process) when none is set.
-spec start_link() -> {ok, pid()} | ignore | {error, term()}.
start_link() ->
    case toroco_live_config:current() of
        undefined -> ignore;
        %% No secret in a start argument (nor in a crash report): the
        %% handlers read them from toroco_live_config.
        Config -> supervisor:start_link({local, ?MODULE}, ?MODULE,
                                        maps:without([token, session_key], Config))
    end.

-spec init(map()) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init(Config) ->
    Flags = #{strategy => rest_for_one, intensity => 5, period => 10},
    {ok, {Flags, [#{id => toroco_live_auth, start => {toroco_live_auth, start_link, []}},
                  #{id => toroco_live_hub, start => {toroco_live_hub, start_link, [Config]}},
                  #{id => toroco_live_http, start => {toroco_live_http, start_link, [Config]}}]}}.
