%% The devices of toroco_hw in the running network: PRU sensors, servos and
%% button through the pru_port program's sim backend (servo PWM on a fake
%% sysfs tree in the case's private directory), the camera over real UDP,
%% the function adapters, and refused options.
-module(toroco_devices_SUITE).
-import(toroco_test_lib, [wait_until/2]).
-import(toroco_hw_test_lib, [fake_pwm/3, pwm/3]).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, groups/0, suite/0, init_per_suite/1, end_per_suite/1,
         init_per_testcase/2, end_per_testcase/2]).
-export([threshold_crossings/1, raw_analog_changes/1, sim_adc_errors/1,
         shared_port_lost_and_back/1,
         servo_duty/1, clamping_and_bad_values/1, enable_disable/1,
         neutral_on_port_death/1, latched_command_back_after_port_restart/1, neutral_on_watchdog/1, keepalive_and_stall/1,
         neutral_on_remove/1, servo_device_while_port_connecting/1,
         button_edges/1,
         camera_datagrams/1, camera_allow_list/1,
         poll_on_change/1, poll_crashes/1, poll_period_changed/1, fun_actuator_calls/1,
         bad_options/1, missing_device_files/1,
         unknown_requests/1]).

-define(NEUTRAL, "1500000").
-define(WAIT, 5000).

suite() ->
    [{timetrap, {seconds, 60}}].

all() ->
    [{group, pru_sensors}, {group, servo_motors}, {group, button}, {group, camera},
     {group, adapters}, {group, options}, {group, engine_defaults}].

groups() ->
    [{pru_sensors, [], [threshold_crossings, raw_analog_changes, sim_adc_errors,
                        shared_port_lost_and_back]},
     {servo_motors, [], [servo_duty, clamping_and_bad_values, enable_disable,
                         neutral_on_port_death, latched_command_back_after_port_restart, neutral_on_watchdog, keepalive_and_stall,
                         neutral_on_remove, servo_device_while_port_connecting]},
     {button, [], [button_edges]},
     {camera, [], [camera_datagrams, camera_allow_list]},
     {adapters, [], [poll_on_change, poll_crashes, poll_period_changed, fun_actuator_calls]},
     {options, [], [bad_options, missing_device_files]},
     {engine_defaults, [], [unknown_requests]}].

init_per_suite(Config) ->
    toroco_hw_test_lib:require_pru_port(Config).

end_per_suite(_Config) ->
    ok.

init_per_testcase(Case, Config) ->
    ok = toroco_test_lib:start(),
    Root = filename:join(?config(priv_dir, Config), atom_to_list(Case)),
    fake_pwm(Root, 0, 0),
    fake_pwm(Root, 0, 1),
    [{root, Root} | Config].

end_per_testcase(_Case, _Config) ->
    _ = [toroco_pru_port:stop(P) || P <- [whereis(shared_pru)], is_pid(P)],
    toroco_test_lib:stop().

%%% ---------------------------------------------------------------------
%%% PRU sensors
%%% ---------------------------------------------------------------------

threshold_crossings(doc) ->
    ["analog_threshold sensors emit once per crossing, nothing for noise inside the band"];
