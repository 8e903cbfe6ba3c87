%% The simulated Torobot driven by a program written for the original
%% Torocó (SPEC §16): its devices under the original's names
%% (config/torobot_lua.wiring) and the Torobot program of
%% apps/toroco_lua/priv/examples/torobot, in lockstep.
-module(torobot_lua_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, suite/0, init_per_suite/1, end_per_suite/1]).
-export([original_program_reaches_red/1, original_names_reach_the_devices/1,
         line_follower_keeps_to_the_tape/1]).

suite() ->
    [{timetrap, {seconds, 120}}].

all() ->
    [original_program_reaches_red, original_names_reach_the_devices,
     line_follower_keeps_to_the_tape].

init_per_suite(Config) ->
    Root = toroco_test_lib:root(),
    [{world, filename:join([Root, "config", "worlds", "default.world"])},
     {wiring, filename:join([Root, "config", "torobot_lua.wiring"])},
     {main, filename:join([Root, "apps", "toroco_lua", "priv", "examples", "torobot", "main.lua"])}
     | Config].

end_per_suite(_Config) ->
    ok.

original_program_reaches_red(doc) ->
    ["The Torobot program in Lua (wander seeded from os.time(), avoid, mouse turns, red "
     "follower on servo_motors) reaches the red ball of the default world in lockstep, "
     "at the same simulated time and with the same trace (SHA-256) twice"];
original_program_reaches_red(Config) ->
    Runs = [run(Config, filename:join(?config(priv_dir, Config), "trace" ++ integer_to_list(K)))
            || K <- [1, 2]],
    [{S1, Sha1}, {S2, Sha2}] = Runs,
    ct:pal("summary ~p, trace sha256 ~s", [S1, binary:encode_hex(Sha1)]),
    ?assertEqual(S1, S2),
    ?assertEqual(Sha1, Sha2),
    ?assertMatch(#{red_touched_ms := 27920}, S1).

original_names_reach_the_devices(doc) ->
    ["servo_motors' setvel2mtr reaches the motors, the camera's red blob comes as "
     "camera.update's x, y (no values when none), mice carries true and false"];
original_names_reach_the_devices(Config) ->
    ok = toroco_test_lib:start(),
    try
        {ok, _} = application:ensure_all_started(toroco_lua),
        ok = toroco:add_device(camera, toroco_fake_sensor, #{outputs => [update_red, update_trq]}),
        ok = toroco:add_device(push, toroco_fake_sensor, #{outputs => [button]}),
        ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [setvel, enable]}),
        ok = toroco:load_wiring(?config(wiring, Config)),
        Main = filename:join(?config(priv_dir, Config), "names.lua"),
        ok = file:write_file(Main, names_program()),
        ok = file:write_file(filename:join(filename:dirname(Main), "names_behavior.lua"),
                             names_behavior()),
        ok = toroco:add_device(seen, toroco_fake_actuator, #{inputs => [blob, left]}),
        {ok, #{behaviors := [names]}} = toroco_lua:load_main(Main, #{}),
        ok = toroco:inject({camera, update_red}, {12, -3}),
        ok = toroco:inject({camera, update_red}, none),
        ok = toroco:inject({mice, leftbutton}, true),
        ok = toroco:inject({mice, leftbutton}, false),
        ok = toroco_fake_actuator:await(seen, fun(H) -> length(H) >= 4 end, 3000),
        %% in order per source (SPEC §4); the camera's path has one hop more
        %% (the camera.update alias), so the two sources may interleave
        Seen = [{I, V} || {I, V, _} <- toroco_fake_actuator:history(seen)],
        ?assertEqual(4, length(Seen)),
        ?assertEqual([{blob, {12, -3}}, {blob, {}}], [E || E = {blob, _} <- Seen]),
        ?assertEqual([{left, true}, {left, false}], [E || E = {left, _} <- Seen]),
        ok = toroco_fake_actuator:await(motors, fun(H) -> lists:keymember({30, -30}, 2, H) end,
                                        3000)
    after
        toroco_test_lib:stop(),
        application:stop(toroco_lua)
    end.

%% A program naming the devices as the original's configuration did.
names_program() ->
    <<"local toroco = require 'toroco.toroco'\n"
      "local device = require 'toroco.device'\n"
      "local behavior = require 'toroco.behavior'\n"
      "toroco.load_behavior(behavior.names, 'names_behavior')\n"
      "toroco.set_inputs(behavior.names, {update = device.camera.update,\n"
      "                                   left = device.mice.leftbutton})\n"
      "toroco.set_inputs(device.servo_motors, {setvel2mtr = behavior.names.motors})\n"
      "toroco.set_inputs(device.seen, {blob = behavior.names.blob, left = behavior.names.left})\n"
      "toroco.run()\n">>.

names_behavior() ->
    <<"local toroco = require 'toroco'\n"
      "local input = toroco.input\n"
      "return function() toroco.set_output {motors = {30, -30}} end,\n"
      "  toroco.trigger(input.update, function(e, ...) toroco.send_output {blob = {...}} end),\n"
      "  toroco.trigger(input.left, function(e, v) toroco.send_output {left = {v}} end)\n">>.

line_follower_keeps_to_the_tape(doc) ->
    ["A line follower written for the original (configure_polling of trc_grey_left and "
     "trc_grey_right with a converter, trc_motor) follows the tape of the line world in "
     "lockstep: more than 3 m along it, never more than 5 cm from it, the same trace twice"];
line_follower_keeps_to_the_tape(Config) ->
    Root = toroco_test_lib:root(),
    World = filename:join([Root, "config", "worlds", "line.world"]),
    Main = filename:join([Root, "apps", "toroco_lua", "priv", "examples", "line_follower",
                          "main.lua"]),
    Run = fun(K) ->
                  Trace = filename:join(?config(priv_dir, Config), "line" ++ integer_to_list(K)),
                  {ok, W} = torobot_sim:simulate(World, #{lua => Main, time => lockstep,
                                                          wiring => ?config(wiring, Config),
                                                          trace => Trace}),
                  {ok, Bin} = file:read_file(Trace),
                  {W, crypto:hash(sha256, Bin)}
          end,
    [{W, Sha}, {_, Sha2}] = [Run(K) || K <- [1, 2]],
    ?assertEqual(Sha, Sha2),
    #{distance_m := D, wall_contacts := 0} = torobot_world:summary(W),
    ?assert(D > 3.0),
    [Tape] = torobot_sensors:floor_lines(W),
    Off = lists:max([lists:min([torobot_geometry:distance({X, Y}, torobot_geometry:closest({X, Y}, A, B))
                                || {A, B} <- lists:zip(lists:droplast(Tape), tl(Tape))])
                     || {_, X, Y, _} <- torobot_world:trajectory(W)]),
    ct:pal("distance ~.2f m, at most ~.3f m off the tape", [D, Off]),
    ?assert(Off < 0.05).

run(Config, Trace) ->
    {ok, Summary} = torobot_sim:run(?config(world, Config),
                                    #{lua => ?config(main, Config),
                                      wiring => ?config(wiring, Config),
                                      time => lockstep, trace => Trace}),
    {ok, Bin} = file:read_file(Trace),
    {Summary, crypto:hash(sha256, Bin)}.
