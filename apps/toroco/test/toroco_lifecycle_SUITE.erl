%% Lifecycle (SPEC §4): emitter death and restart, receiver restart,
%% suspend/resume, removal, router and gate restarts, and graceful degradation
%% when a layer crashes beyond its restart intensity.
-module(toroco_lifecycle_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [values/1, await_values/2, await_values/3, settle/1,
                          sensor/2, actuator/2, wait_until/2]).

suite() -> [{timetrap, {seconds, 30}}].

all() -> [emitter_death_releases_holds_and_latches, restarted_receiver_gets_latched_winner,
          suspend_drops_inputs_resume_redelivers, remove_strips_name_and_lower_takes_over,
          readding_does_not_reattach, router_restart_recovers_latches,
          gate_restart_recovers_inhibition, crashing_top_layer_is_taken_out,
          inspect_is_stable_at_rest, wiring_from_a_callback_does_not_deadlock,
          undeclared_output_is_logged_and_dropped].

init_per_testcase(crashing_top_layer_is_taken_out, Config) ->
    application:load(toroco),
    application:set_env(toroco, layer_restart_intensity, {3, 10}),
    toroco_test_lib:start(),
    Config;
init_per_testcase(_TC, Config) ->
    toroco_test_lib:start(),
    Config.

end_per_testcase(_TC, _Config) ->
    toroco_test_lib:stop(),
    application:unset_env(toroco, layer_restart_intensity).

kill(Name) ->
    Pid = whereis(toroco_names:process(Name)),
    exit(Pid, kill),
    wait_until(fun() -> case whereis(toroco_names:process(Name)) of
                            undefined -> false;
                            P -> P =/= Pid
                        end end, 3000).

emitter_death_releases_holds_and_latches() ->
    [{doc, "A crashed emitter's latches and holds go at once; lower layers take over; its new incarnation starts clean."}].
