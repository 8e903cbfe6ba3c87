%% What the suites of toroco_live and of the applications built on it
%% (toroco_ros) share: toroco_live started with
%% nothing on the default ports and the given app env, the env given back
%% as it was afterwards, and the fake sensor `s' wired to the fake
%% actuator `a'.
-module(tl_live).
-export([start/1, start/2, stop/1, fake_robot/0, replays_on_fakes/2, wiring_file/0, data/1,
         settle_robot/0]).

-define(KEYS, [enabled, log_dir, client_publish]).

%% Starts the applications with `Env' on top of `enabled => false'; returns
%% what to give stop/1.
start(Env) ->
    start(Env, []).

%% ... and `Apps', those built on toroco_live (toroco_ros).
start(Env, Apps) ->
    Saved = start_live(Env),
    [{ok, _} = application:ensure_all_started(A) || A <- Apps],
    Saved.

start_live(Env) ->
    ok = toroco_live_js:ensure_installed(),
    _ = application:load(toroco_live),
    Saved = [{K, application:get_env(toroco_live, K)} || K <- ?KEYS],
    [ok = application:set_env(toroco_live, K, V) || {K, V} <- maps:to_list(Env#{enabled => false})],
    {ok, _} = application:ensure_all_started(toroco_hw),
    {ok, _} = application:ensure_all_started(toroco_live),
    Saved.

%% Stops toroco_live and toroco_rec (the flight recorder with it) and puts
%% the app env back, for the suites after.
stop(Saved) ->
    application:stop(toroco_ros),
    application:stop(toroco_live),
    application:stop(toroco_rec),
    [toroco_test_lib:restore_env(toroco_live, K, V) || {K, V} <- Saved],
    ok.

fake_robot() ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [dist]}),
    ok = toroco:add_device(a, toroco_fake_actuator, #{inputs => [d]}),
    ok = toroco:set_inputs(a, #{d => [{s, dist}]}).

%% The wiring of a recorded run, with fake sensors and motors standing for
%% the devices, replays the recording's sensors to the same motors.
replays_on_fakes(Path, WiringFile) ->
    ok = toroco_test_lib:clear(),
    ok = toroco:add_device(ir, toroco_fake_sensor, #{outputs => [left, right]}),
    ok = toroco:add_device(camera, toroco_fake_sensor, #{outputs => [update_red, update_trq]}),
    ok = toroco:add_device(push, toroco_fake_sensor, #{outputs => [button]}),
    ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [setvel, enable]}),
    ok = toroco:load_wiring(WiringFile),
    {ok, #{replayed := Replayed, matched := Matched, differed := Differed}} =
        toroco_live:replay(Path, #{sources => [ir, camera, push]}),
    ct:log("replayed ~b, matched ~b, differed ~p", [Replayed, Matched, Differed]),
    true = Replayed > 0,
    true = Matched > 0,
    [] = Differed,
    ok.

wiring_file() ->
    Wiring = filename:join(code:lib_dir(torobot), "../../../../config/torobot.wiring"),
    case filelib:is_file(Wiring) of
        true -> Wiring;
        false -> filename:join(toroco_test_lib:root(), "config/torobot.wiring")
    end.

%% A file of this directory (apps/toroco_live/test), for the suites of the
%% applications built on toroco_live.
data(Name) ->
    Src = proplists:get_value(source, ?MODULE:module_info(compile)),
    filename:join(filename:dirname(Src), Name).

%% A recording takes in what was emitted before it stops: what a run's last
%% readings cause is let happen first. Each process of the path answers an
%% inspection once it has handled what came before, as many rounds as the
%% path (sensor, behavior, motors) is deep.
settle_robot() ->
    #{behaviors := Behaviors, devices := Devices} = toroco:inspect(),
    _ = [toroco:inspect(N) || _ <- lists:seq(1, 3), N <- Behaviors ++ Devices],
    ok.
