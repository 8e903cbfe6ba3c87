%% The pru_port program and its owner, through the sim backend, with the
%% servos' PWM on a fake sysfs tree in the case's private directory.
-module(toroco_pru_port_SUITE).
-import(toroco_test_lib, [wait_until/2]).
-import(toroco_hw_test_lib, [fake_pwm/3, pwm/3]).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, groups/0, suite/0, init_per_suite/1, end_per_suite/1,
         init_per_testcase/2, end_per_testcase/2]).
-export([threshold_crossings/1, analog_changes/1, sim_script/1, adc_errors/1,
         button_edges/1, button_debounce/1,
         servo_duty/1, enable_disable/1, servo_errors/1,
         neutral_on_kill/1, neutral_on_watchdog/1, neutral_on_stdin_eof/1,
         neutral_on_owner_stop/1, bad_frames_raw/1, bad_requests_owner/1,
         round_trip/1,
         servo_command_while_connecting/1, neutral_first_after_kill_in_configuring/1,
         hello_backoff/1, first_start_without_hello/1]).

-define(NEUTRAL, "1500000").
-define(WAIT, 5000).

suite() ->
    [{timetrap, {seconds, 60}}].

all() ->
    [{group, adc}, {group, button}, {group, servos}, {group, safety}, {group, connecting},
     {group, performance}].

groups() ->
    [{adc, [], [threshold_crossings, analog_changes, sim_script, adc_errors]},
     {button, [], [button_edges, button_debounce]},
     {servos, [], [servo_duty, enable_disable, servo_errors]},
     {safety, [], [neutral_on_kill, neutral_on_watchdog, neutral_on_stdin_eof,
                   neutral_on_owner_stop, bad_frames_raw, bad_requests_owner]},
     {connecting, [], [servo_command_while_connecting, neutral_first_after_kill_in_configuring,
                       hello_backoff, first_start_without_hello]},
     {performance, [], [round_trip]}].

init_per_suite(Config) ->
    toroco_hw_test_lib:require_pru_port(Config).

end_per_suite(_Config) ->
    ok.

init_per_testcase(Case, Config) ->
    Root = filename:join(?config(priv_dir, Config), atom_to_list(Case)),
    fake_pwm(Root, 0, 0),
    fake_pwm(Root, 0, 1),
    [{root, Root} | Config].

end_per_testcase(_Case, _Config) ->
    ok.

%%% ---------------------------------------------------------------------
%%% ADC
%%% ---------------------------------------------------------------------

threshold_crossings(doc) ->
    ["An analog_threshold channel reports exactly one event per crossing "
     "and none for noise inside the hysteresis band"];
threshold_crossings(Config) ->
    S = start(Config, #{adc => [#{channel => 0, mode => analog_threshold,
                                  threshold_high => 2000, threshold_low => 1500}]}),
    ok = toroco_pru_port:subscribe(S),
    %% first sample: 0; noise; up; noise around high; down; noise; up
    Samples = [1000,
               1400, 1600, 1999, 1501, 1700,
               2000,
               1990, 2100, 1501, 1999, 4095,
               1500,
               1510, 1999, 1600, 0, 1200,
               2500],
    [ok = toroco_pru_port:sim_adc(S, 0, V) || V <- Samples],
    %% each event is sent before the reply of the sample that caused it,
    %% so all of them are in the mailbox now
    ?assertEqual([0, 1, 0, 1], [V || {0, V} <- adc_events()]).

analog_changes(doc) ->
    ["An analog channel reports the raw value on change only, per channel"];
