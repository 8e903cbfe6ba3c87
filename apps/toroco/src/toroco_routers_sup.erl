%% @doc Supervises the routers (one per wired input) and the inhibition gates
%% (one per inhibited output or same-layer pair). Children are added and
%% removed by `toroco_wiring'; a crashed router or gate is restarted and
%% recovers its latches from its upstreams.
-module(toroco_routers_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), []}}.
init([]) ->
    %% one_for_one: wires are independent of each other. Routers are mechanical
    %% and cheap to restart, so the intensity is generous (app env
    %% `router_restart_intensity', {MaxRestarts, Seconds}).
    {R, P} = application:get_env(toroco, router_restart_intensity, {1000, 10}),
    {ok, {#{strategy => one_for_one, intensity => R, period => P}, []}}.
