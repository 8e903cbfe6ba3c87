%% @doc Supervisor of `toroco_hw''s own services (the PRU port owner, when
%% configured). Devices themselves live under the runtime's
%% `toroco_devices_sup', like every node of the network.
%%
%% The owner is started when the app env `pru_port' is a map of
%% `toroco_pru_port' options; it is registered as `toroco_pru_port' unless
%% the map names it otherwise, and the PRU devices of the `devices' list
%% share it with `port => toroco_pru_port'.
-module(toroco_hw_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    Children = case application:get_env(toroco_hw, pru_port) of
                   {ok, Opts} when is_map(Opts) ->
                       [#{id => toroco_pru_port,
                          start => {toroco_pru_port, start_link,
                                    [maps:merge(#{name => toroco_pru_port}, Opts)]},
                          shutdown => 5000}];
                   _ ->
                       []
               end,
    {ok, {#{strategy => one_for_one, intensity => 10, period => 10}, Children}}.
