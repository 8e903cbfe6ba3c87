%% Suppression, holds, latches, idle values, buffering, inhibition and reset,
%% as a user sees them at a recording actuator (SPEC §4).
-module(toroco_semantics_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [values/1, await_values/2, await_values/3, settle/1,
                          sensor/2, actuator/2, wait_until/2]).

suite() -> [{timetrap, {seconds, 60}}].

all() -> [{group, suppression}, {group, inputs}, {group, inhibition}, {group, wiring}].

groups() ->
    [{suppression, [], [higher_hold_suppresses_lower, momentary_send_suppresses_nothing,
                        latch_redelivered_when_hold_ends, set_holds_until_unset,
                        holds_work_in_series, wiring_hold_is_the_default,
                        zero_hold_ends_previous_hold, send_clears_latch,
                        burst_arrives_complete_and_in_order, two_inputs_are_independent]},
     {inputs, [], [idle_on_last_hold_end_not_at_wiring, buffer_latest_keeps_mailbox_bounded]},
     {inhibition, [], [inhibitor_silences_output_everywhere, inhibition_ends_holds,
                       set_while_inhibited_reenters_on_release, timed_inhibition_ends,
                       mutual_pair_first_holder_wins,
                       mutual_pair_wired_while_both_hold, inhibitor_that_only_sends_inhibits_nothing]},
     {wiring, [], [wiring_delivers_latched_winner, rewire_keeps_state_of_sources_that_stay,
                   empty_list_unwires, reset_restarts_from_init]}].

init_per_testcase(_TC, Config) ->
    toroco_test_lib:start(),
    Config.

end_per_testcase(_TC, _Config) ->
    toroco_test_lib:stop().