analog_changes(Config) ->
    S = start(Config, #{adc => [#{channel => 1, mode => analog},
                                #{channel => 2, mode => analog}]}),
    ok = toroco_pru_port:subscribe(S),
    [ok = toroco_pru_port:sim_adc(S, Ch, V)
     || {Ch, V} <- [{1, 5}, {1, 5}, {2, 5}, {1, 6}, {2, 5}, {1, 6}, {1, 4095}]],
    ?assertEqual([{1, 5}, {2, 5}, {1, 6}, {1, 4095}], adc_events()).

sim_script(doc) ->
    ["A sim script's samples go through the same filter, in order"];
sim_script(Config) ->
    Script = filename:join(?config(root, Config), "ir.script"),
    ok = file:write_file(Script, "# left IR\n50 0 1000\n5 0 1800\n5 0 2600\n5 0 1700\n5 0 900\n"),
    S = start(Config, #{sim_script => Script,
                        adc => [#{channel => 0, mode => analog_threshold,
                                  threshold_high => 2000, threshold_low => 1500}]}),
    ok = toroco_pru_port:subscribe(S),
    ?assertEqual([0, 1, 0], [await_adc(0), await_adc(0), await_adc(0)]),
    ?assertEqual([], adc_events()).

adc_errors(doc) ->
    ["Refused ADC configurations name the channel and change nothing"];
