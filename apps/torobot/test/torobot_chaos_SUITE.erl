%% The robustness lab (SPEC §17), in lockstep so every outcome is exact:
%% exits are steps (a crashing behavior's run is byte-identical twice),
%% each fault kind changes the trace as it should and no more, bad input
%% is refused before anything runs, and a planted weakness (an avoid that
%% forgets its turn when it restarts) is found, shrunk to one kill and
%% replayed, while the same wiring with the real avoid passes every run.
-module(torobot_chaos_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-define(DEFAULT_SHA, <<"4d84d42651fb04ff46209484d9f4f38c9a5175f4d0a70be75d2a4c7cb70b1851">>).

suite() ->
    [{timetrap, {minutes, 10}}].

all() ->
    [{group, exits}, {group, faults}, {group, bad_input}, {group, explore}].

groups() ->
    [{exits, [], [crashing_follower_is_exact, layer_out_in_simulated_time,
                    devices_out_in_simulated_time]},
     {faults, [], [no_fault_keeps_the_plain_trace, dropout_removes_readings,
                   stuck_repeats_the_reading, every_kind_changes_the_run, kill_restarts_in_place,
                   pru_port_restarts_in_place, lua_port_restarts_in_place,
                   runs_repeat_under_faults]},
     {bad_input, [], [bad_schedules_refused, bad_properties_refused, bad_files_name_the_line,
                      crashing_property_fails_its_run, properties_judge_observations]},
     {explore, [], [planted_weakness_found_shrunk_replayed, robust_wiring_passes]}].

init_per_suite(Config) ->
    logger:set_primary_config(level, error),
    Root = toroco_test_lib:root(),
    Old = application:get_env(torobot, wiring),
    ok = application:set_env(torobot, wiring, filename:join([Root, "config", "torobot.wiring"])),
    [{root, Root}, {old_wiring, Old}, {default, filename:join([Root, "config", "worlds", "default.world"])},
     {wiring, filename:join([Root, "config", "torobot.wiring"])} | Config].

end_per_suite(Config) ->
    logger:set_primary_config(level, notice),
    toroco_test_lib:restore_env(torobot, wiring, ?config(old_wiring, Config)).

init_per_group(explore, Config) ->
    %% the avoids crash often: their layer must not be taken out for it,
    %% so the weakness is the only thing the property can see (the worker
    %% peers take this node's environment); loaded first, or loading it
    %% would put the .app file's value back
    _ = application:load(toroco),
    {ok, Old} = application:get_env(toroco, layer_restart_intensity),
    ok = application:set_env(toroco, layer_restart_intensity, {1000, 1}),
    [{intensity, Old} | Config];
init_per_group(_, Config) ->
    Config.

end_per_group(explore, Config) ->
    ok = application:set_env(toroco, layer_restart_intensity, ?config(intensity, Config));
end_per_group(_, _Config) ->
    ok.

data(Config, File) -> filename:join(?config(data_dir, Config), File).

%%====================================================================
%% Exits are steps
%%====================================================================

crashing_follower_is_exact() ->
    [{doc, "A red_follower that crashes every 2 s of simulated time: its exits, restarts "
      "and its layer taken out are steps, so two runs give byte-identical traces that "
      "show each of them."}].
crashing_follower_is_exact(Config) ->
    Wiring = swapped(red_follower, torobot_crashing_follower, Config),
    World = filename:join([?config(root, Config), "test", "worlds", "red_crashing.world"]),
    [{A, TA}, {B, TB}] = [traced(World, Wiring, Tag, Config) || Tag <- ["a", "b"]],
    ?assertEqual(A, B),
    ?assertEqual(sha(TA), sha(TB)),
    Lines = binary:split(TA, <<"\n">>, [global]),
    Exits = [L || L <- Lines, binary:match(L, <<"red_follower exit red_follower_crash_test">>) =/= nomatch],
    Restarts = [L || L <- Lines, binary:match(L, <<"red_follower restarted">>) =/= nomatch],
    %% six crashes in 12 s: the sixth restart is one more than 5 in 10 s
    ?assertEqual(6, length(Exits)),
    ?assertEqual(6, length(Restarts)),
    ?assertEqual([<<"12000 layer 4 out">>], [L || L <- Lines, binary:match(L, <<"layer 4 out">>) =/= nomatch]),
    ?assertEqual(0, maps:get(wall_contacts, A)).

layer_out_in_simulated_time() ->
    [{doc, "Restart intensity counts simulated time: kills 3 s apart (fewer than 5 in 10 s) "
      "never take the layer out; six within 1 s do, at the sixth."}].
layer_out_in_simulated_time(Config) ->
    Spread = [{at, 1000 + 3000 * I, {kill, avoid_left}} || I <- lists:seq(0, 9)],
    Burst = [{at, 1000 + 100 * I, {kill, avoid_left}} || I <- lists:seq(0, 5)],
    {ok, #{sha256 := _}} = run_traced(#{faults => Spread}, "spread", Config),
    Spreaded = trace_lines("spread", Config),
    ?assertEqual([], [L || L <- Spreaded, binary:match(L, <<"layer 1 out">>) =/= nomatch]),
    ?assertEqual(10, length([L || L <- Spreaded, binary:match(L, <<"avoid_left restarted">>) =/= nomatch])),
    {ok, _} = run_traced(#{faults => Burst}, "burst", Config),
    ?assertEqual([<<"1500 layer 1 out">>],
                 [L || L <- trace_lines("burst", Config), binary:match(L, <<"layer 1 out">>) =/= nomatch]).

devices_out_in_simulated_time() ->
    [{doc, "The devices' restart intensity counts simulated time too: with 3 restarts in "
      "10 s allowed, a device killed 4 s apart keeps coming back; four kills within "
      "0.3 s take the devices out at the fourth, and the run is the same twice."}].
devices_out_in_simulated_time(Config) ->
    Old = application:get_env(toroco, device_restart_intensity),
    ok = application:set_env(toroco, device_restart_intensity, {3, 10}),
    try
        Spread = [{at, 1000 + 4000 * I, {kill, bumper}} || I <- lists:seq(0, 7)],
        Burst = [{at, 1000 + 100 * I, {kill, bumper}} || I <- lists:seq(0, 3)],
        {ok, _} = run_traced(#{faults => Spread}, "dspread", Config),
        Spreaded = trace_lines("dspread", Config),
        ?assertEqual([], matching(<<"devices out">>, Spreaded)),
        ?assertEqual(8, length(matching(<<"bumper restarted">>, Spreaded))),
        {ok, #{sha256 := A}} = run_traced(#{faults => Burst}, "dburst", Config),
        {ok, #{sha256 := B}} = run_traced(#{faults => Burst}, "dburst2", Config),
        ?assertEqual(A, B),
        ?assertEqual([<<"1300 devices out">>], matching(<<"devices out">>, trace_lines("dburst", Config)))
    after
        toroco_test_lib:restore_env(toroco, device_restart_intensity, Old)
    end.

matching(Pattern, Lines) ->
    [L || L <- Lines, binary:match(L, Pattern) =/= nomatch].

%%====================================================================
%% Faults
%%====================================================================

no_fault_keeps_the_plain_trace() ->
    [{doc, "Without faults, at rate 0 and with noise of sigma 0 the default world's "
      "trace keeps its SHA-256."}].
no_fault_keeps_the_plain_trace(Config) ->
    [?assertMatch({ok, #{sha256 := ?DEFAULT_SHA, violation := none}},
                  torobot_chaos:run(#{world => ?config(default, Config), faults => F}))
     || F <- [[], [{rate, 0, {kill, any}}],
              [{at, 0, {noise, {ir, left}, 0, 60000}}, {at, 500, {noise, range, 0, 30000}}]]].

dropout_removes_readings() ->
    [{doc, "A dropout of the left IR sensor from 10 s to 20 s removes exactly its "
      "readings then: the right sensor's and the left's outside the window are as "
      "without the fault until the run parts."}].
dropout_removes_readings(Config) ->
    {ok, _} = run_traced(#{faults => [{at, 10000, {dropout, {ir, left}, 10000}}]}, "drop", Config),
    {ok, _} = run_traced(#{faults => []}, "plain", Config),
    Left = fun(Tag) -> [T || {T, L} <- samples(Tag, Config), L =:= left] end,
    ?assertEqual([], [T || T <- Left("drop"), T >= 10000, T < 20000]),
    ?assert(length([T || T <- Left("plain"), T >= 10000, T < 20000]) > 0),
    ?assertEqual([T || T <- Left("plain"), T < 10000], [T || T <- Left("drop"), T < 10000]).

stuck_repeats_the_reading() ->
    [{doc, "A stuck right IR sensor repeats its last reading: from its start no reading "
      "of it reaches the robot (only changes are sent), and the left sensor's still do."}].
stuck_repeats_the_reading(Config) ->
    {ok, _} = run_traced(#{faults => [{at, 0, {stuck, {ir, right}, 60000}}]}, "stuck", Config),
    Samples = samples("stuck", Config),
    ?assertEqual([0], [T || {T, right} <- Samples]),
    ?assert(length([T || {T, left} <- Samples]) > 1).

every_kind_changes_the_run() ->
    [{doc, "Each fault kind, applied for 10 s from 31 s (red in view), changes the run's trace (each "
      "acts), and each run of it is the same twice."}].
every_kind_changes_the_run(Config) ->
    Kinds = [{kill, avoid_left}, {kill, router, {motors, setvel}}, {kill, camera},
             {suspend, trq_ignore, 10000}, {dropout, camera, 10000}, {stuck, camera, 10000},
             {noise, ir, 80, 10000}, {noise, range, 0.1, 10000}, {camera, loss, 0.5, 10000},
             {camera, delay, 200, 10000}, {slip, left, 0.5, 10000}],
    [begin
         Faults = [{at, 31000, K}],
         {ok, #{sha256 := A}} = torobot_chaos:run(#{world => ?config(default, Config), faults => Faults}),
         {ok, #{sha256 := B}} = torobot_chaos:run(#{world => ?config(default, Config), faults => Faults}),
         ?assertEqual({K, A}, {K, B}),
         ?assertNotEqual({K, ?DEFAULT_SHA}, {K, A})
     end || K <- Kinds].

kill_restarts_in_place() ->
    [{doc, "A killed behavior is restarted at the simulated instant of the kill: the trace "
      "shows the kill, the exit and the restart at that millisecond."}].
kill_restarts_in_place(Config) ->
    {ok, _} = run_traced(#{faults => [{at, 7321, {kill, hold_left}}]}, "kill", Config),
    Lines = [L || L <- trace_lines("kill", Config), binary:match(L, <<"hold_left">>) =/= nomatch,
                  binary:match(L, <<"7321 ">>) =:= {0, 5}],
    ?assertMatch([<<"7321 fault kill hold_left">>, <<"7321 hold_left exit killed">>,
                  <<"7321 hold_left restarted">> | _], Lines).

runs_repeat_under_faults() ->
    [{doc, "Runs of the default world with mixed faults (kills, suspends, sensors, camera, "
      "wheels) at 1 per simulated second repeat byte for byte, seed after seed."}].
runs_repeat_under_faults(Config) ->
    Mixed = filename:join([?config(root, Config), "config", "faults", "mixed.faults"]),
    {ok, Schedule} = torobot_faults:read(Mixed, element(2, torobot_chaos:names(?config(wiring, Config)))),
    Fast = [case E of {rate, R, S} -> {rate, R * 5, S}; _ -> E end || E <- Schedule],
    [begin
         Run = fun() -> torobot_chaos:run(#{world => ?config(default, Config), faults => Fast,
                                            seed => Seed}) end,
         {ok, #{sha256 := A, faults := F}} = Run(),
         {ok, #{sha256 := B}} = Run(),
         ?assert(length(F) > 10),
         ?assertEqual({Seed, A}, {Seed, B})
     end || Seed <- [1, 2, 3]].

%%====================================================================
%% Bad input
%%====================================================================

bad_schedules_refused() ->
    [{doc, "An unknown fault kind, a name the wiring lacks, a negative or non-numeric time, "
      "a bad duration are refused before anything runs, naming the culprit."}].
bad_schedules_refused(Config) ->
    Run = fun(F) -> torobot_chaos:run(#{world => ?config(default, Config), faults => F}) end,
    ?assertMatch({error, {unknown_fault, {at, 1, {explode, forward}}}}, Run([{at, 1, {explode, forward}}])),
    ?assertMatch({error, {unknown_name, {nobody, _}}}, Run([{at, 1, {kill, nobody}}])),
    ?assertMatch({error, {unknown_input, {{motors, fly}, _}}}, Run([{at, 1, {kill, router, {motors, fly}}}])),
    ?assertMatch({error, {bad_time, _}}, Run([{at, -5, {kill, forward}}])),
    ?assertMatch({error, {bad_time, _}}, Run([{at, soon, {kill, forward}}])),
    ?assertMatch({error, {bad_duration, _}}, Run([{at, 5, {dropout, camera, -1}}])),
    ?assertMatch({error, {unknown_sensor, _}}, Run([{at, 5, {dropout, sonar, 10}}])),
    ?assertMatch({error, {bad_rate, _}}, Run([{rate, fast, {kill, any}}])),
    %% a node the wiring does not place anything on, and the world's own
    ?assertMatch({error, {unknown_node, {'laptop@h', _}}}, Run([{at, 5, {disconnect, 'laptop@h', 100}}])),
    ?assertMatch({error, {unknown_node, {'laptop@h', _}}}, Run([{at, 5, {kill_node, 'laptop@h'}}])),
    Own = node(),
    ?assertMatch({error, {own_node, {Own, _}}}, Run([{at, 5, {disconnect, Own, 100}}])),
    ?assertMatch({error, {world, _}}, torobot_chaos:run(#{world => "no/such.world"})),
    HeadOn = filename:join([?config(root, Config), "test", "worlds", "head_on.world"]),
    ?assertEqual({error, {world, several_robots}}, torobot_chaos:run(#{world => HeadOn})).

bad_properties_refused() ->
    [{doc, "An unknown condition or a malformed property is refused before anything runs."}].
bad_properties_refused(Config) ->
    Run = fun(P) -> torobot_chaos:run(#{world => ?config(default, Config), property => P}) end,
    ?assertEqual({error, {unknown_condition, flying}}, Run({never, flying})),
    ?assertEqual({error, {unknown_condition, {winner, motors, 3}}}, Run({within, 100, {winner, motors, 3}})),
    ?assertMatch({error, {bad_property, {sometimes, red_touched}}}, Run({sometimes, red_touched})),
    ?assertMatch({error, {bad_time, _}}, Run({within, -1, red_touched})).

bad_files_name_the_line() ->
    [{doc, "Errors in fault and property files name File:Line; a malformed file too."}].
bad_files_name_the_line(Config) ->
    Dir = ?config(priv_dir, Config),
    Faults = filename:join(Dir, "bad.faults"),
    ok = file:write_file(Faults, "{at, 100, {kill, forward}}.\n\n{at, 200,\n {kill, ghost}}.\n"),
    Line3 = Faults ++ ":3",
    ?assertMatch({error, {unknown_name, {Line3, _}}},
                 torobot_chaos:run(#{world => ?config(default, Config), faults => Faults})),
    Broken = filename:join(Dir, "broken.faults"),
    ok = file:write_file(Broken, "{at, 100, {kill, forward}}.\n{at, 200, \n"),
    ?assertMatch({error, {malformed, {_, _}}},
                 torobot_chaos:run(#{world => ?config(default, Config), faults => Broken})),
    Props = filename:join(Dir, "bad.props"),
    ok = file:write_file(Props, "{never, wall_contact}.\n{never, lava}.\n"),
    Line2 = Props ++ ":2",
    ?assertMatch({error, {unknown_condition, {Line2, lava}}},
                 torobot_chaos:run(#{world => ?config(default, Config), property => Props})).

crashing_property_fails_its_run() ->
    [{doc, "A property fun that crashes fails that run with the crash as its reason."}].
crashing_property_fails_its_run(Config) ->
    ?assertMatch({ok, #{violation := {{crash, {error, badarith}}, 0}}},
                 torobot_chaos:run(#{world => ?config(default, Config),
                                     property => fun(Obs) -> length(Obs) / 0 end})).

properties_judge_observations() ->
    [{doc, "The property clauses on a hand-made run: never, within (with a figure of the "
      "summary), always_after and and, each violated where it should be."}].
properties_judge_observations(_Config) ->
    Obs = [#{t => T, wall => T =:= 300, blue => false, red => false, dist => 0.5,
             winner => case T >= 200 of true -> escape; false -> forward end,
             motors => {0, 0}, events => [],
             figures => #{docked_ms => case T >= 250 of true -> 250; false -> none end}}
           || T <- [0, 50, 100, 150, 200, 250, 300, 350, 400]],
    V = fun(P) -> torobot_props:violation(P, Obs, #{}) end,
    ?assertEqual({{never, wall_contact}, 300}, V({never, wall_contact})),
    ?assertEqual(none, V({within, 300, {figure, docked_ms}})),
    ?assertEqual({{within, 200, {figure, docked_ms}}, 200}, V({within, 200, {figure, docked_ms}})),
    ?assertEqual(none, V({always_after, wall_contact, 50, {winner, motors, escape}})),
    ?assertEqual({{always_after, wall_contact, 50, {winner, motors, forward}}, 350},
                 V({always_after, wall_contact, 50, {winner, motors, forward}})),
    ?assertEqual({{never, wall_contact}, 300},
                 V({'and', [{within, 400, red_touched}, {never, wall_contact}]})),
    ?assertEqual(ok, torobot_props:check({within, 1, {figure, docked_ms}})).

%%====================================================================
%% Exploring
%%====================================================================

planted_weakness_found_shrunk_replayed() ->
    [{doc, "An avoid that loses its turn when it restarts during one: explore finds it "
      "within 200 runs at one crash a second, no failing run differs when re-run, the "
      "first failure shrinks to one kill of an avoid, and its replay file gives the same "
      "SHA-256 and violation."}].
planted_weakness_found_shrunk_replayed(Config) ->
    {ok, R} = explore("fragile.wiring", 200, Config),
    #{failed := Failed, nondeterministic := Nondet, passed := Passed} = R,
    ct:log("fragile: ~b passed, ~b failed", [Passed, length(Failed)]),
    ?assertEqual([], Nondet),
    ?assert(length(Failed) > 0),
    [#{shrunk := #{faults := [{at, _, {kill, Avoid}}], violation := V, sha256 := Sha,
                   replay := Replay, lines := [Line]}} | _] = Failed,
    ct:log("shrunk to ~s, ~p", [Line, V]),
    ?assert(lists:member(Avoid, [avoid_left, avoid_right])),
    ?assertMatch({{never, wall_contact}, _}, V),
    ?assertMatch({ok, #{sha256 := Sha, violation := V}}, torobot_chaos:replay(Replay)).

robust_wiring_passes() ->
    [{doc, "The same wiring with the real avoid, which takes its turn back from the "
      "router's redelivery when it restarts, passes all 200 runs."}].
robust_wiring_passes(Config) ->
    {ok, R} = explore("box.wiring", 200, Config),
    ?assertMatch(#{runs := 200, passed := 200, failed := [], nondeterministic := []}, R).

explore(Wiring, Runs, Config) ->
    torobot_chaos:explore(#{worlds => [data(Config, "box.world")],
                            wiring => data(Config, Wiring),
                            faults => data(Config, "avoid_kills.faults"),
                            property => data(Config, "no_wall.props"),
                            runs => Runs, seed => 1, shrink => 1,
                            dir => ?config(priv_dir, Config)}).

%%====================================================================
%% Helpers
%%====================================================================

run_traced(Opts, Tag, Config) ->
    torobot_chaos:run(Opts#{world => maps:get(world, Opts, ?config(default, Config)),
                            trace => filename:join(?config(priv_dir, Config), Tag ++ ".trace")}).

trace_lines(Tag, Config) ->
    {ok, Bin} = file:read_file(filename:join(?config(priv_dir, Config), Tag ++ ".trace")),
    binary:split(Bin, <<"\n">>, [global, trim]).

pru_port_restarts_in_place() ->
    [{doc, "A killed pru_port program is started again at the simulated instant of the kill: "
      "its devices are told as steps there, the motors stop and take the latched command "
      "again, and the run is the same twice."}].
pru_port_restarts_in_place(Config) ->
    Faults = [{at, 7321, {kill, port, pru_port}}],
    {ok, #{sha256 := A}} = run_traced(#{faults => Faults}, "pru", Config),
    {ok, #{sha256 := B}} = run_traced(#{faults => Faults}, "pru2", Config),
    ?assertEqual(A, B),
    ?assertNotEqual(?DEFAULT_SHA, A),
    At = [L || L <- trace_lines("pru", Config), binary:match(L, <<"7321 ">>) =:= {0, 5}],
    Restarted = <<"notice {toroco_pru_port,{port_restarted,{exit_status,137}}}">>,
    ?assertMatch([<<"7321 fault kill port pru_port">>, <<"7321 toroco:ir ", _/binary>> | _], At),
    ?assertEqual([<<"toroco:ir">>, <<"toroco:motors">>, <<"toroco:push">>],
                 [hd(binary:split(Rest, <<" ">>)) || <<"7321 ", Rest/binary>> <- At,
                                                     binary:match(Rest, Restarted) =/= nomatch]),
    ?assert(lists:member(<<"7321 toroco:wheels deliver applied {0,0}">>, At)),
    ?assert(lists:member(<<"7321 toroco:wheels deliver applied {80,80}">>, At)).

lua_port_restarts_in_place() ->
    [{doc, "A killed lua_port program is started again at the simulated instant of the kill: "
      "the Lua behavior is told as a step there and its new state latches its command "
      "again; the run is the same twice; lua_port is refused for a wiring without Lua."}].
lua_port_restarts_in_place(Config) ->
    {ok, _} = application:ensure_all_started(toroco_lua),
    Wiring = filename:join(?config(priv_dir, Config), "lua_forward.wiring"),
    Lua = filename:join(?config(data_dir, Config), "forward.lua"),
    ok = file:write_file(Wiring, [io_lib:format("~tp.~n", [T]) || T <- lua_forward(Lua)]),
    Faults = [{at, 7321, {kill, port, lua_port}}],
    Run = fun(Tag) -> run_traced(#{wiring => Wiring, faults => Faults}, Tag, Config) end,
    {ok, #{sha256 := A}} = Run("lua"),
    {ok, #{sha256 := B}} = Run("lua2"),
    ?assertEqual(A, B),
    At = [L || L <- trace_lines("lua", Config), binary:match(L, <<"7321 ">>) =:= {0, 5}],
    ?assertMatch([<<"7321 fault kill port lua_port">>,
                  <<"7321 toroco:forward notice {toroco_lua_port,down,{exit_status,137}}">> | _], At),
    ?assert(lists:member(<<"7321 toroco:motors/setvel emit forward.motors unset">>, At)
            orelse lists:any(fun(L) -> binary:match(L, <<"forward.motors unset">>) =/= nomatch end, At)),
    ?assert(lists:any(fun(L) -> binary:match(L, <<"forward.motors set {80,80}">>) =/= nomatch end, At)),
    ?assertMatch({error, {unknown_port, {lua_port, _}}},
                 torobot_chaos:run(#{world => ?config(default, Config), faults => Faults})).

lua_forward(Lua) ->
    [{behavior, forward, toroco_lua, #{layer => 0, file => Lua}},
     {behavior, button, torobot_button, #{layer => 0, params => #{enabled => false}}},
     {inputs, button, #{press => [{push, button}]}},
     {inputs, motors, #{setvel => #{sources => [{forward, motors}], idle => {0, 0}},
                        enable => [{button, enable}]}}].

%% The IR samples handed to the robot: {Time, Side}.
samples(Tag, Config) ->
    [{binary_to_integer(T), binary_to_atom(Side)}
     || L <- trace_lines(Tag, Config),
        [T, <<"toroco:ir">>, <<"stimulus">>, <<"{toroco_pru_sensors,sample,", Rest/binary>>]
            <- [binary:split(L, <<" ">>, [global])],
        [Side | _] <- [binary:split(Rest, <<",">>)]].

traced(World, Wiring, Tag, Config) ->
    Trace = filename:join(?config(priv_dir, Config), "crashing_" ++ Tag ++ ".trace"),
    {ok, Summary} = torobot_sim:run(World, #{time => lockstep, wiring => Wiring, trace => Trace}),
    {ok, Bin} = file:read_file(Trace),
    {Summary, Bin}.

swapped(Name, Module, Config) ->
    {ok, Terms} = file:consult(?config(wiring, Config)),
    File = filename:join(?config(priv_dir, Config), atom_to_list(Module) ++ ".wiring"),
    ok = file:write_file(File, [io_lib:format("~tp.~n", [case T of
                                                          {behavior, Name, _, O} -> {behavior, Name, Module, O};
                                                          _ -> T
                                                      end]) || T <- Terms]),
    File.

sha(Bin) -> binary:encode_hex(crypto:hash(sha256, Bin)).