%% Two sources into actuator `a': `hi' (layer 1) above `lo' (layer 0).
two_sources(Idle) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in]),
    Spec = case Idle of
               none -> [{hi, out}, {lo, out}];
               V -> #{sources => [{hi, out}, {lo, out}], idle => V}
           end,
    ok = toroco:set_inputs(a, #{in => Spec}).

%%--------------------------------------------------------------------
%% Suppression
%%--------------------------------------------------------------------

higher_hold_suppresses_lower() ->
    [{doc, "A held event of a higher source suppresses the lower one until the hold ends."}].
higher_hold_suppresses_lower(_) ->
    two_sources(none),
    ok = toroco:inject({hi, out}, h1, #{hold => 300}),
    ok = toroco:inject({lo, out}, l1),
    await_values(a, [h1]),
    #{inputs := #{in := #{winner := {hi, out}, holds := [{{hi, out}, Ms}]}}} = toroco:inspect(a),
    true = Ms > 0 andalso Ms =< 300,
    wait_until(fun() -> maps:get(winner, maps:get(in, maps:get(inputs, toroco:inspect(a)))) =:= none end, 2000),
    ok = toroco:inject({lo, out}, l2),
    await_values(a, [h1, l2]).

momentary_send_suppresses_nothing() ->
    [{doc, "A send without a hold (default 0) suppresses nothing."}].
momentary_send_suppresses_nothing(_) ->
    two_sources(none),
    ok = toroco:inject({hi, out}, h1),
    ok = toroco:inject({lo, out}, l1),
    await_values(a, [h1, l1]).

latch_redelivered_when_hold_ends() ->
    [{doc, "The lower source's latch is re-delivered when the higher hold expires."}].
latch_redelivered_when_hold_ends(_) ->
    two_sources(none),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    await_values(a, [fwd]),
    ok = toroco:inject({hi, out}, turn, #{hold => 200}),
    await_values(a, [fwd, turn, fwd]).

set_holds_until_unset() ->
    [{doc, "A set holds until unset; then the lower latch is re-delivered."}].
set_holds_until_unset(_) ->
    two_sources(none),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({hi, out}, stop, #{latch => true}),
    ok = toroco:inject({lo, out}, fwd2, #{latch => true}),
    await_values(a, [fwd, stop]),
    settle(a),
    [fwd, stop] = values(a),
    ok = toroco:inject({hi, out}, unset_ignored_value, #{hold => 0}),
    %% hi's send (hold 0) is delivered and ends hi's hold: lo's latch comes back.
    await_values(a, [fwd, stop, unset_ignored_value, fwd2]).

holds_work_in_series() ->
    [{doc, "A suppressed event still starts its hold (Brooks' suppressors in series)."}].
holds_work_in_series(_) ->
    ok = toroco:add_behavior(s1, tb_relay, #{layer => 2}),
    ok = toroco:add_behavior(s2, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(s3, tb_relay, #{layer => 0}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{s1, out}, {s2, out}, {s3, out}]}),
    ok = toroco:inject({s1, out}, x1, #{hold => 100}),
    ok = toroco:inject({s2, out}, x2, #{hold => 600}),   % suppressed, but holds
    await_values(a, [x1]),
    wait_until(fun() -> winner(a, in) =:= {s2, out} end, 2000),
    ok = toroco:inject({s3, out}, x3),                    % still suppressed by s2
    settle(a),
    [x1] = values(a),
    wait_until(fun() -> winner(a, in) =:= none end, 3000),
    ok = toroco:inject({s3, out}, x4),
    await_values(a, [x1, x4]).

wiring_hold_is_the_default() ->
    [{doc, "A wiring entry's hold applies to sends that give none; an emit-time hold wins."}].
wiring_hold_is_the_default(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out, #{hold => 100000}}, {lo, out}]}),
    ok = toroco:inject({hi, out}, h1),
    ok = toroco:inject({lo, out}, l1),
    await_values(a, [h1]),
    #{inputs := #{in := #{holds := [{{hi, out}, Ms}]}}} = toroco:inspect(a),
    true = Ms > 1000,
    ok = toroco:inject({hi, out}, h2, #{hold => 0}),
    ok = toroco:inject({lo, out}, l2),
    await_values(a, [h1, h2, l2]).

zero_hold_ends_previous_hold() ->
    [{doc, "A 0 ms hold ends the output's previous hold at once, so the winner is re-picked."}].
zero_hold_ends_previous_hold(_) ->
    two_sources(none),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({hi, out}, h1, #{hold => infinity}),
    await_values(a, [fwd, h1]),
    ok = toroco:inject({hi, out}, h2, #{hold => 0}),
    await_values(a, [fwd, h1, h2, fwd]).

send_clears_latch() ->
    [{doc, "A send clears the output's latch: nothing is re-delivered afterwards."}].
send_clears_latch(_) ->
    two_sources(none),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({lo, out}, once),
    ok = toroco:inject({hi, out}, h, #{hold => 50}),
    await_values(a, [fwd, once, h]),
    wait_until(fun() -> winner(a, in) =:= none end, 2000),
    settle(a),
    [fwd, once, h] = values(a),
    #{inputs := #{in := #{latches := []}}} = toroco:inspect(a).

burst_arrives_complete_and_in_order() ->
    [{doc, "Nothing is lost in a burst: 20,000 events arrive complete and in order."}].
burst_arrives_complete_and_in_order(_) ->
    sensor(s, [v]),
    ok = toroco:add_behavior(p, tb_relay, #{}),
    actuator(a, [in]),
    ok = toroco:set_inputs(p, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{in => [{p, out}]}),
    N = 20000,
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, N)],
    await_values(a, lists:seq(1, N), 20000).

two_inputs_are_independent() ->
    [{doc, "A source wired to two inputs of one receiver is held and latched independently."}].
two_inputs_are_independent(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in, in2]),
    ok = toroco:set_inputs(a, #{in => [{hi, out, #{hold => 100000}}, {lo, out}],
                                in2 => [{hi, out}, {lo, out}]}),
    ok = toroco:inject({hi, out}, h),
    ok = toroco:inject({lo, out}, l),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:sort([{I, V} || {I, V, _} <- H]) =:=
                                                     [{in, h}, {in2, h}, {in2, l}] end, 2000),
    #{inputs := #{in := #{winner := {hi, out}}, in2 := #{winner := none}}} = toroco:inspect(a).

%%--------------------------------------------------------------------
%% Input options
%%--------------------------------------------------------------------

idle_on_last_hold_end_not_at_wiring() ->
    [{doc, "idle is delivered when the last holder lets go (unset, expiry, removal, unwiring), never at wiring time."}].
idle_on_last_hold_end_not_at_wiring(_) ->
    two_sources({0, 0}),
    settle(a),
    [] = values(a),
    ok = toroco:inject({hi, out}, {50, 50}, #{latch => true}),
    await_values(a, [{50, 50}]),
    ok = toroco:inject({hi, out}, {10, 10}, #{hold => 100}),
    await_values(a, [{50, 50}, {10, 10}, {0, 0}]),
    ok = toroco:inject({lo, out}, {20, 20}, #{latch => true}),
    await_values(a, [{50, 50}, {10, 10}, {0, 0}, {20, 20}]),
    ok = toroco:remove_behavior(lo),
    await_values(a, [{50, 50}, {10, 10}, {0, 0}, {20, 20}, {0, 0}]),
    ok = toroco:inject({hi, out}, {30, 30}, #{latch => true}),
    ok = toroco:set_inputs(a, #{in => []}),              % unwiring the holder's input
    await_values(a, [{50, 50}, {10, 10}, {0, 0}, {20, 20}, {0, 0}, {30, 30}, {0, 0}]).

buffer_latest_keeps_mailbox_bounded() ->
    [{doc, "With buffer => latest a slow receiver gets the newest value and its mailbox stays small."}].
buffer_latest_keeps_mailbox_bounded(_) ->
    sensor(s, [v]),
    ok = toroco:add_behavior(slow, tb_relay, #{}),
    actuator(a, [in]),
    ok = toroco:set_inputs(slow, #{in => #{sources => [{s, v}], buffer => latest}}),
    ok = toroco:set_inputs(a, #{in => [{slow, out}]}),
    Slow = whereis(toroco_names:process(slow)),
    N = 200,
    MaxQ = lists:max([begin
                          ok = toroco:inject({s, v}, {sleep, 20, I}),
                          element(2, erlang:process_info(Slow, message_queue_len))
                      end || I <- lists:seq(1, N)]),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:last([0 | [V || {_, V, _} <- H]]) =:= N end,
                                    5000),
    Got = values(a),
    ct:pal("latest: ~p of ~p delivered, max mailbox ~p", [length(Got), N, MaxQ]),
    true = MaxQ =< 2,
    true = length(Got) < N,
    Got = lists:sort(Got).

%%--------------------------------------------------------------------
%% Inhibition
%%--------------------------------------------------------------------

inhibitor_silences_output_everywhere() ->
    [{doc, "While an inhibitor holds, the output's events reach no router at all."}].
inhibitor_silences_output_everywhere(_) ->
    ok = toroco:add_behavior(e, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    actuator(b, [in]),
    ok = toroco:set_inputs(a, #{in => [{e, out}]}),
    ok = toroco:set_inputs(b, #{in => [{e, out}]}),
    ok = toroco:set_inhibitors(e, #{out => [{i, out}]}),
    ok = toroco:inject({e, out}, before),
    await_values(a, [before]),
    await_values(b, [before]),
    ok = toroco:inject({i, out}, on, #{latch => true}),
    ok = toroco:inject({e, out}, during),
    #{outputs := #{out := #{inhibited := true, inhibitors := [{i, out}]}}} = toroco:inspect(e),
    settle(a), settle(b),
    [before] = values(a),
    [before] = values(b),
    ok = toroco:inject({i, out}, off, #{hold => 0}),
    wait_until(fun() -> not inhibited(e, out) end, 2000),
    ok = toroco:inject({e, out}, 'after'),
    await_values(a, [before, 'after']),
    await_values(b, [before, 'after']).

inhibition_ends_holds() ->
    [{doc, "An inhibited output's holds end at every router, so lower sources take over."}].
inhibition_ends_holds(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 2}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:set_inhibitors(hi, #{out => [{i, out}]}),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({hi, out}, turn, #{latch => true}),
    await_values(a, [fwd, turn]),
    ok = toroco:inject({i, out}, x, #{latch => true}),
    await_values(a, [fwd, turn, fwd]),
    #{inputs := #{in := #{winner := {lo, out}}}} = toroco:inspect(a).

set_while_inhibited_reenters_on_release() ->
    [{doc, "A set while inhibited updates the latch; it re-enters as a fresh set on release."}].
set_while_inhibited_reenters_on_release(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 2}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:set_inhibitors(hi, #{out => [{i, out}]}),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({i, out}, x, #{latch => true}),
    ok = toroco:inject({hi, out}, turn1, #{latch => true}),
    ok = toroco:inject({hi, out}, turn2, #{latch => true}),
    settle(a),
    [fwd] = values(a),
    #{outputs := #{out := #{latch := {value, turn2}, inhibited := true}}} = toroco:inspect(hi),
    ok = toroco:inject({i, out}, x, #{hold => 0}),
    await_values(a, [fwd, turn2]).

timed_inhibition_ends() ->
    [{doc, "An inhibitor's timed hold ends by itself; the output is free again and inspect shows the countdown."}].
timed_inhibition_ends(_) ->
    ok = toroco:add_behavior(e, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{e, out}]}),
    ok = toroco:set_inhibitors(e, #{out => [{i, out}]}),
    ok = toroco:inject({i, out}, on, #{hold => 300}),
    #{outputs := #{out := #{inhibited := true, inhibitor_holds := [{{i, out}, Ms}]}}} = toroco:inspect(e),
    true = Ms > 0 andalso Ms =< 300,
    ok = toroco:inject({e, out}, during),
    wait_until(fun() -> not inhibited(e, out) end, 2000),
    ok = toroco:inject({e, out}, 'after'),
    await_values(a, ['after']),
    %% the gate is idle again, not spinning
    {_, R1} = erlang:process_info(whereis(toroco_names:gate({e, out})), reductions),
    toroco_test_lib:quiet(200),
    {_, R2} = erlang:process_info(whereis(toroco_names:gate({e, out})), reductions),
    true = R2 - R1 < 1000.

mutual_pair_first_holder_wins() ->
    [{doc, "Two same-layer outputs inhibiting each other: the one whose hold started first wins."}].
mutual_pair_first_holder_wins(_) ->
    ok = toroco:add_behavior(l, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(r, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{l, out}, {r, out}]}),
    ok = toroco:set_inhibitors(l, #{out => [{r, out}]}),
    ok = toroco:set_inhibitors(r, #{out => [{l, out}]}),
    ok = toroco:inject({r, out}, right, #{latch => true}),
    ok = toroco:inject({l, out}, left, #{latch => true}),
    await_values(a, [right]),
    true = inhibited(l, out),
    false = inhibited(r, out),
    ok = toroco:inject({r, out}, x, #{hold => 0}),        % r lets go: l's latch enters
    await_values(a, [right, x, left]),
    true = inhibited(r, out),
    false = inhibited(l, out).

mutual_pair_wired_while_both_hold() ->
    [{doc, "When both outputs of a pair already hold as they are wired, the smaller one wins."}].
mutual_pair_wired_while_both_hold(_) ->
    ok = toroco:add_behavior(l, tb_relay, #{layer => 1, params => #{latch => left}}),
    ok = toroco:add_behavior(r, tb_relay, #{layer => 1, params => #{latch => right}}),
    actuator(a, [in]),
    ok = toroco:set_inhibitors(r, #{out => [{l, out}]}),
    ok = toroco:set_inhibitors(l, #{out => [{r, out}]}),
    ok = toroco:set_inputs(a, #{in => [{r, out}, {l, out}]}),
    await_values(a, [left]),
    false = inhibited(l, out),
    true = inhibited(r, out).

inhibitor_that_only_sends_inhibits_nothing() ->
    [{doc, "An inhibitor that only sends without a hold inhibits nothing."}].
inhibitor_that_only_sends_inhibits_nothing(_) ->
    ok = toroco:add_behavior(e, tb_relay, #{layer => 0}),
    ok = toroco:add_behavior(i, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{e, out}]}),
    ok = toroco:set_inhibitors(e, #{out => [{i, out}]}),
    ok = toroco:inject({i, out}, ping),
    ok = toroco:inject({e, out}, pass),
    await_values(a, [pass]).

%%--------------------------------------------------------------------
%% Wiring and reset
%%--------------------------------------------------------------------

wiring_delivers_latched_winner() ->
    [{doc, "Wiring takes effect with the sources' current state: a latched winner is delivered."}].
wiring_delivers_latched_winner(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1, params => #{latch => high}}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => low}}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    #{inputs := #{in := #{winner := {hi, out}, latches := [{{hi, out}, high}, {{lo, out}, low}]}}} =
        toroco:inspect(a),
    await_values(a, [high]).

rewire_keeps_state_of_sources_that_stay() ->
    [{doc, "A re-wired router keeps the holds and latches of the sources that stay."}].
rewire_keeps_state_of_sources_that_stay(_) ->
    two_sources(none),
    ok = toroco:add_behavior(x, tb_relay, #{layer => 0}),
    ok = toroco:inject({lo, out}, fwd, #{latch => true}),
    ok = toroco:inject({hi, out}, h, #{hold => 100000}),
    await_values(a, [fwd, h]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}, {x, out}]}),
    #{inputs := #{in := #{winner := {hi, out}, latches := [{{lo, out}, fwd}],
                          holds := [{{hi, out}, _}, {{lo, out}, infinity}]}}} = toroco:inspect(a),
    settle(a),
    [fwd, h] = values(a).

empty_list_unwires() ->
    [{doc, "[] unwires an input; the receiver's other inputs are left alone."}].
empty_list_unwires(_) ->
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in, in2]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    ok = toroco:set_inputs(a, #{in2 => [{lo, out}]}),
    ok = toroco:set_inputs(a, #{in => []}),
    #{inputs := #{in := #{sources := []}, in2 := #{sources := [{lo, out}]}}} = toroco:inspect(a),
    ok = toroco:inject({lo, out}, l),
    ok = toroco_fake_actuator:await(a, fun(H) -> [{I, V} || {I, V, _} <- H] =:= [{in2, l}] end, 2000).

reset_restarts_from_init() ->
    [{doc, "Each event on a reset source restarts the behavior from init/1, its latches cleared first."}].
reset_restarts_from_init(_) ->
    ok = toroco:add_behavior(b, tb_relay, #{layer => 0, params => #{latch => initial}}),
    ok = toroco:add_behavior(r, tb_relay, #{layer => 1}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => #{sources => [{b, out}], idle => idle}}),
    await_values(a, [initial]),
    ok = toroco:inject({b, out}, changed, #{latch => true}),
    await_values(a, [initial, changed]),
    ok = toroco:set_reset(b, [{r, out}]),
    ok = toroco:inject({r, out}, go),
    await_values(a, [initial, changed, idle, initial]).

%%--------------------------------------------------------------------

winner(A, I) ->
    #{inputs := #{I := #{winner := W}}} = toroco:inspect(A),
    W.

inhibited(E, O) ->
    #{outputs := #{O := #{inhibited := Inh}}} = toroco:inspect(E),
    Inh.
