%% @doc The root of `toroco_live'.
%%
%% ```
%% toroco_live_sup (one_for_one)
%%   toroco_live_world            the simulated world's latest snapshot (always there)
%%   toroco_live_dashboard_sup    the dashboard, while it runs (toroco_live:start/1)
%%   toroco_live_foxglove         the Foxglove bridge, while the dashboard runs and
%%                                its option `foxglove' is a port
%% '''
%%
%% The tree is the same whatever the configuration: the dashboard's and the
%% bridge's children have no process while the configuration
%% (`toroco_live_config', set by `toroco_live:start/1') does not ask for
%% them, and `toroco_live:start/1' and `stop/0' restart and terminate them
%% (`toroco_live_bridge'). Other applications' bridges (the rosbridge
%% server, `toroco_ros') are children of their own supervisors, and so is
%% the flight recorder (`toroco_rec_sup', started before this application).
%%
%% one_for_one: the dashboard and the bridge are independent views of the
%% robot; one crashing takes none of the others with it.
-module(toroco_live_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    Flags = #{strategy => one_for_one, intensity => 5, period => 10},
    World = #{id => toroco_live_world, start => {toroco_live_world, start_link, []}},
    Dashboard = #{id => toroco_live_dashboard_sup, start => {toroco_live_dashboard_sup, start_link, []},
                  type => supervisor},
    Foxglove = toroco_live_bridge:child_spec(foxglove, toroco_live_foxglove),
    {ok, {Flags, [World, Dashboard, Foxglove]}}.