threshold_crossings(_Config) ->
    ok = toroco:add_device(ir, toroco_pru_sensors, #{sensors => ir_sensors()}),
    rec([left, right]),
    ok = toroco:set_inputs(rec, #{left => [{ir, ir_left}], right => [{ir, ir_right}]}),
    %% first sample: 0; noise; near; noise around high; far; noise; near
    Samples = [1000, 1400, 1600, 1999, 1501, 1700, 2000, 1990, 2100, 1501, 1999, 4095,
               1500, 1510, 1999, 1600, 0, 1200, 2500],
    [ok = toroco_pru_sensors:sim_adc(ir, ir_left, V) || V <- Samples],
    [ok = toroco_pru_sensors:sim_adc(ir, ir_right, V) || V <- [3000, 2999, 100]],
    %% each sensor's events arrive in order: an extra one would break equality
    await_input(rec, left, [0, 1, 0, 1]),
    await_input(rec, right, [1, 0]),
    #{sensors := #{ir_left := #{value := {value, 1}}}, emitted := 6, port_status := up} =
        dev(ir).

raw_analog_changes(doc) ->
    ["analog sensors emit the raw value on each change, and only on change"];
raw_analog_changes(_Config) ->
    ok = toroco:add_device(adc, toroco_pru_sensors,
                           #{sensors => [{pot, #{channel => 3, mode => analog}}]}),
    rec([pot]),
    ok = toroco:set_inputs(rec, #{pot => [{adc, pot}]}),
    [ok = toroco_pru_sensors:sim_adc(adc, pot, V) || V <- [5, 5, 6, 6, 6, 4095, 0]],
    await_input(rec, pot, [5, 6, 4095, 0]).

sim_adc_errors(doc) ->
    ["sim_adc names an unknown sensor, a device that is not running, a bad raw value"];
sim_adc_errors(_Config) ->
    ok = toroco:add_device(ir, toroco_pru_sensors, #{sensors => ir_sensors()}),
    ?assertEqual({error, {unknown_sensor, {ir, ir_middle}}},
                 toroco_pru_sensors:sim_adc(ir, ir_middle, 10)),
    ?assertEqual({error, {not_running, nowhere}}, toroco_pru_sensors:sim_adc(nowhere, a, 1)),
    ?assertEqual({error, {bad_adc_value, 5000}}, toroco_pru_sensors:sim_adc(ir, ir_left, 5000)).

shared_port_lost_and_back(doc) ->
    ["Three devices share one owner; when it dies and comes back they attach and "
     "configure again, the servos reporting {0, 0} meanwhile"];
shared_port_lost_and_back(Config) ->
    Root = ?config(root, Config),
    Owner = fun() ->
                    {ok, P} = toroco_pru_port:start_link(#{name => shared_pru, backend => sim,
                                                           sysfs_root => Root}),
                    unlink(P),
                    P
            end,
    P1 = Owner(),
    ok = toroco:add_device(ir, toroco_pru_sensors, #{port => shared_pru, sensors => ir_sensors()}),
    ok = toroco:add_device(motors, toroco_servo_motors, #{port => shared_pru}),
    ok = toroco:add_device(btn, toroco_gpio_button, #{port => shared_pru, line => 7,
                                                      debounce_ms => 0}),
    motor_rig(),
    rec([left, button]),
    ok = toroco:set_inputs(rec, #{left => [{ir, ir_left}], button => [{btn, button}]}),
    ok = toroco:inject({cmd, setvel}, {30, 30}),
    await_input(world, applied, [{30, 30}]),
    ok = toroco_pru_sensors:sim_adc(ir, ir_left, 2500),
    ok = toroco_gpio_button:sim_button(btn, 0),
    await_input(rec, left, [1]),
    await_input(rec, button, [pressed]),
    exit(P1, kill),
    await_input(world, applied, [{30, 30}, {0, 0}]),
    ok = wait_until(fun() -> maps:get(port_status, dev(ir)) =:= down end, ?WAIT),
    _P2 = Owner(),
    ok = wait_until(fun() -> [maps:get(port_status, dev(D)) || D <- [ir, motors, btn]]
                                 =:= [up, up, up] end, ?WAIT),
    %% the new owner knew nothing of the sections: the devices set them again
    ok = toroco_pru_sensors:sim_adc(ir, ir_left, 100),
    [ok = toroco_gpio_button:sim_button(btn, L) || L <- [0, 1]],
    await_input(rec, left, [1, 0]),
    await_input(rec, button, [pressed, pressed, released]),
    ok = toroco:inject({cmd, setvel}, {-20, -20}),
    await_input(world, applied, [{30, 30}, {0, 0}, {-20, -20}]),
    ?assertEqual("1400000", pwm(Root, 0, "duty_cycle")),
    #{port_losses := 1} = dev(motors).

%%% ---------------------------------------------------------------------
%%% Servo motors
%%% ---------------------------------------------------------------------

servo_duty(doc) ->
    ["setvel -100, 0, 100 give the calibrated duty cycles, mirrored on the reversed right servo"];
servo_duty(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root}),
    motor_rig(),
    ?assertEqual({"20000000", "20000000"}, {pwm(Root, 0, "period"), pwm(Root, 1, "period")}),
    ?assertEqual({"1", "1"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}),
    Steps = [{{-100, -100}, "1000000", "2000000"},
             {{0, 0}, ?NEUTRAL, ?NEUTRAL},
             {{100, 100}, "2000000", "1000000"},
             {{100, -50}, "2000000", "1750000"}],
    lists:foldl(fun({V, Left, Right}, Seen) ->
                        ok = toroco:inject({cmd, setvel}, V),
                        %% {0, 0} right at the start is no change: nothing applied
                        Seen1 = case Seen of [] when V =:= {0, 0} -> []; _ -> Seen ++ [V] end,
                        await_input(world, applied, Seen1),
                        ?assertEqual({V, Left, Right},
                                     {V, pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
                        Seen1
                end, [], Steps),
    #{applied := {100, -50}, commanded := {100, -50}, enabled := true} = dev(motors).

clamping_and_bad_values(doc) ->
    ["Out-of-range velocities are clamped and counted, floats rounded, bad values counted"];
clamping_and_bad_values(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {150, -300}),
    ok = toroco:inject({cmd, setvel}, {fast, slow}),
    ok = toroco:inject({cmd, setvel}, 7),
    ok = toroco:inject({cmd, enable}, maybe),
    ok = toroco:inject({cmd, setvel}, {50.4, -20.6}),
    await_input(world, applied, [{100, -100}, {50, -21}]),
    ?assertEqual("1750000", pwm(Root, 0, "duty_cycle")),
    #{clamped := 2, bad_input := #{bad_value := 3}} = dev(motors).

enable_disable(doc) ->
    ["Disabled servos stand at neutral with PWM off and report {0, 0}; enable applies the command"];
enable_disable(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root, enabled => false}),
    motor_rig(),
    ?assertEqual({"0", "0"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}),
    ok = toroco:inject({cmd, setvel}, {80, 80}),
    ok = toroco:inject({cmd, enable}, true),
    await_input(world, applied, [{80, 80}]),
    ?assertEqual({"1", "1"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}),
    ?assertEqual("1900000", pwm(Root, 0, "duty_cycle")),
    ok = toroco:inject({cmd, enable}, false),
    await_input(world, applied, [{80, 80}, {0, 0}]),
    ?assertEqual({"0", "0", ?NEUTRAL}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable"),
                                       pwm(Root, 0, "duty_cycle")}),
    ok = toroco:inject({cmd, setvel}, {-60, 60}),
    ok = toroco:inject({cmd, enable}, true),
    await_input(world, applied, [{80, 80}, {0, 0}, {-60, 60}]).

neutral_on_port_death(doc) ->
    ["kill -9 of the port program: applied {0, 0}, duty neutral, the command forgotten"];
neutral_on_port_death(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {100, 100}),
    await_input(world, applied, [{100, 100}]),
    ?assertEqual("2000000", pwm(Root, 0, "duty_cycle")),
    #{port := Owner} = dev(motors),
    OsPid = toroco_pru_port:os_pid(Owner),
    "" = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    await_input(world, applied, [{100, 100}, {0, 0}]),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
    ?assertNotEqual(OsPid, toroco_pru_port:os_pid(Owner)),
    #{port_restarts := 1, commanded := {0, 0}} = dev(motors),
    ok = toroco:inject({cmd, setvel}, {10, 10}),
    await_input(world, applied, [{100, 100}, {0, 0}, {10, 10}]).

latched_command_back_after_port_restart(doc) ->
    ["After the port program restarts, neutral first, then the wiring's latched setvel drives again"];
latched_command_back_after_port_restart(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {80, 80}, #{latch => true}),
    await_input(world, applied, [{80, 80}]),
    #{port := Owner} = dev(motors),
    OsPid = toroco_pru_port:os_pid(Owner),
    "" = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    await_input(world, applied, [{80, 80}, {0, 0}, {80, 80}]),
    ?assertNotEqual(OsPid, toroco_pru_port:os_pid(Owner)),
    #{port_restarts := 1, commanded := {80, 80}} = dev(motors).

neutral_on_watchdog(doc) ->
    ["Without keepalive a velocity lasts the watchdog period: then neutral and applied {0, 0}"];
neutral_on_watchdog(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root, watchdog_ms => 100,
                                                          keepalive => false}),
    motor_rig(),
    T0 = erlang:monotonic_time(millisecond),
    ok = toroco:inject({cmd, setvel}, {-70, -70}),
    await_input(world, applied, [{-70, -70}, {0, 0}]),
    ?assert(erlang:monotonic_time(millisecond) - T0 >= 90),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
    %% an idle period before the setvel may have counted one more
    #{watchdogs := W, keepalive_ms := off} = dev(motors),
    ?assert(W >= 1).

keepalive_and_stall(doc) ->
    ["The keepalive holds a velocity past the watchdog period; a stalled device gets neutral"];
keepalive_and_stall(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root, watchdog_ms => 150}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {40, 40}),
    await_input(world, applied, [{40, 40}]),
    %% four watchdog periods in which nothing may happen
    ?assertEqual({error, timeout},
                 toroco_fake_actuator:await(world, fun(H) -> length(H) > 1 end, 600)),
    ?assertEqual("1700000", pwm(Root, 0, "duty_cycle")),
    #{watchdogs := 0, keepalive_ms := 50} = dev(motors),
    %% this side stalls: the program's watchdog takes the servos to neutral
    Pid = toroco:whereis(motors),
    ok = sys:suspend(Pid),
    try
        ok = wait_until(fun() -> pwm(Root, 0, "duty_cycle") =:= ?NEUTRAL end, ?WAIT)
    after
        ok = sys:resume(Pid)
    end,
    await_input(world, applied, [{40, 40}, {0, 0}]),
    #{watchdogs := 1, applied := {0, 0}} = dev(motors),
    ?assertEqual(?NEUTRAL, pwm(Root, 0, "duty_cycle")).

neutral_on_remove(doc) ->
    ["Removing the device puts the servos at neutral and sends applied {0, 0}; "
     "a sim device without sysfs_root runs on its own temporary tree, removed with it"];
neutral_on_remove(Config) ->
    Root = ?config(root, Config),
    ok = toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Root}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {60, 60}),
    await_input(world, applied, [{60, 60}]),
    ?assertEqual("1800000", pwm(Root, 0, "duty_cycle")),
    #{port := Owner} = dev(motors),
    OsPid = toroco_pru_port:os_pid(Owner),
    ok = toroco:remove_device(motors),
    await_input(world, applied, [{60, 60}, {0, 0}]),
    ?assertNot(is_process_alive(Owner)),
    %% the program writes neutral once more on its way out: read once it is gone
    ok = wait_until(fun() -> not filelib:is_dir("/proc/" ++ integer_to_list(OsPid)) end, ?WAIT),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
    %% the same without a tree of its own
    ok = toroco:add_device(motors, toroco_servo_motors, #{}),
    ok = toroco:set_inputs(motors, #{setvel => [{cmd, setvel}]}),
    ok = toroco:set_inputs(world, #{applied => [{motors, applied}]}),
    #{sysfs_root := Tmp} = dev(motors),
    ?assert(filelib:is_dir(Tmp)),
    ok = toroco:inject({cmd, setvel}, {-10, 0}),
    await_input(world, applied, [{60, 60}, {0, 0}, {-10, 0}]),
    ?assertEqual("1450000", pwm(Tmp, 0, "duty_cycle")),
    ok = toroco:remove_device(motors),
    await_input(world, applied, [{60, 60}, {0, 0}, {-10, 0}, {0, 0}]),
    ?assertNot(filelib:is_dir(Tmp)).

servo_device_while_port_connecting(doc) ->
    ["While its restarted program withholds its hello, the servo device answers within 100 ms "
     "and a setvel is refused at once as connecting (counted), not queued; the program back, "
     "the latched command drives again"];
servo_device_while_port_connecting(Config) ->
    Root = ?config(root, Config),
    Flag = filename:join(Root, "no_hello"),
    Exe = filename:join(Root, "withhold.sh"),
    ok = file:write_file(Exe, ["#!/bin/sh\n",
                               "if [ -e '", Flag, "' ]; then exec sleep 30; fi\n",
                               "exec '", filename:join(code:priv_dir(toroco_hw), "pru_port"),
                               "' \"$@\"\n"]),
    ok = file:change_mode(Exe, 8#755),
    ok = toroco:add_device(motors, toroco_servo_motors,
                           #{sysfs_root => Root, executable => Exe, hello_timeout_ms => 60000}),
    motor_rig(),
    ok = toroco:inject({cmd, setvel}, {30, 30}, #{latch => true}),
    await_input(world, applied, [{30, 30}]),
    #{port := Owner} = dev(motors),
    Old = toroco_pru_port:os_pid(Owner),
    ok = file:write_file(Flag, ""),
    "" = os:cmd("kill -9 " ++ integer_to_list(Old)),
    ok = wait_until(fun() ->
                            case toroco_pru_port:info(Owner) of
                                #{state := connecting, os_pid := P} -> is_integer(P) andalso P =/= Old;
                                _ -> false
                            end
                    end, ?WAIT),
    #{port_errors := E0} = dev(motors),
    ok = toroco:inject({cmd, setvel}, {60, 60}, #{latch => true}),
    T0 = erlang:monotonic_time(microsecond),
    ok = wait_until(fun() -> maps:get(port_errors, dev(motors)) > E0 end, ?WAIT),
    Us = erlang:monotonic_time(microsecond) - T0,
    ct:pal("servo device: setvel refused as connecting, seen in its info after ~b us", [Us]),
    ?assert(Us < 100000),
    ?assertEqual({error, {connecting, awaiting_hello}}, toroco_pru_port:set_servos(Owner, #{left => 60})),
    #{commanded := {60, 60}, applied := {30, 30}} = dev(motors),
    #{os_pid := Sleeper} = toroco_pru_port:info(Owner),
    ok = file:delete(Flag),
    "" = os:cmd("kill -9 " ++ integer_to_list(Sleeper)),
    %% back: neutral first, then the wiring's latched command again
    await_input(world, applied, [{30, 30}, {0, 0}, {60, 60}]),
    ?assertEqual("1800000", pwm(Root, 0, "duty_cycle")).

%%% ---------------------------------------------------------------------
%%% Button
%%% ---------------------------------------------------------------------

button_edges(doc) ->
    ["An active-low button emits pressed and released once per edge"];
button_edges(_Config) ->
    ok = toroco:add_device(btn, toroco_gpio_button, #{line => 17, debounce_ms => 0}),
    rec([button]),
    ok = toroco:set_inputs(rec, #{button => [{btn, button}]}),
    [ok = toroco_gpio_button:sim_button(btn, L) || L <- [1, 0, 0, 1, 1, 0]],
    await_input(rec, button, [pressed, released, pressed]),
    #{edges := 3, last := pressed, line := 17} = dev(btn),
    ?assertEqual({error, {bad_level, 2}}, toroco_gpio_button:sim_button(btn, 2)).

%%% ---------------------------------------------------------------------
%%% Camera
%%% ---------------------------------------------------------------------

camera_datagrams(doc) ->
    ["Valid detector datagrams emit {X, Y} or none; malformed ones are counted by reason"];
camera_datagrams(_Config) ->
    ok = toroco:add_device(cam, toroco_udp_camera, #{port => 0}),
    rec([red, trq]),
    ok = toroco:set_inputs(rec, #{red => [{cam, update_red}], trq => [{cam, update_trq}]}),
    #{port := Port, accepted := 0, rejected := 0} = dev(cam),
    ?assert(Port > 0),
    Good = [<<"{\"color\":\"red\",\"x\":-12,\"y\":40,\"area\":300,\"t\":17}">>,
            <<"{\"color\":\"blue\",\"x\":5,\"y\":6,\"area\":20,\"t\":18}">>,
            <<"{\"color\":\"red\",\"none\":true}">>,
            <<"{\"t\":19,\"color\":\"blue\",\"none\":true,\"x\":1}">>,
            <<"{\"color\":\"red\",\"x\":0,\"y\":0,\"extra\":[1,2]}">>],
    Bad = [{<<"{\"color\":\"green\",\"x\":1,\"y\":1}">>, unknown_colour},
           {<<"{\"color\":\"red\",\"x\":1}">>, bad_field},
           {<<"{\"color\":\"red\",\"x\":1.5,\"y\":2}">>, bad_field},
           {<<"{\"color\":\"red\",\"x\":\"1\",\"y\":2}">>, bad_field},
           {<<"{\"color\":\"red\",\"x\":99999999999999999999,\"y\":2}">>, bad_field},
           {<<"{\"color\":\"red\",\"x\":1,\"y\":2,\"area\":\"big\"}">>, bad_field},
           {<<"{\"color\":\"red\",\"none\":1}">>, bad_field},
           {<<"{\"x\":1,\"y\":2}">>, no_colour},
           {<<"[1,2,3]">>, not_object},
           {<<"\"red\"">>, not_object},
           {<<"{\"color\":\"red\",\"x\":1,">>, not_json},
           {<<>>, not_json},
           {<<255, 0, 17>>, not_json},
           {binary:copy(<<" ">>, 2000), oversized}],
    send_udp(Port, Good ++ [B || {B, _} <- Bad]),
    await_input(rec, red, [{-12, 40}, none, {0, 0}]),
    await_input(rec, trq, [{5, 6}, none]),
    ok = wait_until(fun() -> maps:get(rejected, dev(cam)) =:= length(Bad) end, ?WAIT),
    Expected = lists:foldl(fun({_, R}, Acc) -> maps:update_with(R, fun(N) -> N + 1 end, 1, Acc) end,
                           #{}, Bad),
    #{accepted := 5, rejected_by := RejectedBy} = dev(cam),
    ?assertEqual(Expected, RejectedBy).

camera_allow_list(doc) ->
    ["A camera with an allow-list drops datagrams from other senders as not_allowed"];
camera_allow_list(_Config) ->
    ok = toroco:add_device(cam, toroco_udp_camera, #{allow => [{127, 0, 0, 2}], ip => "127.0.0.1"}),
    rec([red]),
    ok = toroco:set_inputs(rec, #{red => [{cam, update_red}]}),
    #{port := Port} = dev(cam),
    send_udp(Port, [<<"{\"color\":\"red\",\"x\":1,\"y\":1}">>]),
    ok = wait_until(fun() -> maps:get(rejected_by, dev(cam)) =:= #{not_allowed => 1} end, ?WAIT),
    {ok, S} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 2}}]),
    ok = gen_udp:send(S, {127, 0, 0, 1}, Port, <<"{\"color\":\"red\",\"x\":2,\"y\":2}">>),
    gen_udp:close(S),
    await_input(rec, red, [{2, 2}]).

%%% ---------------------------------------------------------------------
%%% Function adapters
%%% ---------------------------------------------------------------------

poll_on_change(doc) ->
    ["A polled function's value is emitted at start and then only when it changes"];
poll_on_change(_Config) ->
    Tab = ets:new(poll, [public]),
    true = ets:insert(Tab, {v, 1}),
    Read = fun() -> ets:lookup_element(Tab, v, 2) end,
    rec([level]),
    ok = toroco:add_device(gauge, toroco_poll_sensor, #{fn => Read, every_ms => 5,
                                                        output => level}),
    ok = toroco:set_inputs(rec, #{level => [{gauge, level}]}),
    %% added before wiring: the first value went nowhere; a change shows up
    true = ets:insert(Tab, {v, 2}),
    await_input(rec, level, [2]),
    ok = wait_until(fun() -> maps:get(polls, dev(gauge)) >= 5 end, ?WAIT),
    true = ets:insert(Tab, {v, 3}),
    await_input(rec, level, [2, 3]),
    true = ets:insert(Tab, {v, {a, b}}),
    await_input(rec, level, [2, 3, {a, b}]),
    #{emitted := 4, crashes := 0, last := {value, {a, b}}} = dev(gauge).

poll_crashes(doc) ->
    ["A polled function that crashes is counted; the device lives on and polls again"];
poll_crashes(_Config) ->
    Tab = ets:new(poll, [public]),
    true = ets:insert(Tab, {v, 1}),
    Read = fun() -> case ets:lookup_element(Tab, v, 2) of
                        crash -> error(sensor_unplugged);
                        throw -> throw(nope);
                        V -> V
                    end end,
    rec([level]),
    ok = toroco:add_device(gauge, toroco_poll_sensor, #{fn => {erlang, apply, [Read, []]},
                                                        every_ms => 5, output => level,
                                                        latch => true}),
    ok = toroco:set_inputs(rec, #{level => [{gauge, level}]}),
    %% latched: wiring delivers the current value
    await_input(rec, level, [1]),
    Pid = toroco:whereis(gauge),
    true = ets:insert(Tab, {v, crash}),
    ok = wait_until(fun() -> maps:get(crashes, dev(gauge)) >= 3 end, ?WAIT),
    true = ets:insert(Tab, {v, throw}),
    ok = wait_until(fun() -> maps:get(crashes, dev(gauge)) >= 6 end, ?WAIT),
    true = ets:insert(Tab, {v, 2}),
    await_input(rec, level, [1, 2]),
    ?assertEqual(Pid, toroco:whereis(gauge)).

poll_period_changed(doc) ->
    ["{toroco_poll, every_ms, Ms} re-times a polled sensor (the original Torocó's "
     "configure_polling); a bad period is refused and changes nothing"];
poll_period_changed(_Config) ->
    ok = toroco:add_device(gauge, toroco_poll_sensor, #{fn => fun() -> 1 end, every_ms => 60000}),
    ok = wait_until(fun() -> maps:get(polls, dev(gauge)) >= 1 end, ?WAIT),
    ?assertEqual({error, {bad_option, {every_ms, 0}}},
                 toroco_device:call(gauge, {toroco_poll, every_ms, 0}, 5000)),
    #{every_ms := 60000, polls := 1} = dev(gauge),
    ok = toroco_device:call(gauge, {toroco_poll, every_ms, 5}, 5000),
    #{every_ms := 5} = dev(gauge),
    ok = wait_until(fun() -> maps:get(polls, dev(gauge)) >= 5 end, ?WAIT).

fun_actuator_calls(doc) ->
    ["A function actuator is called with each delivered value, in order; crashes are counted"];
fun_actuator_calls(_Config) ->
    Self = self(),
    Fn = fun(_In, boom) -> error(boom);
            (In, V) -> Self ! {called, In, V}
         end,
    ok = toroco:add_device(src, toroco_fake_sensor, #{outputs => [a, b]}),
    ok = toroco:add_device(act, toroco_fun_actuator, #{fn => Fn, inputs => [x, y]}),
    ok = toroco:set_inputs(act, #{x => [{src, a}], y => [{src, b}]}),
    [ok = toroco:inject({src, a}, V) || V <- [1, boom, 2, 3]],
    ok = toroco:inject({src, b}, hello),
    ?assertEqual([{x, 1}, {x, 2}, {x, 3}], [receive {called, x, V} -> {x, V} after ?WAIT -> none end
                                            || _ <- [1, 2, 3]]),
    receive {called, y, hello} -> ok after ?WAIT -> ct:fail(no_call_on_y) end,
    ok = wait_until(fun() -> dev(act) =:= #{calls => 5, crashes => 1} end, ?WAIT),
    %% an {M, F, A} function gets the input and value first
    ok = toroco:add_device(act2, toroco_fun_actuator,
                           #{fn => {erlang, send, []}, inputs => [x]}),
    ok = toroco:set_inputs(act2, #{x => [{src, a}]}),
    ok = toroco:inject({src, a}, not_a_pid),
    ok = wait_until(fun() -> dev(act2) =:= #{calls => 1, crashes => 1} end, ?WAIT).

%%% ---------------------------------------------------------------------
%%% Options
%%% ---------------------------------------------------------------------

bad_options(doc) ->
    ["Bad options refuse add_device with a reason naming the device and the option"];
bad_options(Config) ->
    Root = ?config(root, Config),
    Cases =
        [{toroco_udp_camera, #{port => -1}, {bad_option, {port, -1}}},
         {toroco_udp_camera, #{ip => "nonsense"}, {bad_option, {ip, "nonsense"}}},
         {toroco_udp_camera, #{colour => red}, {unknown_option, colour}},
         {toroco_udp_camera, #{max_datagram => 0}, {bad_option, {max_datagram, 0}}},
         {toroco_udp_link, #{peers => [{"127.0.0.1", 70000}]},
          {bad_option, {peers, [{"127.0.0.1", 70000}]}}},
         {toroco_udp_link, #{inputs => ["cmd"]}, {bad_option, {inputs, ["cmd"]}}},
         {toroco_tcp_link, #{max_line => 0}, {bad_option, {max_line, 0}}},
         {toroco_tcp_link, #{allow => [nowhere]}, {bad_option, {allow, [nowhere]}}},
         {toroco_tcp_link, #{line_timeout => 0}, {bad_option, {line_timeout, 0}}},
         {toroco_tcp_link, #{min_age => -1}, {bad_option, {min_age, -1}}},
         {toroco_pru_sensors, #{}, {bad_option, {sensors, missing}}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 9}}]},
          {bad_option, {sensors, {a, {channel, 9}}}}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 0, mode => analog_threshold,
                                                  threshold_high => 10,
                                                  threshold_low => 20}}]},
          {bad_option, {sensors, {a, {thresholds, 10, 20}}}}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 0}}, {b, #{channel => 0}}]},
          {bad_option, {sensors, {duplicate_channel, 0}}}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 0}}], port => no_such_owner},
          {port_not_running, no_such_owner}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 0}}], backend => qemu},
          {bad_option, {backend, qemu}}},
         {toroco_pru_sensors, #{sensors => [{a, #{channel => 0}}], port => x, backend => sim},
          {bad_option, {backend, only_without_port}}},
         {toroco_servo_motors, #{servos => #{middle => #{}}, sysfs_root => Root},
          {bad_option, {servos, {unknown_servo, middle}}}},
         {toroco_servo_motors, #{servos => #{left => #{span_ns => 2000000}}, sysfs_root => Root},
          {bad_option, {servos, {left, {pulse_out_of_period, {20000000, 1500000, 2000000}}}}}},
         {toroco_servo_motors, #{watchdog_ms => -5, sysfs_root => Root},
          {bad_option, {watchdog_ms, -5}}},
         {toroco_servo_motors, #{enabled => yes}, {bad_option, {enabled, yes}}},
         {toroco_gpio_button, #{}, {bad_option, {line, missing}}},
         {toroco_poll_sensor, #{fn => fun(_) -> x end}, {bad_option, {fn, '_'}}},
         {toroco_poll_sensor, #{fn => fun() -> x end, every_ms => 0}, {bad_option, {every_ms, 0}}},
         {toroco_fun_actuator, #{fn => fun(_, _) -> ok end}, {bad_option, {inputs, missing}}}],
    [begin
         Result = refusal(toroco:add_device(bad, M, Opts)),
         case {Result, Expected} of
             {{bad, {bad_option, {fn, _}}}, {bad_option, {fn, '_'}}} -> ok;
             _ -> ?assertEqual({M, {bad, Expected}}, {M, Result})
         end
     end || {M, Opts, Expected} <- Cases],
    ?assertEqual([], maps:get(devices, toroco:inspect())),
    %% a port in use
    {ok, S} = gen_udp:open(0, [{ip, {127, 0, 0, 1}}]),
    {ok, Taken} = inet:port(S),
    ?assertEqual({cam, {udp_open, {{127, 0, 0, 1}, Taken}, eaddrinuse}},
                 refusal(toroco:add_device(cam, toroco_udp_camera, #{port => Taken}))),
    gen_udp:close(S).

missing_device_files(doc) ->
    ["A servo tree without its PWM files refuses the device, naming the missing file"];
missing_device_files(Config) ->
    Empty = filename:join(?config(priv_dir, Config), "empty_sysfs"),
    ok = filelib:ensure_dir(filename:join(Empty, "x")),
    Export = filename:join(Empty, "class/pwm/pwmchip0/export"),
    ?assertEqual({motors, {servos, {sysfs, Export, enoent}}},
                 refusal(toroco:add_device(motors, toroco_servo_motors, #{sysfs_root => Empty}))),
    Script = filename:join(Empty, "no_such_script"),
    ?assertEqual({ir, {port_program, {sim_script, Script, enoent}}},
                 refusal(toroco:add_device(ir, toroco_pru_sensors,
                                           #{sensors => [{a, #{channel => 0}}],
                                             sim_script => Script}))),
    %% nothing is left running
    ?assertEqual([], maps:get(devices, toroco:inspect())).

%%% ---------------------------------------------------------------------
%%% What no device handles
%%% ---------------------------------------------------------------------

unknown_requests(doc) ->
    ["Every device answers a call it does not know with unknown_call naming it and the "
     "request, and keeps running after a message it does not know"];
unknown_requests(_Config) ->
    Devices = [{ir, toroco_pru_sensors, #{sensors => ir_sensors()}},
               {motors, toroco_servo_motors, #{}},
               {btn, toroco_gpio_button, #{line => 7}},
               {cam, toroco_udp_camera, #{port => 0}},
               {gauge, toroco_poll_sensor, #{fn => fun() -> 1 end, every_ms => 50,
                                             output => level}},
               {act, toroco_fun_actuator, #{fn => fun(_, _) -> ok end, inputs => [x]}},
               {fake_in, toroco_fake_sensor, #{outputs => [v]}},
               {fake_out, toroco_fake_actuator, #{inputs => [x]}}],
    [ok = toroco:add_device(N, M, Opts) || {N, M, Opts} <- Devices],
    lists:foreach(
      fun({N, _, _}) ->
              Pid = toroco:whereis(N),
              Pid ! {no_such, message},
              ?assertEqual({error, {unknown_call, {N, {no_such, request}}}},
                           gen_statem:call(Pid, {no_such, request}, ?WAIT)),
              ?assertEqual(Pid, toroco:whereis(N)),
              ?assertMatch(#{status := running}, toroco:inspect(N))
      end, Devices).

%%% ---------------------------------------------------------------------
%%% Helpers
%%% ---------------------------------------------------------------------

ir_sensors() ->
    [{ir_left, #{channel => 0, mode => analog_threshold, threshold_high => 2000,
                 threshold_low => 1500}},
     {ir_right, #{channel => 1, mode => analog_threshold, threshold_high => 2000,
                  threshold_low => 1500}}].

%% A fake sensor `cmd' driving the motors, a recorder `world' on `applied'.
motor_rig() ->
    ok = toroco:add_device(cmd, toroco_fake_sensor, #{outputs => [setvel, enable]}),
    ok = toroco:add_device(world, toroco_fake_actuator, #{inputs => [applied]}),
    ok = toroco:set_inputs(motors, #{setvel => [{cmd, setvel}], enable => [{cmd, enable}]}),
    ok = toroco:set_inputs(world, #{applied => [{motors, applied}]}).

rec(Inputs) ->
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => Inputs}).

%% The device and reason of a refused add_device. The supervisor adds its
%% child record to the reason a start failed with; that part is left out.
refusal({error, {start_failed, {Name, {Reason, Child}}}}) when element(1, Child) =:= child ->
    {Name, Reason};
refusal({error, {start_failed, {Name, Reason}}}) ->
    {Name, Reason};
refusal(Other) ->
    ct:fail({not_a_refused_start, Other}).

dev(Name) ->
    maps:get(device, toroco:inspect(Name)).

await_input(A, Input, Expected) ->
    toroco_test_lib:await_input(A, Input, Expected, ?WAIT).

send_udp(Port, Datagrams) ->
    {ok, S} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    [ok = gen_udp:send(S, {127, 0, 0, 1}, Port, D) || D <- Datagrams],
    gen_udp:close(S).