adc_errors(Config) ->
    ?assertEqual({error, {adc, {bad_threshold, 3}}},
                 start_link(Config, #{adc => [#{channel => 3, mode => analog_threshold,
                                                threshold_high => 100, threshold_low => 200}]})),
    S = start(Config, #{adc => [#{channel => 0, mode => analog}]}),
    ?assertEqual({error, {bad_channel, 9}},
                 toroco_pru_port:configure_adc(S, [#{channel => 9, mode => analog}])),
    ?assertEqual({error, {duplicate_channel, 1}},
                 toroco_pru_port:configure_adc(S, [#{channel => 1, mode => analog},
                                                   #{channel => 1, mode => off}])),
    ?assertMatch({error, {bad_adc_channel, _}},
                 toroco_pru_port:configure_adc(S, [#{channel => 1}])),
    ?assertEqual({error, {unconfigured_channel, 1}}, toroco_pru_port:sim_adc(S, 1, 10)),
    ok = toroco_pru_port:subscribe(S),
    ok = toroco_pru_port:sim_adc(S, 0, 10),
    ?assertEqual([{0, 10}], adc_events()).

%%% ---------------------------------------------------------------------
%%% Button
%%% ---------------------------------------------------------------------

button_edges(doc) ->
    ["An active-low button reports pressed on a low line and released on a high one, once each"];
button_edges(Config) ->
    S = start(Config, #{button => #{line => 17, active_low => true, debounce_ms => 0}}),
    ok = toroco_pru_port:subscribe(S),
    [ok = toroco_pru_port:sim_button(S, L) || L <- [1, 0, 0, 1, 1, 0]],
    ?assertEqual([pressed, released, pressed], button_events()),
    ?assertEqual({error, {bad_level, 2}}, toroco_pru_port:sim_button(S, 2)).

button_debounce(doc) ->
    ["Bounces shorter than the debounce time give one edge, once the level holds"];
button_debounce(Config) ->
    S = start(Config, #{button => #{line => 17, active_low => false, debounce_ms => 30}}),
    ok = toroco_pru_port:subscribe(S),
    %% without the debounce these would be five edges
    [ok = toroco_pru_port:sim_button(S, L) || L <- [1, 0, 1, 0, 1]],
    receive
        {toroco_pru_port, {button, pressed, _}} -> ok
    after ?WAIT -> ct:fail(no_debounced_edge)
    end,
    %% the debounce timer has fired; anything else would be here by now
    pong = toroco_pru_port:ping(S),
    ?assertEqual([], button_events()).

%%% ---------------------------------------------------------------------
%%% Servos
%%% ---------------------------------------------------------------------

servo_duty(doc) ->
    ["Velocities -100, 0, 100 give the calibrated duty cycles, mirrored for a reversed servo"];
servo_duty(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos()}),
    ?assertEqual("20000000", pwm(Root, 0, "period")),
    ?assertEqual(?NEUTRAL, pwm(Root, 0, "duty_cycle")),
    ?assertEqual(?NEUTRAL, pwm(Root, 1, "duty_cycle")),
    ?assertEqual("0", pwm(Root, 0, "enable")),
    Expect = [{100, "2000000", "1000000"}, {0, ?NEUTRAL, ?NEUTRAL},
              {-100, "1000000", "2000000"}, {50, "1750000", "1250000"}],
    [begin
         ok = toroco_pru_port:set_servos(S, #{left => V, right => V}),
         ?assertEqual({V, Left, Right},
                      {V, pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")})
     end || {V, Left, Right} <- Expect],
    ok = toroco_pru_port:neutral(S),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}).

enable_disable(doc) ->
    ["enable_servos writes every servo's enable file"];
enable_disable(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos()}),
    ok = toroco_pru_port:enable_servos(S, true),
    ?assertEqual({"1", "1"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}),
    ok = toroco_pru_port:enable_servos(S, false),
    ?assertEqual({"0", "0"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}).

servo_errors(doc) ->
    ["Refused servo commands name the servo or the file, and write nothing"];
servo_errors(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos()}),
    ok = toroco_pru_port:set_servos(S, #{left => 20}),
    ?assertEqual({error, {unknown_servo, middle}},
                 toroco_pru_port:set_servos(S, #{middle => 10})),
    ?assertEqual({error, {bad_velocity, left}}, toroco_pru_port:set_servos(S, #{left => 101})),
    ?assertEqual("1600000", pwm(Root, 0, "duty_cycle")),
    Missing = filename:join(Root, "class/pwm/pwmchip4/export"),
    ?assertEqual({error, {sysfs, Missing, enoent}},
                 toroco_pru_port:configure_servos(S, #{far => #{pwmchip => 4, channel => 0}})),
    ?assertEqual({error, {servos, {bad_calibration, wide}}},
                 start_link(Config, #{servos => #{wide => #{pwmchip => 0, channel => 0,
                                                            span_ns => 1600000}}})).

%%% ---------------------------------------------------------------------
%%% Safety
%%% ---------------------------------------------------------------------

neutral_on_kill(doc) ->
    ["kill -9 of the program: the owner restarts it, servos are neutral, "
     "the configuration (ADC, servos, enable) is applied again"];
neutral_on_kill(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos(),
                        adc => [#{channel => 0, mode => analog_threshold,
                                  threshold_high => 2000, threshold_low => 1500}]}),
    ok = toroco_pru_port:configure_adc(S, [#{channel => 2, mode => analog_threshold,
                                             threshold_high => 3000, threshold_low => 1000}]),
    ok = toroco_pru_port:enable_servos(S, true),
    ok = toroco_pru_port:set_servos(S, #{left => 100, right => -40}),
    ?assertEqual("2000000", pwm(Root, 0, "duty_cycle")),
    ok = toroco_pru_port:subscribe(S),
    Old = toroco_pru_port:os_pid(S),
    "" = os:cmd("kill -9 " ++ integer_to_list(Old)),
    receive
        {toroco_pru_port, {port_restarted, {exit_status, Status}}} -> ?assertEqual(137, Status)
    after ?WAIT -> ct:fail(no_restart)
    end,
    ?assertNotEqual(Old, toroco_pru_port:os_pid(S)),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
    ?assertEqual({"1", "1"}, {pwm(Root, 0, "enable"), pwm(Root, 1, "enable")}),
    %% the ADC set in force is the one configured last, not the start one
    ?assertEqual({error, {unconfigured_channel, 0}}, toroco_pru_port:sim_adc(S, 0, 2500)),
    ok = toroco_pru_port:sim_adc(S, 2, 3500),
    ok = toroco_pru_port:sim_adc(S, 2, 2000),
    ok = toroco_pru_port:sim_adc(S, 2, 500),
    ?assertEqual([{2, 1}, {2, 0}], adc_events()).

neutral_on_watchdog(doc) ->
    ["No servo command for the watchdog period: neutral, then one watchdog event"];
neutral_on_watchdog(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos(), watchdog_ms => 100}),
    ok = toroco_pru_port:subscribe(S),
    ok = toroco_pru_port:set_servos(S, #{left => -100, right => 100}),
    ?assertEqual("1000000", pwm(Root, 0, "duty_cycle")),
    T0 = erlang:monotonic_time(millisecond),
    receive
        {toroco_pru_port, {watchdog, _}} -> ok
    after ?WAIT -> ct:fail(no_watchdog)
    end,
    Waited = erlang:monotonic_time(millisecond) - T0,
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}),
    ?assert(Waited >= 90),
    %% once per silence: a ping round trip later there is still only one
    pong = toroco_pru_port:ping(S),
    receive {toroco_pru_port, {watchdog, _}} -> ct:fail(second_watchdog) after 0 -> ok end.

neutral_on_stdin_eof(doc) ->
    ["Closing the program's stdin (the port) puts the servos at neutral"];
neutral_on_stdin_eof(Config) ->
    Root = ?config(root, Config),
    P = raw_port(Config),
    {reply, 1, ok} = raw_call(P, {1, {configure_servos, [wire_left()]}}),
    {reply, 2, ok} = raw_call(P, {2, {set_servos, [{left, 100}]}}),
    ?assertEqual("2000000", pwm(Root, 0, "duty_cycle")),
    true = port_close(P),
    %% nothing more can come from a closed port: watch the file instead
    ok = wait_until(fun() -> pwm(Root, 0, "duty_cycle") =:= ?NEUTRAL end, ?WAIT).

neutral_on_owner_stop(doc) ->
    ["Stopping the owner leaves the servos at neutral"];
neutral_on_owner_stop(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{servos => servos()}),
    ok = toroco_pru_port:set_servos(S, #{left => 70, right => 70}),
    OsPid = toroco_pru_port:os_pid(S),
    ok = toroco_pru_port:stop(S),
    %% the program writes neutral once more on its way out (stdin EOF):
    %% read the files once it is gone
    ok = wait_until(fun() -> not filelib:is_dir("/proc/" ++ integer_to_list(OsPid)) end, ?WAIT),
    ?assertEqual({?NEUTRAL, ?NEUTRAL}, {pwm(Root, 0, "duty_cycle"), pwm(Root, 1, "duty_cycle")}).

bad_frames_raw(doc) ->
    ["Undecodable frames get error terms, go neutral first, and the program lives on"];
bad_frames_raw(Config) ->
    Root = ?config(root, Config),
    P = raw_port(Config),
    {reply, 1, ok} = raw_call(P, {1, {configure_servos, [wire_left()]}}),
    Bad = [{<<1, 2, 3>>, {error, {bad_frame, not_a_term}}},
           {<<>>, {error, {bad_frame, not_a_term}}},
           {<<131, 104, 2, 97>>, {error, {bad_frame, not_a_term}}},
           {term_to_binary(self()), {error, {bad_frame, not_a_term}}},
           {term_to_binary(hello), {error, {bad_frame, not_a_request}}},
           {term_to_binary({7, {set_servos, fast}}), {reply, 7, {error, {bad_request, set_servos}}}},
           {term_to_binary({8, {launch, 1}}), {reply, 8, {error, {unknown_request, launch}}}}],
    [begin
         {reply, 2, ok} = raw_call(P, {2, {set_servos, [{left, 100}]}}),
         ?assertEqual("2000000", pwm(Root, 0, "duty_cycle")),
         true = port_command(P, Frame),
         ?assertEqual(Reply, raw_recv(P)),
         ?assertEqual(?NEUTRAL, pwm(Root, 0, "duty_cycle"))
     end || {Frame, Reply} <- Bad],
    ?assertEqual({reply, 9, pong}, raw_call(P, {9, ping})),
    port_close(P).

bad_requests_owner(doc) ->
    ["Through the owner, a malformed request is an error value; the program is not restarted"];
bad_requests_owner(Config) ->
    S = start(Config, #{}),
    Pid = toroco_pru_port:os_pid(S),
    ?assertEqual({error, {unknown_request, launch}}, toroco_pru_port:call(S, {launch, 1})),
    ?assertEqual({error, {bad_request, sim_adc}}, toroco_pru_port:call(S, {sim_adc, x, y})),
    ?assertEqual({error, button_not_configured}, toroco_pru_port:sim_button(S, 1)),
    ?assertEqual(pong, toroco_pru_port:ping(S)),
    ?assertEqual(Pid, toroco_pru_port:os_pid(S)).

%%% ---------------------------------------------------------------------
%%% Connecting: the owner answers while a program starts
%%% ---------------------------------------------------------------------

servo_command_while_connecting(doc) ->
    ["While a restarted program withholds its hello (30 s), a servo command answers within "
     "100 ms with {error, {connecting, awaiting_hello}}; a neutral waits for the next program"];
servo_command_while_connecting(Config) ->
    Root = ?config(root, Config),
    S = start(Config, #{executable => withhold_exe(Config), servos => servos(),
                        hello_timeout_ms => 60000}),
    ok = toroco_pru_port:subscribe(S),
    ok = toroco_pru_port:set_servos(S, #{left => 50}),
    Old = toroco_pru_port:os_pid(S),
    ok = file:write_file(flag(Config), ""),
    kill(Old),
    ok = wait_until(fun() -> awaiting_hello(S, Old) end, ?WAIT),
    #{os_pid := Sleeper} = toroco_pru_port:info(S),
    ok = wait_until(fun() -> withholding(Config, Sleeper) end, ?WAIT),
    Self = self(),
    _ = spawn_link(fun() -> Self ! {neutral, toroco_pru_port:call(S, neutral, 60000)} end),
    Calls = [begin
                 T0 = erlang:monotonic_time(microsecond),
                 R = toroco_pru_port:set_servos(S, #{left => 10}),
                 {erlang:monotonic_time(microsecond) - T0, R}
             end || _ <- lists:seq(1, 50)],
    Us = lists:sort([T || {T, _} <- Calls]),
    ct:pal("set_servos while the program withholds its hello, 50 calls: "
           "first ~b us, median ~b us, max ~b us",
           [element(1, hd(Calls)), lists:nth(25, Us), lists:last(Us)]),
    ?assertEqual([{error, {connecting, awaiting_hello}}], lists:usort([R || {_, R} <- Calls])),
    ?assert(lists:last(Us) < 100000),
    ?assertEqual({error, {connecting, awaiting_hello}}, toroco_pru_port:ping(S)),
    ?assertMatch(#{state := connecting, os_pid := Sleeper}, toroco_pru_port:info(S)),
    receive {neutral, Early} -> ct:fail({neutral_answered_without_program, Early})
    after 0 -> ok
    end,
    %% the test ends the withholding: the next program says hello, goes
    %% neutral, and the waiting neutral is answered
    ok = file:delete(flag(Config)),
    kill(Sleeper),
    receive
        {toroco_pru_port, {port_restarted, Why}} -> ?assertEqual({exit_status, 137}, Why)
    after ?WAIT -> ct:fail(no_restart)
    end,
    receive {neutral, Neutral} -> ?assertEqual(ok, Neutral)
    after ?WAIT -> ct:fail(neutral_not_answered)
    end,
    ?assertEqual(?NEUTRAL, pwm(Root, 0, "duty_cycle")),
    ok = toroco_pru_port:set_servos(S, #{left => 10}),
    ok = toroco_pru_port:stop(S).

neutral_first_after_kill_in_configuring(doc) ->
    ["A program killed while it is being configured: meanwhile a servo command is refused "
     "as connecting, and the next program's first servo command is neutral (its frames, "
     "logged by a fake program)"];
neutral_first_after_kill_in_configuring(Config) ->
    Root = ?config(root, Config),
    Exe = filename:join(Root, "fake_pru_port"),
    {ok, _} = file:copy(filename:join(?config(data_dir, Config), "fake_pru_port.escript"), Exe),
    ok = file:change_mode(Exe, 8#755),
    Conf = filename:join(Root, "fake.conf"),
    S = start(Config, #{executable => Exe, servos => servos(), enabled => true,
                        watchdog_ms => 500}),
    ok = toroco_pru_port:subscribe(S),
    ok = toroco_pru_port:set_servos(S, #{left => 100, right => 100}),
    First = toroco_pru_port:os_pid(S),
    %% the second program leaves its servo configuration unanswered
    ok = file:write_file(Conf, "{stall, configure_servos}.\n"),
    kill(First),
    ok = wait_until(fun() -> requests(Root, other_than(First), configure_servos) =/= [] end,
                    4 * ?WAIT),
    #{state := configuring, os_pid := Second} = toroco_pru_port:info(S),
    ?assertEqual({error, {connecting, configuring}},
                 toroco_pru_port:set_servos(S, #{left => 100, right => 100})),
    ok = file:delete(Conf),
    kill(Second),
    receive
        {toroco_pru_port, {port_restarted, Why}} -> ?assertEqual({exit_status, 137}, Why)
    after 4 * ?WAIT -> ct:fail(no_restart)
    end,
    Third = toroco_pru_port:os_pid(S),
    ok = toroco_pru_port:set_servos(S, #{left => 20}),
    Tags = fun(Pid) -> [tag(R) || R <- requests(Root, fun(P) -> P =:= Pid end, any)] end,
    ct:pal("frames by program: ~p", [[{P, Tags(P)} || P <- [First, Second, Third]]]),
    ?assertEqual([configure_watchdog, configure_servos], Tags(Second)),
    ?assertEqual([neutral, enable_servos, set_servos],
                 [T || T <- Tags(Third), lists:member(T, [neutral, enable_servos, set_servos])]),
    ?assertEqual([configure_watchdog, configure_servos, neutral, enable_servos, configure_adc,
                  set_servos], Tags(Third)),
    ok = toroco_pru_port:stop(S).

hello_backoff(doc) ->
    ["Programs that never say hello are killed and retried after 50, 100, 200, 400, 400 ms "
     "(doubling, bounded), counted by info/1; the next one that says hello runs"];
hello_backoff(Config) ->
    S = start(Config, #{executable => withhold_exe(Config), servos => servos(),
                        hello_timeout_ms => 200, restart_backoff => {50, 400},
                        max_restarts => {1000, 60000}}),
    ok = toroco_pru_port:subscribe(S),
    ok = file:write_file(flag(Config), ""),
    T0 = erlang:monotonic_time(millisecond),
    kill(toroco_pru_port:os_pid(S)),
    {Delays, Info} = watch_backoff(S, 6, 30000),
    Elapsed = erlang:monotonic_time(millisecond) - T0,
    ct:pal("six hellos that never came: delays ~p ms, ~b ms in all, ~p", [Delays, Elapsed, Info]),
    %% 0: a program that ran is restarted at once
    ?assertEqual([0, 50, 100, 200, 400], Delays),
    ?assertMatch(#{state := connecting, hello_timeouts := 6, failed_starts := 6,
                   restarts := 7, backoff_ms := 400, failures := 6}, Info),
    %% six hello timeouts and the delays between them were waited
    ?assert(Elapsed >= 6 * 200 + 50 + 100 + 200 + 400 + 400),
    %% the program now waiting has seen the flag: it is killed at its hello
    %% timeout and the next one starts
    ok = wait_until(fun() -> case toroco_pru_port:info(S) of
                                 #{os_pid := P} when is_integer(P) -> withholding(Config, P);
                                 _ -> false
                             end
                    end, ?WAIT),
    ok = file:delete(flag(Config)),
    receive
        {toroco_pru_port, {port_restarted, Why}} -> ?assertEqual({exit_status, 137}, Why)
    after 4 * ?WAIT -> ct:fail(no_restart)
    end,
    ?assertMatch(#{state := running, failures := 0}, toroco_pru_port:info(S)),
    ok = toroco_pru_port:set_servos(S, #{left => 10}),
    ok = toroco_pru_port:stop(S).

first_start_without_hello(doc) ->
    ["A first program that never says hello: start_link's caller waits, the owner answers "
     "meanwhile, and start_link returns {error, {port_program, start_timeout}} with the program "
     "killed and the name free"];
first_start_without_hello(Config) ->
    ok = file:write_file(flag(Config), ""),
    Self = self(),
    Opts = #{name => hello_less, backend => sim, executable => withhold_exe(Config),
             sysfs_root => ?config(root, Config), servos => servos(), hello_timeout_ms => 1000},
    Starter = spawn(fun() -> Self ! {started, toroco_pru_port:start_link(Opts)} end),
    ok = wait_until(fun() -> is_pid(whereis(hello_less)) end, ?WAIT),
    #{state := connecting, os_pid := Sleeper} = toroco_pru_port:info(hello_less),
    T0 = erlang:monotonic_time(microsecond),
    ?assertEqual({error, {connecting, awaiting_hello}},
                 toroco_pru_port:set_servos(hello_less, #{left => 10})),
    ?assert(erlang:monotonic_time(microsecond) - T0 < 100000),
    receive
        {started, Result} ->
            ?assertEqual({error, {port_program, start_timeout}}, Result)
    after ?WAIT -> ct:fail(start_link_did_not_return)
    end,
    ?assertNot(is_process_alive(Starter)),
    ?assertEqual(undefined, whereis(hello_less)),
    ok = wait_until(fun() -> not filelib:is_dir("/proc/" ++ integer_to_list(Sleeper)) end, ?WAIT).

%%% ---------------------------------------------------------------------
%%% Performance
%%% ---------------------------------------------------------------------

round_trip(doc) ->
    ["Erlang -> port -> Erlang round trip over 10,000 frames, p50/p99 printed"];
round_trip(Config) ->
    S = start(Config, #{}),
    N = 10000,
    Times = lists:sort([begin
                            T0 = erlang:monotonic_time(microsecond),
                            pong = toroco_pru_port:ping(S),
                            erlang:monotonic_time(microsecond) - T0
                        end || _ <- lists:seq(1, N)]),
    P50 = lists:nth(N div 2, Times),
    P99 = lists:nth(N * 99 div 100, Times),
    ct:pal("pru_port round trip over ~b frames: p50 ~b us, p99 ~b us, max ~b us",
           [N, P50, P99, lists:last(Times)]),
    ?assert(P99 < 50000).

%%% ---------------------------------------------------------------------
%%% Helpers
%%% ---------------------------------------------------------------------

%% A start expected to be refused: the refusal is an exit of the linked
%% process, which must not take the test case with it.
start_link(Config, Opts) ->
    Trap = process_flag(trap_exit, true),
    Result = start_opts(Config, Opts),
    case Result of
        {error, _} -> receive {'EXIT', _, _} -> ok after ?WAIT -> ok end;
        {ok, _} -> ok
    end,
    process_flag(trap_exit, Trap),
    Result.

start_opts(Config, Opts) ->
    toroco_pru_port:start_link(maps:merge(#{backend => sim,
                                            executable => ?config(exe, Config),
                                            sysfs_root => ?config(root, Config)},
                                          Opts)).

%% Unlinked so that a refused start or a stop does not take the case down.
start(Config, Opts) ->
    {ok, S} = start_opts(Config, Opts),
    unlink(S),
    S.

servos() ->
    #{left => #{pwmchip => 0, channel => 0, period_ns => 20000000,
                neutral_ns => 1500000, span_ns => 500000},
      right => #{pwmchip => 0, channel => 1, period_ns => 20000000,
                 neutral_ns => 1500000, span_ns => 500000, reversed => true}}.

wire_left() ->
    {left, 0, 0, 20000000, 1500000, 500000, false}.

%% The ADC events in the mailbox now, oldest first.
adc_events() ->
    receive
        {toroco_pru_port, {adc, Ch, V, _T}} -> [{Ch, V} | adc_events()]
    after 0 -> []
    end.

button_events() ->
    receive
        {toroco_pru_port, {button, Edge, _T}} -> [Edge | button_events()]
    after 0 -> []
    end.

await_adc(Ch) ->
    receive
        {toroco_pru_port, {adc, Ch, V, _T}} -> V
    after ?WAIT -> ct:fail({no_adc_event, Ch})
    end.

raw_port(Config) ->
    P = open_port({spawn_executable, ?config(exe, Config)},
                  [{packet, 2}, binary, exit_status,
                   {args, ["--backend", "sim", "--sysfs-root", ?config(root, Config)]}]),
    {hello, 1, sim} = raw_recv(P),
    P.

raw_call(P, Term) ->
    true = port_command(P, term_to_binary(Term)),
    raw_recv(P).

raw_recv(P) ->
    receive
        {P, {data, Bin}} -> binary_to_term(Bin);
        {P, {exit_status, S}} -> ct:fail({port_exited, S})
    after ?WAIT -> ct:fail(no_reply)
    end.

%% A program that withholds its hello (sleeps 30 s, until killed) while
%% the case's flag file exists, and is the real program otherwise.
withhold_exe(Config) ->
    Exe = filename:join(?config(root, Config), "withhold.sh"),
    ok = file:write_file(Exe, ["#!/bin/sh\n",
                               "if [ -e '", flag(Config), "' ]; then\n",
                               "  : > '", flag(Config), ".withholding.'$$\n",
                               "  exec sleep 30\n",
                               "fi\n",
                               "exec '", ?config(exe, Config), "' \"$@\"\n"]),
    ok = file:change_mode(Exe, 8#755),
    Exe.

%% Whether the program with OS pid `OsPid' is withholding its hello (has
%% seen the flag): until then deleting the flag would let it start.
withholding(Config, OsPid) ->
    filelib:is_regular(flag(Config) ++ ".withholding." ++ integer_to_list(OsPid)).

flag(Config) ->
    filename:join(?config(root, Config), "no_hello").

kill(OsPid) ->
    "" = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    ok.

awaiting_hello(S, Old) ->
    case toroco_pru_port:info(S) of
        #{state := connecting, os_pid := P} -> is_integer(P) andalso P =/= Old;
        _ -> false
    end.

%% The distinct restart delays info/1 reports, in order, until N hello
%% timeouts are counted (within Timeout ms).
watch_backoff(S, N, Timeout) ->
    Step = fun(Seen) ->
                   Info = #{backoff_ms := Ms, hello_timeouts := H} = toroco_pru_port:info(S),
                   Seen1 = case Seen of
                               [Ms | _] -> Seen;
                               _ -> [Ms | Seen]
                           end,
                   case H >= N of
                       true -> {done, {lists:reverse(Seen1), Info}};
                       false -> {more, Seen1}
                   end
           end,
    toroco_test_lib:wait_fold(Step, [], Timeout, {hello_timeouts, N}).

%% The requests the fake program logged in Dir, of the programs Which
%% accepts, with tag Tag (or any).
requests(Dir, Which, Tag) ->
    Log = case file:consult(filename:join(Dir, "frames.log")) of
              {ok, Terms} -> Terms;
              {error, _} -> []
          end,
    [R || {P, {_Ref, R}} <- Log, Which(P), Tag =:= any orelse tag(R) =:= Tag].

other_than(Pid) ->
    fun(P) -> P =/= Pid end.

tag(T) when is_tuple(T) -> element(1, T);
tag(A) -> A.
