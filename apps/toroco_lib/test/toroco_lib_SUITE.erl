%% The library's behaviors one by one, each between fake devices: a
%% `toroco_fake_sensor' drives its inputs and a `toroco_fake_actuator'
%% (`motors', its `setvel' idle value {0, 0}) records what reaches the
%% motors. Parameters are checked for every behavior of the catalogue.
%%
%% The behaviors run in lockstep (SPEC §14): each injected event is handled
%% to quiescence before the next, and waiting moves simulated time in 10 ms
%% steps, so a behavior's timeouts (a stall, a search, a stale command) are
%% measured in simulated milliseconds, not at the mercy of the machine's
%% load. Teleoperation over a real UDP socket runs in real time.
-module(toroco_lib_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [lockstep/0, settle/0, pass/1]).

suite() ->
    [{timetrap, {seconds, 60}}].

all() ->
    [{group, params}, {group, behaviors}, {group, links}].

groups() ->
    [{params, [], [unknown_param_refused, bad_values_refused, inconsistent_params_refused,
                   params_documented]},
     %% in lockstep (SPEC §14): each event handled before the next, time
     %% simulated, so the behaviors' timeouts are exact
     {behaviors, [], [cruise_latches_forward, wander_is_seeded, avoid_spins_away,
                      avoid_keeps_its_side, follow_wall_keeps_distance, follow_wall_searches,
                      escape_after_bump, escape_after_stall, seek_colour_steers,
                      dock_homes_and_stops, stale_stop_times_out, fear_and_love]},
     %% in real time: commands come over a real UDP socket
     {links, [], [teleop_overrides_from_link]}].

init_per_group(behaviors, Config) ->
    [{lockstep, true} | Config];
init_per_group(_, Config) ->
    Config.

end_per_group(_, _Config) ->
    ok.

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    case ?config(lockstep, Config) of
        true -> ok = toroco_clock:lockstep(#{});
        _ -> ok
    end,
    ok = toroco:add_device(sensor, toroco_fake_sensor,
                           #{outputs => [a, b, c, bump, command, odometry]}),
    ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [setvel]}),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = (catch toroco_clock:realtime()),
    toroco_test_lib:stop().

%%====================================================================
%% Parameters
%%====================================================================

unknown_param_refused() ->
    [{doc, "Every behavior refuses a parameter it does not have, naming it."}].
unknown_param_refused(_Config) ->
    [?assertEqual({error, {start_failed, {Name, {unknown_param, colour_of_sky}}}},
                  toroco:add_behavior(Name, M, #{params => #{colour_of_sky => blue}}))
     || {Name, M} <- toroco_lib:behaviors()].

bad_values_refused() ->
    [{doc, "Every parameter of every behavior refuses a value of the wrong kind at "
      "add_behavior, naming the parameter and the value; the defaults are accepted."}].
bad_values_refused(_Config) ->
    lists:foreach(
      fun(#{name := Name, module := M, params := Specs}) ->
              [begin
                   Bad = bad(Kind),
                   ?assertEqual({error, {start_failed, {Name, {bad_param, {P, Bad}}}}},
                                toroco:add_behavior(Name, M, #{params => #{P => Bad}}))
               end || {P, Kind, _} <- Specs, Kind =/= term],
              ok = toroco:add_behavior(Name, M, #{}),
              ok = toroco:remove_behavior(Name)
      end, toroco_lib:catalogue()).

inconsistent_params_refused() ->
    [{doc, "Parameters fine alone but not together are refused, naming the one that "
      "does not fit: a hysteresis below its threshold, an interval upside down."}].
inconsistent_params_refused(_Config) ->
    ?assertEqual({error, {start_failed, {avoid, {bad_param, {far, 0.1}}}}},
                 toroco:add_behavior(avoid, toroco_lib_avoid,
                                     #{params => #{near => 0.3, far => 0.1}})),
    ?assertEqual({error, {start_failed, {wander, {bad_param, {max_ms, 100}}}}},
                 toroco:add_behavior(wander, toroco_lib_wander,
                                     #{params => #{min_ms => 500, max_ms => 100}})),
    %% params that are not a map never reach init/1: the runtime refuses them
    ?assertEqual({error, {bad_params, {c, [{speed, 10}]}}},
                 toroco:add_behavior(c, toroco_lib_cruise, #{params => [{speed, 10}]})).

params_documented() ->
    [{doc, "Each behavior's module doc names its inputs, outputs and every parameter."}].
params_documented(_Config) ->
    lists:foreach(
      fun(#{module := M, params := Specs, inputs := Ins, outputs := Outs}) ->
              {ok, Source} = file:read_file(proplists:get_value(source, M:module_info(compile))),
              Doc = iolist_to_binary([L || L <- binary:split(Source, <<"\n">>, [global]),
                                           binary:match(L, <<"%%">>) =:= {0, 2}]),
              [?assertMatch({_, _}, binary:match(Doc, <<"`", (atom_to_binary(N))/binary>>),
                            {M, N})
               || N <- [P || {P, _, _} <- Specs] ++ Ins ++ Outs],
              ?assertMatch({_, _}, binary:match(Doc, <<"Usual layer">>), M)
      end, toroco_lib:catalogue()).

bad(speed) -> 250;
bad(pos_speed) -> -5;
bad(ms) -> 0;
bad(metres) -> -1.0;
bad(pos_number) -> 0;
bad(non_neg_number) -> -1;
bad(integer) -> 1.5;
bad(wheels) -> fast;
bad({one_of, _}) -> sideways.

%%====================================================================
%% Behaviors
%%====================================================================

cruise_latches_forward() ->
    [{doc, "cruise latches {Speed, Speed} at start; the motors get it when wired."}].
cruise_latches_forward(_Config) ->
    ok = toroco:add_behavior(cruise, toroco_lib_cruise, #{params => #{speed => 42}}),
    motors([cruise]),
    await([{42, 42}]).

wander_is_seeded() ->
    [{doc, "wander changes arcs on its timer within min_ms..max_ms, within the turn "
      "bound, and the same seed gives the same arcs."}].
wander_is_seeded(_Config) ->
    Params = #{speed => 50, turn => 30, min_ms => 60, max_ms => 120, seed => 42},
    First = wander_arcs(Params, 6),
    ?assertEqual([V || {V, _} <- First], [V || {V, _} <- wander_arcs(Params, 6)]),
    ?assertNotEqual([V || {V, _} <- First],
                    [V || {V, _} <- wander_arcs(Params#{seed => 43}, 6)]),
    [?assert(abs(L - 50) =< 30 andalso L + R =:= 100) || {{L, R}, _} <- First],
    Gaps = gaps([T || {_, T} <- First]),
    ct:log("wander intervals ~w ms", [Gaps]),
    [?assert(G >= 60 andalso G =< 120) || G <- Gaps].

wander_arcs(Params, N) ->
    ok = toroco_fake_actuator:clear(motors),
    ok = toroco:add_behavior(wander, toroco_lib_wander, #{params => Params}),
    motors([wander]),
    await_motors(fun(H) -> length(H) >= N end, fun() -> {fewer_than, N, values()} end),
    ok = toroco:remove_behavior(wander),
    %% its holder gone, the motors get the input's idle value: waited for,
    %% so that it lands in this run's history and not in the next one's
    await_last({0, 0}),
    [{V, T} || {setvel, V, T} <- lists:sublist(toroco_fake_actuator:history(motors), N)].

avoid_spins_away() ->
    [{doc, "avoid spins away from a near side with hysteresis (near at 0.25 m, far "
      "again beyond 0.32 m), and lets go when all is far; levels work as readings."}].
avoid_spins_away(_Config) ->
    ok = toroco:add_behavior(avoid, toroco_lib_avoid, #{params => #{spin => 40}}),
    wire(avoid, #{left => a, right => b, front => c}),
    motors([avoid]),
    send(a, 0.8), send(a, 0.2),
    await([{40, -40}]),
    send(a, 0.3),                              % within the hysteresis: still turning
    send(a, 0.5),
    await([{40, -40}, {0, 0}]),
    send(b, near),
    await([{40, -40}, {0, 0}, {-40, 40}]),
    send(b, far),
    await([{40, -40}, {0, 0}, {-40, 40}, {0, 0}]).

avoid_keeps_its_side() ->
    [{doc, "In a corner (the other side turns near too) avoid keeps the side it chose "
      "until both are far; something ahead alone turns to the preferred side."}].
avoid_keeps_its_side(_Config) ->
    ok = toroco:add_behavior(avoid, toroco_lib_avoid, #{params => #{prefer => right}}),
    wire(avoid, #{left => a, right => b, front => c}),
    motors([avoid]),
    send(b, 0.1),
    await_last({-50, 50}),
    send(a, 0.1), fed(avoid, left, 0.1),
    send(b, 1.0), fed(avoid, right, 1.0),
    send(a, 1.0),
    await([{-50, 50}, {0, 0}]),
    send(c, 0.1),
    await([{-50, 50}, {0, 0}, {50, -50}]).

follow_wall_keeps_distance() ->
    [{doc, "follow_wall turns towards a wall too far, away from one too near, goes "
      "straight at the set distance, and spins away from something ahead."}].
follow_wall_keeps_distance(_Config) ->
    ok = toroco:add_behavior(follow, toroco_lib_follow_wall,
                             #{params => #{side => right, distance => 0.25, speed => 60,
                                           gain => 100, heading_gain => 0}}),
    wire(follow, #{side => a, front => c}),
    motors([follow]),
    send(c, 1.5),
    send(a, 0.35),                             % 0.1 too far: turn right by 10
    await_last({70, 50}),
    send(a, 0.15),                             % 0.1 too near: turn left by 10
    await_last({50, 70}),
    send(a, 0.25),
    await_last({60, 60}),
    send(c, 0.2),
    await_last({-50, 50}),
    ok = toroco:add_behavior(left_follow, toroco_lib_follow_wall,
                             #{params => #{side => left, gain => 100, heading_gain => 0,
                                           speed => 60}}),
    wire(left_follow, #{side => b}),
    motors([left_follow]),
    send(b, 0.35),
    await_last({50, 70}).

follow_wall_searches() ->
    [{doc, "With no wall in reach follow_wall arcs towards its side, and after "
      "search_ms goes straight ahead to find one."}].
follow_wall_searches(_Config) ->
    ok = toroco:add_behavior(follow, toroco_lib_follow_wall,
                             #{params => #{speed => 60, search_turn => 20, search_ms => 300}}),
    wire(follow, #{side => a}),
    motors([follow]),
    send(a, 0.3),
    send(a, 1.2),
    {_, _, T0} = await_last({80, 40}),
    {_, _, T1} = await_last({60, 60}),
    ?assertEqual(300, T1 - T0).

escape_after_bump() ->
    [{doc, "A bump on the left backs up for back_ms, spins right for turn_ms, then lets "
      "go; a rear bump while backing starts the turn at once."}].
escape_after_bump(_Config) ->
    ok = toroco:add_behavior(escape, toroco_lib_escape,
                             #{params => #{back_ms => 300, turn_ms => 200, back_speed => 40,
                                           spin => 45}}),
    wire(escape, #{bump => bump}),
    motors([escape]),
    send(bump, left),
    {_, _, T} = await_last({0, 0}),
    [{_, {-40, -40}, T0}, {_, {45, -45}, T1}, {_, {0, 0}, T2}] =
        toroco_fake_actuator:history(motors),
    ?assertEqual({300, 200}, {T1 - T0, T2 - T1}),
    ?assertEqual(T2, T),
    ok = toroco_fake_actuator:clear(motors),
    send(bump, right),
    await_last({-40, -40}),
    send(bump, rear),
    {_, {-45, 45}, Tr} = await_last({-45, 45}),
    [{_, _, Tb} | _] = toroco_fake_actuator:history(motors),
    ?assertEqual(0, Tr - Tb).                  % at once, in the same simulated ms

escape_after_stall() ->
    [{doc, "Wheels commanded but not turning for stall_ms start an escape; wheels "
      "that turn, or a stall shorter than stall_ms, do not."}].
escape_after_stall(_Config) ->
    ok = toroco:add_behavior(escape, toroco_lib_escape,
                             #{params => #{stall_ms => 300, back_ms => 100, turn_ms => 100}}),
    wire(escape, #{command => command, odometry => odometry}),
    motors([escape]),
    send(command, {60, 60}),
    send(odometry, {58, 61}),
    send(odometry, {5, 0}),                    % stalled ...
    pass(150),
    send(odometry, {55, 60}),                  % ... but not for long
    pass(400),
    ?assertEqual([], toroco_fake_actuator:history(motors)),
    T0 = toroco_clock:now_ms(),                % the runtime's time, as the motors' stamps
    send(odometry, {0, 0}),
    {_, _, T1} = await_last({-50, -50}),
    ?assertEqual(300, T1 - T0),
    await_last({0, 0}).

seek_colour_steers() ->
    [{doc, "seek_colour steers towards the target in proportion to its x, clamped, "
      "and lets go when it is gone."}].
seek_colour_steers(_Config) ->
    ok = toroco:add_behavior(seek, toroco_lib_seek_colour,
                             #{params => #{speed => 50, gain => 0.5, max_turn => 30}}),
    wire(seek, #{target => a}),
    motors([seek]),
    send(a, {20, 0}),
    send(a, {20, 5}),                          % same command: nothing sent
    send(a, {-150, 0}),
    send(a, {0, 0}),
    send(a, none),
    await([{60, 40}, {20, 80}, {50, 50}, {0, 0}]).

dock_homes_and_stops() ->
    [{doc, "dock spins to a beacon far off the heading, steers to a near one, slows "
      "close to it, stops on the dock and stays until off it; no beacon lets go."}].
dock_homes_and_stops(_Config) ->
    ok = toroco:add_behavior(dock, toroco_lib_dock,
                             #{params => #{speed => 50, slow_speed => 20, gain => 1.0,
                                           spin => 30}}),
    wire(dock, #{beacon => a, docked => b}),
    motors([dock]),
    send(a, {90, 2.0}),
    send(a, {-10, 2.0}),
    send(a, {0, 0.3}),
    await_last({20, 20}),
    send(b, true),
    await_last({0, 0}),
    send(a, {5, 0.05}),                        % docked: the beacon changes nothing
    fed(dock, beacon, {5, 0.05}),
    send(b, false),
    await_last({15, 25}),
    send(a, none),
    await([{-30, 30}, {60, 40}, {20, 20}, {0, 0}, {15, 25}, {0, 0}]).

stale_stop_times_out() ->
    [{doc, "stale_stop passes commands on and puts the idle value after max_age_ms "
      "without one."}].
stale_stop_times_out(_Config) ->
    ok = toroco:add_behavior(stale, toroco_lib_stale_stop,
                             #{params => #{max_age_ms => 200, idle => {1, 1}}}),
    wire(stale, #{command => command}),
    motors([stale]),
    send(command, {70, 70}),
    pass(100),
    send(command, {60, 60}),
    {_, _, T0} = await_last({60, 60}),
    {_, _, T1} = await_last({1, 1}),
    ?assertEqual(200, T1 - T0),
    ?assertEqual([{70, 70}, {60, 60}, {1, 1}], values()).

teleop_overrides_from_link() ->
    [{doc, "Commands from a UDP link drive the motors over cruise while they come; "
      "when they stop, cruise is back after timeout_ms; stop hands back at once."}].
teleop_overrides_from_link(_Config) ->
    ok = toroco:add_device(link, toroco_udp_link, #{outputs => [cmd]}),
    #{device := #{port := Port}} = toroco:inspect(link),
    ok = toroco:add_behavior(cruise, toroco_lib_cruise, #{params => #{speed => 30}}),
    ok = toroco:add_behavior(teleop, toroco_lib_teleop,
                             #{layer => 5, params => #{timeout_ms => 300, max_speed => 80}}),
    ok = toroco:set_inputs(teleop, #{command => [{link, cmd}]}),
    motors([teleop, cruise]),
    await_last({30, 30}),
    {ok, Sock} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    Send = fun(Json) -> ok = gen_udp:send(Sock, {127, 0, 0, 1}, Port, Json) end,
    Send(<<"{\"output\":\"cmd\",\"value\":[90,-20]}">>),
    {_, _, T0} = await_last({80, -20}),
    {_, _, T1} = await_last({30, 30}),
    ?assert(T1 - T0 >= 250 andalso T1 - T0 =< 1000),
    Send(<<"{\"output\":\"cmd\",\"value\":{\"left\":10,\"right\":20}}">>),
    await_last({10, 20}),
    Send(<<"{\"output\":\"cmd\",\"value\":\"stop\"}">>),
    {_, _, T2} = await_last({30, 30}),
    [{_, {10, 20}, T3} | _] = lists:reverse(lists:droplast(toroco_fake_actuator:history(motors))),
    ?assert(T2 - T3 < 250),
    gen_udp:close(Sock).

fear_and_love() ->
    [{doc, "fear speeds each wheel by its own side's reading (turning away), love slows "
      "it (turning towards, resting at rest_level); both let go in the dark."}].
fear_and_love(_Config) ->
    ok = toroco:add_behavior(fear, toroco_lib_fear,
                             #{params => #{speed => 20, gain => 60, full_scale => 600,
                                           threshold => 50}}),
    wire(fear, #{left => a, right => b}),
    motors([fear]),
    send(b, 0), fed(fear, right, 0),
    send(a, 300),
    send(a, 10),
    await([{50, 20}, {0, 0}]),
    ok = toroco:remove_behavior(fear),
    ok = toroco_fake_actuator:clear(motors),
    ok = toroco:add_behavior(love, toroco_lib_love,
                             #{params => #{speed => 60, rest_level => 600, threshold => 50}}),
    wire(love, #{left => a, right => b}),
    motors([love]),
    send(a, 300),
    await_last({30, 60}),
    send(b, 150),
    await_last({30, 45}),
    send(a, 600),
    await_last({0, 45}),
    send(b, 600),
    await([{30, 60}, {30, 45}, {0, 45}, {0, 0}]).

%%====================================================================
%% Helpers
%%====================================================================

%% Inputs of `B' from the fake sensor's outputs.
wire(B, Inputs) ->
    ok = toroco:set_inputs(B, maps:map(fun(_In, Out) -> [{sensor, Out}] end, Inputs)).

motors(Sources) ->
    ok = toroco:set_inputs(motors, #{setvel => #{sources => [{S, motors} || S <- Sources],
                                                 idle => {0, 0}}}).

send(Out, V) ->
    ok = toroco:inject({sensor, Out}, V, #{latch => true}),
    settle().

%% Waits until `Holds(History)' of the motors, for at most 3 s of the
%% runtime's time: in lockstep simulated time moves in 10 ms steps, in real
%% time the actuator checks at each delivery. Fails with `Why()'.
await_motors(Holds, Why) ->
    case lockstep() of
        true -> toroco_test_lib:await_runtime(
                  fun() -> Holds(toroco_fake_actuator:history(motors)) end, 3000,
                  fun() -> ct:fail(Why()) end);
        false ->
            case toroco_fake_actuator:await(motors, Holds, 3000) of
                ok -> ok;
                {error, timeout} -> ct:fail(Why())
            end
    end.

%% Waits until behavior `B' has had `V' on input `In': events of different
%% sources may arrive in any order (SPEC §4), so a case that needs one
%% first waits for it (in lockstep it has: send/2 settles).
fed(B, In, V) ->
    toroco_test_lib:wait_until(fun() -> case toroco:inspect(B) of
                                            #{inputs := #{In := #{last := {value, V}}}} -> true;
                                            _ -> false
                                        end
                               end, 2000, {not_fed, B, In, V}).

values() ->
    [V || {_, V, _} <- toroco_fake_actuator:history(motors)].

await(Expected) ->
    await_motors(fun(H) -> [V || {_, V, _} <- H] =:= Expected end,
                 fun() -> {expected, Expected, got, values()} end).

%% Waits until the last delivery is `V'; that delivery.
await_last(V) ->
    await_motors(fun([]) -> false; (H) -> element(2, lists:last(H)) =:= V end,
                 fun() -> {expected_last, V, got, values()} end),
    lists:last(toroco_fake_actuator:history(motors)).

gaps([_]) -> [];
gaps([A, B | Rest]) -> [B - A | gaps([B | Rest])].
