%% Runs the properties of `prop_router': the router and gate cores against the
%% brute-force oracles of SPEC §4, and the running processes against a model
%% built from those oracles; and those of `prop_tap_batch': a producer's tap
%% batch against a model of what it keeps and drops (SPEC §10). A case fails when its property fails; the shrunk
%% counterexample and the disagreement are in the case's log.
-module(prop_SUITE).

-include_lib("common_test/include/ct.hrl").

-export([all/0, suite/0, init_per_suite/1, end_per_suite/1,
         init_per_testcase/2, end_per_testcase/2]).
-export([router_core_matches_oracle/0, router_core_matches_oracle/1,
         gate_core_matches_oracle/0, gate_core_matches_oracle/1,
         gate_core_untimed_matches_oracle/0, gate_core_untimed_matches_oracle/1,
         network_matches_model/0, network_matches_model/1,
         gate_attach_keeps_send_hold/0, gate_attach_keeps_send_hold/1,
         activation_stamp_keeps_order/0, activation_stamp_keeps_order/1,
         tap_batch_keeps_order/0, tap_batch_keeps_order/1,
         tap_batch_counts_exactly/0, tap_batch_counts_exactly/1]).

suite() -> [{timetrap, {minutes, 10}}].

all() ->
    [router_core_matches_oracle, gate_core_matches_oracle, gate_core_untimed_matches_oracle,
     network_matches_model, gate_attach_keeps_send_hold, activation_stamp_keeps_order,
     tap_batch_keeps_order, tap_batch_counts_exactly].

%% The network property lifts the restart intensities (its kills are
%% commands, not faults): what they were comes back at the end, so that the
%% suites after this one in the same node take layers out as configured.
-define(INTENSITIES, [layer_restart_intensity, device_restart_intensity]).

init_per_suite(Config) ->
    _ = application:load(toroco),
    [{intensities, [{K, application:get_env(toroco, K)} || K <- ?INTENSITIES]} | Config].

end_per_suite(Config) ->
    toroco_test_lib:stop(),
    [toroco_test_lib:restore_env(toroco, K, Was)
     || {K, Was} <- proplists:get_value(intensities, Config)],
    ok.

init_per_testcase(_Case, Config) ->
    _ = ets:new(prop_router_counts, [named_table, public]),
    _ = ets:new(prop_output, [named_table, public, ordered_set]),
    %% Kills are commands of the network property: their supervisor reports
    %% would bury everything else in the log.
    ok = logger:add_primary_filter(prop_killed, {fun quiet_kills/2, []}),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = logger:remove_primary_filter(prop_killed),
    ets:delete(prop_router_counts),
    ets:delete(prop_output),
    toroco_test_lib:stop().

