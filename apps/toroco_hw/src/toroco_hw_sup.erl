%% @doc Supervisor of `toroco_hw''s own services (the PRU port owner, when
%% configured). Devices themselves live under the runtime's
%% `toroco_devices_sup', like every node of the network.
-module(toroco_hw_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), []}}.
init([]) ->
    {ok, {#{strategy => one_for_one, intensity => 10, period => 10}, []}}.
