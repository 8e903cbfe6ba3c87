%% @doc The `toroco_hw' application: the device modules, and the devices of
%% `config/sys.config' (app env `devices', a list of `{Name, Module, Opts}'),
%% added to the runtime at start.
-module(toroco_hw_app).
-behaviour(application).

-export([start/2, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    {ok, Sup} = toroco_hw_sup:start_link(),
    Devices = application:get_env(toroco_hw, devices, []),
    case add_devices(Devices) of
        ok -> {ok, Sup};
        {error, _} = Err -> Err
    end.

add_devices([]) -> ok;
add_devices([{Name, Module, Opts} | Rest]) ->
    case toroco:add_device(Name, Module, Opts) of
        ok -> add_devices(Rest);
        {error, Reason} ->
            logger:error("toroco_hw: device ~p (~p) not started: ~p", [Name, Module, Reason]),
            {error, {device, Name, Reason}}
    end;
add_devices([Bad | _]) ->
    {error, {bad_device_entry, Bad}}.

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