emitter_death_releases_holds_and_latches(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => fwd}}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:inject({hi, out}, stop, #{latch => true}),
    await_values(a, [fwd, stop]),
    kill(hi),
    await_values(a, [fwd, stop, fwd]),
    #{inputs := #{in := #{winner := {lo, out}, latches := [{{lo, out}, fwd}]}}} = toroco:inspect(a).

restarted_receiver_gets_latched_winner() ->
    [{doc, "A restarted behavior is re-delivered each input's latched winner, so it catches up."}].
restarted_receiver_gets_latched_winner(_) ->
    ok = toroco:add_behavior(src, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(mid, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(mid, #{in => [{src, out}]}),
    ok = toroco:set_inputs(a, #{in => [{mid, out}]}),
    ok = toroco:inject({src, out}, v1, #{latch => true}),
    await_values(a, [v1]),
    kill(mid),
    await_values(a, [v1, v1]).

suspend_drops_inputs_resume_redelivers() ->
    [{doc, "Inputs to a suspended behavior are dropped; resume re-delivers the latched winner."}].
suspend_drops_inputs_resume_redelivers(_) ->
    ok = toroco:add_behavior(src, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(mid, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(mid, #{in => [{src, out}]}),
    ok = toroco:set_inputs(a, #{in => [{mid, out}]}),
    ok = toroco:suspend_behavior(mid),
    #{status := suspended} = toroco:inspect(mid),
    ok = toroco:inject({src, out}, dropped),
    ok = toroco:inject({src, out}, kept, #{latch => true}),
    _ = toroco:inspect(mid), settle(a),
    [] = values(a),
    ok = toroco:resume_behavior(mid),
    await_values(a, [kept]),
    #{status := running} = toroco:inspect(mid).

remove_strips_name_and_lower_takes_over() ->
    [{doc, "remove_behavior ends its holds, strips it from every list, and stops routers left empty."}].
remove_strips_name_and_lower_takes_over(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => fwd}}),
    actuator(a, [in]),
    actuator(b, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:set_inputs(b, #{in => [{hi, out}]}),
    ok = toroco:inject({hi, out}, turn, #{latch => true}),
    await_values(a, [fwd, turn]),
    ok = toroco:remove_behavior(hi),
    await_values(a, [fwd, turn, fwd]),
    #{inputs := #{in := #{sources := [{lo, out}]}}} = toroco:inspect(a),
    #{inputs := #{in := #{sources := []}}} = toroco:inspect(b),
    undefined = whereis(toroco_names:router(b, in)),
    {error, {unknown_name, hi}} = toroco:inspect(hi).

readding_does_not_reattach() ->
    [{doc, "Adding a removed name again does not re-attach it: it must be wired again."}].
readding_does_not_reattach(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}]}),
    ok = toroco:remove_behavior(hi),
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:inject({hi, out}, lost),
    settle(a),
    [] = values(a),
    ok = toroco:set_inputs(a, #{in => [{hi, out}]}),
    ok = toroco:inject({hi, out}, found),
    await_values(a, [found]).

router_restart_recovers_latches() ->
    [{doc, "A killed router restarts, recovers latches from the emitters and re-delivers the winner."}].
router_restart_recovers_latches(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1, params => #{latch => high}}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => low}}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    await_values(a, [high]),
    Router = whereis(toroco_names:router(a, in)),
    exit(Router, kill),
    await_values(a, [high, high]),
    true = whereis(toroco_names:router(a, in)) =/= Router,
    #{inputs := #{in := #{winner := {hi, out}, latches := [{{hi, out}, high}, {{lo, out}, low}]}}} =
        toroco:inspect(a),
    ok = toroco:inject({hi, out}, x, #{hold => 0}),
    await_values(a, [high, high, x, low]).

gate_restart_recovers_inhibition() ->
    [{doc, "A killed gate restarts with the inhibition its latched inhibitor dictates."}].
gate_restart_recovers_inhibition(_) ->
    ok = toroco:add_behavior(e, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 1, params => #{latch => on}}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{e, out}]}),
    ok = toroco:set_inhibitors(e, #{out => [{i, out}]}),
    Gate = whereis(toroco_names:gate({e, out})),
    exit(Gate, kill),
    %% the new incarnation, not the old one still registered while it dies
    wait_until(fun() -> not lists:member(whereis(toroco_names:gate({e, out})), [undefined, Gate]) end,
               2000),
    #{outputs := #{out := #{inhibited := true}}} = toroco:inspect(e),
    ok = toroco:inject({e, out}, blocked),
    settle(a),
    [] = values(a).

crashing_top_layer_is_taken_out() ->
    [{doc, "A top layer crashing in a loop is restarted, then taken out; the actuator ends on the lower layer's latch."}].
crashing_top_layer_is_taken_out(_) ->
    ok = toroco:add_behavior(forward, tb_relay, #{layer => 0, params => #{latch => forward}}),
    ok = toroco:add_behavior(top, tb_crasher, #{layer => 2, params => #{value => top, after_ms => 30}}),
    actuator(motors, [in]),
    ok = toroco:set_inputs(motors, #{in => [{top, out}, {forward, out}]}),
    wait_until(fun() -> maps:get(removed_layers, toroco:inspect()) =:= [2] end, 5000),
    await_values(motors, [top, forward, top, forward, top, forward, top, forward], 2000),
    #{inputs := #{in := #{winner := {forward, out}}}} = toroco:inspect(motors),
    #{status := down} = toroco:inspect(top),
    #{status := running} = toroco:inspect(forward),
    ok = toroco:inject({forward, out}, still_here, #{latch => true}),
    await_values(motors, [top, forward, top, forward, top, forward, top, forward, still_here]).

inspect_is_stable_at_rest() ->
    [{doc, "With no events flowing and no timed holds, two inspect calls return equal maps."}].
inspect_is_stable_at_rest(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1, params => #{latch => high}}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:set_inhibitors(lo, #{out => [{hi, out}]}),
    await_values(a, [high]),
    A1 = toroco:inspect(a), A2 = toroco:inspect(a),
    A1 = A2,
    L1 = toroco:inspect(lo), L1 = toroco:inspect(lo),
    #{name := a, kind := device, module := toroco_fake_actuator, layer := 0, status := running,
      inputs := #{in := #{sources := [{hi, out}, {lo, out}], winner := {hi, out},
                          holds := [{{hi, out}, infinity}], latches := [{{hi, out}, high}],
                          last := {value, high}}},
      outputs := #{}} = A1,
    #{outputs := #{out := #{inhibited := true, inhibitors := [{hi, out}], latch := none}},
      inputs := #{in := #{sources := []}}} = L1,
    #{behaviors := [hi, lo], devices := [a], layers := #{0 := [lo], 1 := [hi]},
      removed_layers := []} = toroco:inspect().

wiring_from_a_callback_does_not_deadlock() ->
    [{doc, "A behavior that wires itself as a source from its own callback gets its latch delivered."}].
wiring_from_a_callback_does_not_deadlock(_) ->
    actuator(a, [in]),
    ok = toroco:add_behavior(self_wirer, tb_self_wirer, #{}),
    ok = toroco:inject({self_wirer, out}, go, #{latch => true}),
    sensor(s, [v]),
    ok = toroco:set_inputs(self_wirer, #{in => [{s, v}]}),
    ok = toroco:inject({s, v}, wire),
    await_values(a, [go]).

undeclared_output_is_logged_and_dropped() ->
    [{doc, "An emission on an undeclared output is dropped with a log; the behavior keeps running."}].
undeclared_output_is_logged_and_dropped(_) ->
    ok = toroco:add_behavior(b, tb_self_wirer, #{}),
    Pid = whereis(toroco_names:process(b)),
    ok = toroco:set_inputs(b, #{in => [{b, out}]}),
    ok = toroco:inject({b, out}, bogus),
    _ = toroco:inspect(b),
    Pid = whereis(toroco_names:process(b)),
    #{status := running} = toroco:inspect(b).