quiet_kills(#{msg := {report, #{label := {supervisor, child_terminated}, report := R}}}, _) ->
    case proplists:get_value(reason, R) of
        killed -> stop;
        _ -> ignore
    end;
quiet_kills(_Event, _) ->
    ignore.

%%====================================================================
%% Cases
%%====================================================================

router_core_matches_oracle() ->
    [{doc, "toroco_router_core delivers, reports and schedules exactly as the suppression "
           "oracle recomputes from the whole history (2000 random event sequences)."}].
router_core_matches_oracle(_Config) ->
    check(prop_router:prop_router_core(), 2000, 100).

gate_core_matches_oracle() ->
    [{doc, "toroco_gate_core, ticked at its deadlines, forwards and reports exactly what "
           "the inhibition oracle says, timed holds included (1000 random sequences)."}].
gate_core_matches_oracle(_Config) ->
    check(prop_router:prop_gate_core(), 1000, 100).

gate_core_untimed_matches_oracle() ->
    [{doc, "The same with holds of 0 or infinity only: inhibition by set, unset and "
           "pairs, with no timer in the way (1000 random sequences)."}].
gate_core_untimed_matches_oracle(_Config) ->
    check(prop_router:prop_gate_core_untimed(), 1000, 100).

network_matches_model() ->
    [{doc, "Running networks (emitters in layers, a fake actuator, an inhibitor or a "
           "mutual pair) deliver, hold, latch and inhibit as the model says after every "
           "command of 500 random command sequences, timed inhibitor holds expiring."}].
network_matches_model(_Config) ->
    check(prop_router:prop_network(), 500, 60).

gate_attach_keeps_send_hold() ->
    [{doc, "Attaching an inhibitor that does not hold leaves the member's send hold at "
           "its routers (found by the network property; SPEC §4: a re-wired router keeps "
           "the holds of the sources that stay, and only inhibition ends them)."}].
gate_attach_keeps_send_hold(_Config) ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok = toroco:add_behavior(hi, prop_emitter, #{layer => 1}),
    ok = toroco:add_behavior(lo, prop_emitter, #{layer => 0}),
    ok = toroco:add_behavior(inh, prop_emitter, #{layer => 1}),
    ok = toroco:add_device(act, toroco_fake_actuator, #{inputs => [in]}),
    ok = toroco:set_inputs(act, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:inject({lo, out}, l, #{latch => true}),
    ok = toroco:inject({hi, out}, h, #{hold => infinity}),
    #{inputs := #{in := #{winner := {hi, out}}}} = toroco:inspect(act),
    ok = toroco:set_inhibitors(hi, #{out => [{inh, out}]}),
    #{inputs := #{in := In}} = toroco:inspect(act),
    Values = [V || {_, V, _} <- toroco_fake_actuator:history(act)],
    case {maps:get(winner, In), Values} of
        {{hi, out}, [l, h]} -> ok;
        Other -> ct:fail({send_hold_dropped_by_set_inhibitors,
                          #{winner_and_history => Other, input => In}})
    end.

activation_stamp_keeps_order() ->
    [{doc, "The emit events of one activation carry one time stamp and reach a subscriber "
           "in the order the callback returned its actions, while another emitter's "
           "activations run at once (200 random runs, SPEC §10)."}].
activation_stamp_keeps_order(_Config) ->
    ok = prop_tap:setup(),
    check(prop_tap:prop_activation_order(), 200, 20).

tap_batch_keeps_order() ->
    [{doc, "A producer's tap batch sends each subscription the events the model keeps, "
           "in the order they were tapped (1000 random sequences over three subscriptions)."}].
tap_batch_keeps_order(_Config) ->
    check(prop_tap_batch:prop_order(), 1000, 100).

tap_batch_counts_exactly() ->
    [{doc, "Every event tapped is kept or counted as dropped once, the drops are the "
           "model's, and the room a part gives back is what it took and did not use "
           "(1000 random sequences)."}].
tap_batch_counts_exactly(_Config) ->
    check(prop_tap_batch:prop_counts(), 1000, 100).

%%====================================================================
%% Running a property
%%====================================================================

check(Prop, NumTests, MaxSize) ->
    T0 = erlang:monotonic_time(millisecond),
    Result = proper:quickcheck(Prop, [{numtests, NumTests}, {max_size, MaxSize},
                                      {on_output, fun buffer/2}]),
    Ms = erlang:monotonic_time(millisecond) - T0,
    ct:log("~ts", [[Text || {_, Text} <- ets:tab2list(prop_output)]]),
    case Result of
        true ->
            ct:pal("passed ~p cases in ~p ms~ts", [NumTests, Ms, counts(prop_router:counts())]);
        _ ->
            ct:pal("failed after ~p ms~ts; counterexample:~n~p",
                   [Ms, counts(prop_router:counts()), proper:counterexample()]),
            ct:fail({property_failed, {counterexample, proper:counterexample()}})
    end.

counts(C) when map_size(C) =:= 0 -> "";
counts(C) -> io_lib:format(" (~p)", [C]).

%% PropEr's own output (progress, statistics, the counterexample), kept for
%% one entry in the case's log.
buffer(Format, Args) ->
    ets:insert(prop_output, {erlang:unique_integer([monotonic]),
                             io_lib:format(Format, Args)}),
    ok.
