%% What the Foxglove and recording suites share: toroco_live started with
%% nothing on the default ports and the given app env, the env given back
%% as it was afterwards, and the fake sensor `s' wired to the fake
%% actuator `a'.
-module(tl_live).
-export([start/1, stop/1, fake_robot/0]).

-define(KEYS, [enabled, log_dir, client_publish]).

%% Starts the applications with `Env' on top of `enabled => false'; returns
%% what to give stop/1.
start(Env) ->
    ok = toroco_live_js:ensure_installed(),
    _ = application:load(toroco_live),
    Saved = [{K, application:get_env(toroco_live, K)} || K <- ?KEYS],
    [ok = application:set_env(toroco_live, K, V) || {K, V} <- maps:to_list(Env#{enabled => false})],
    {ok, _} = application:ensure_all_started(toroco_hw),
    {ok, _} = application:ensure_all_started(toroco_live),
    Saved.

%% Stops toroco_live and puts the app env back, for the suites after.
stop(Saved) ->
    application:stop(toroco_live),
    [case V of
         {ok, Value} -> application:set_env(toroco_live, K, Value);
         undefined -> application:unset_env(toroco_live, K)
     end || {K, V} <- Saved],
    ok.

fake_robot() ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [dist]}),
    ok = toroco:add_device(a, toroco_fake_actuator, #{inputs => [d]}),
    ok = toroco:set_inputs(a, #{d => [{s, dist}]}).
