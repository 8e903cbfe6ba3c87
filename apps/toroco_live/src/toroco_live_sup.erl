%% @doc The root of `toroco_live'.
%%
%% ```
%% toroco_live_sup (one_for_one)
%%   toroco_live_world            the simulated world's latest snapshot (always there)
%%   toroco_live_flight           the flight recorder (always on) and the recording
%%   toroco_live_rosclient_sup    the rosbridge clients, one per server dialled
%%                                (toroco_live:rosbridge_connect/2)
%%   toroco_live_dashboard_sup    the dashboard, added by toroco_live:start/1
%%   toroco_live_foxglove         the Foxglove bridge, added by toroco_live:start/1
%%   toroco_live_rosbridge        the rosbridge v2 server, added by toroco_live:start/1
%% '''
%%
%% one_for_one: the dashboard, the bridges, the rosbridge clients and the
%% recorders are independent views of the robot; one crashing takes none
%% of the others with it.
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
    Flight = #{id => toroco_live_flight, start => {toroco_live_flight, start_link, []},
               shutdown => 30000},
    Clients = #{id => toroco_live_rosclient_sup, start => {toroco_live_rosclient_sup, start_link, []},
                type => supervisor},
    {ok, {Flags, [World, Flight, Clients]}}.
