%% @doc Supervises the devices (sensors and actuators, layer 0).
-module(toroco_devices_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), []}}.
init([]) ->
    %% one_for_one: a device failing says nothing about the others.
    {R, P} = application:get_env(toroco, device_restart_intensity, {20, 10}),
    {ok, {#{strategy => one_for_one, intensity => R, period => P}, []}}.
