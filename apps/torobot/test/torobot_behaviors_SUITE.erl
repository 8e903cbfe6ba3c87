%% The Torobot's behaviors and wiring (config/torobot.wiring) on the real
%% runtime, with fake devices standing in for the sensors and the motors:
%% events are injected on the fake sensors and the commands that reach the
%% motors are checked. Each case loads the shipped wiring afresh.
%%
%% The cases run in lockstep (SPEC §14): every injected event is followed
%% by quiescence, so the whole chain it starts (the avoids, their holds and
%% gates, the latches released when an inhibition lifts) is handled before
%% the next event, and each case checks the exact sequence the motors got.
-module(torobot_behaviors_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [settle/0]).

-define(FORWARD, {80, 80}).
-define(SPIN_RIGHT, {50, -50}).          % avoid_left's turn
-define(SPIN_LEFT, {-50, 50}).           % avoid_right's turn
-define(ARC_LEFT, {50, 70}).             % trq_ignore, blue on the right

all() ->
    [{group, wiring}].

groups() ->
    [{wiring, [],
      [forward_at_start, button_toggles, avoid_turns_away, avoids_inhibit_each_other,
       trq_ignore_steers_away, trq_ignore_keeps_its_side, trq_ignore_suppresses_avoid_without_hold,
       hold_passes_through, hold_keeps_turn_while_blue, hold_waits_for_an_avoid,
       red_follower_steers, red_follower_wins_and_hands_back, red_follower_command]}].

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    ok = toroco_clock:lockstep(#{}),
    ok = toroco:add_device(ir, toroco_fake_sensor, #{outputs => [left, right]}),
    ok = toroco:add_device(camera, toroco_fake_sensor, #{outputs => [update_red, update_trq]}),
    ok = toroco:add_device(push, toroco_fake_sensor, #{outputs => [button]}),
    ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [setvel, enable]}),
    ok = toroco:load_wiring(filename:join([root(), "config", "torobot.wiring"])),
    settle(),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = (catch toroco_clock:realtime()),
    toroco_test_lib:stop().

%%====================================================================
%% Cases
%%====================================================================

forward_at_start() ->
    [{doc, "At start the motors get forward's speed, and are disabled until the button."}].
forward_at_start(_Config) ->
    await(setvel, ?FORWARD),
    await(enable, false),
    ?assertMatch(#{inputs := #{setvel := #{winner := {forward, motors}}}},
                 toroco:inspect(motors)).

button_toggles() ->
    [{doc, "Each press toggles the motors' enable; releases do nothing."}].
button_toggles(_Config) ->
    await(enable, false),
    press(),
    await(enable, true),
    press(),
    await(enable, false),
    ?assertEqual([false, true, false], values(enable)).

avoid_turns_away() ->
    [{doc, "An IR sensor's near sets its avoid's turn away; far gives the motors back to "
      "forward."}].
avoid_turns_away(_Config) ->
    await(setvel, ?FORWARD),
    ir(left, 1),
    await(setvel, ?SPIN_RIGHT),
    ir(left, 0),
    await(setvel, ?FORWARD),
    ir(right, 1),
    await(setvel, ?SPIN_LEFT),
    ir(right, 0),
    await(setvel, ?FORWARD).

avoids_inhibit_each_other() ->
    [{doc, "Both sensors near (a corner): the avoid that turned first keeps turning; the "
      "other's turn comes in when the first clears."}].
avoids_inhibit_each_other(_Config) ->
    await(setvel, ?FORWARD),
    ir(left, 1),
    await(setvel, ?SPIN_RIGHT),
    ir(right, 1),
    ?assertEqual(?SPIN_RIGHT, last(setvel)),
    ir(left, 0),
    await(setvel, ?SPIN_LEFT),
    ir(right, 0),
    await(setvel, ?FORWARD),
    ?assertEqual([?FORWARD, ?SPIN_RIGHT, ?SPIN_LEFT, ?FORWARD], changes(setvel)).

trq_ignore_steers_away() ->
    [{doc, "Blue on the right turns the robot left, blue on the left turns it right; none "
      "hands back."}].
trq_ignore_steers_away(_Config) ->
    await(setvel, ?FORWARD),
    blue({40, 10}),
    await(setvel, ?ARC_LEFT),
    blue(none),
    await(setvel, ?FORWARD),
    blue({-40, 10}),
    await(setvel, {70, 50}),
    blue(none),
    await(setvel, ?FORWARD).

trq_ignore_keeps_its_side() ->
    [{doc, "A blue blob crossing the centre while blue stays in view does not flip the "
      "turn, and frames that change nothing emit nothing."}].
trq_ignore_keeps_its_side(_Config) ->
    await(setvel, ?FORWARD),
    blue({0, 10}),
    await(setvel, ?ARC_LEFT),
    [blue({X, 10}) || X <- [-10, -60, -120, 30]],
    ?assertEqual([?FORWARD, ?ARC_LEFT], values(setvel)).

trq_ignore_suppresses_avoid_without_hold() ->
    [{doc, "With the holds unwired, steering away from blue suppresses an avoid's turn "
      "(the dithering the holds exist to prevent)."}].
trq_ignore_suppresses_avoid_without_hold(_Config) ->
    ok = toroco:remove_behavior(hold_left),
    ok = toroco:remove_behavior(hold_right),
    await(setvel, ?FORWARD),
    blue({40, 10}),
    await(setvel, ?ARC_LEFT),
    ir(left, 1),
    ?assertEqual(?ARC_LEFT, last(setvel)),
    blue(none),
    await(setvel, ?SPIN_RIGHT).

hold_passes_through() ->
    [{doc, "With no blue in view a hold passes its avoid's turn through, and lets go when "
      "the avoid clears."}].
hold_passes_through(_Config) ->
    await(setvel, ?FORWARD),
    ir(left, 1),
    await(setvel, ?SPIN_RIGHT),
    %% avoid_left's turn arrives first; hold_left passes the same turn on as
    %% its own latch just after (the same value, so not delivered twice).
    winner_is(setvel, {hold_left, motors}),
    ir(left, 0),
    await(setvel, ?FORWARD).

hold_keeps_turn_while_blue() ->
    [{doc, "Blue in view and a wall near: the avoid's turn wins over steering away from "
      "blue and is kept after the avoid clears, until blue is gone."}].
hold_keeps_turn_while_blue(_Config) ->
    await(setvel, ?FORWARD),
    blue({40, 10}),
    await(setvel, ?ARC_LEFT),
    ir(left, 1),
    await(setvel, ?SPIN_RIGHT),
    ir(left, 0),
    blue({10, 10}),
    ?assertEqual(?SPIN_RIGHT, last(setvel)),
    blue(none),
    await(setvel, ?FORWARD),
    ?assertEqual([?FORWARD, ?ARC_LEFT, ?SPIN_RIGHT, ?FORWARD], changes(setvel)).

hold_waits_for_an_avoid() ->
    [{doc, "An avoid turn that ended before blue came into view is not held: blue alone "
      "is trq_ignore's."}].
hold_waits_for_an_avoid(_Config) ->
    await(setvel, ?FORWARD),
    ir(right, 1),
    await(setvel, ?SPIN_LEFT),
    ir(right, 0),
    await(setvel, ?FORWARD),
    blue({40, 10}),
    await(setvel, ?ARC_LEFT),
    ?assertMatch(#{inputs := #{setvel := #{winner := {trq_ignore, motors}}}},
                 toroco:inspect(motors)).

red_follower_steers() ->
    [{doc, "Red steers hard beyond 50 px, soft beyond 25 px, straight in between."}].
red_follower_steers(_Config) ->
    await(setvel, ?FORWARD),
    Expect = [{60, {80, 20}}, {30, {80, 50}}, {10, {80, 80}}, {-30, {50, 80}},
              {-60, {20, 80}}, {-51, {20, 80}}],
    [begin red({X, 0}), await(setvel, V) end || {X, V} <- Expect],
    red(none),
    await(setvel, ?FORWARD),
    %% a command is sent only when it changes
    ?assertEqual([?FORWARD, {80, 20}, {80, 50}, {80, 80}, {50, 80}, {20, 80}, ?FORWARD],
                 values(setvel)).

red_follower_wins_and_hands_back() ->
    [{doc, "Red wins over blue and a wall; when red is gone the motors go back to what "
      "the layers below hold."}].
red_follower_wins_and_hands_back(_Config) ->
    await(setvel, ?FORWARD),
    ir(right, 1),
    await(setvel, ?SPIN_LEFT),
    red({0, 0}),
    await(setvel, {80, 80}),
    blue({40, 0}),
    ?assertEqual({80, 80}, last(setvel)),
    red(none),
    await(setvel, ?SPIN_LEFT).

red_follower_command() ->
    [{doc, "The steering command as a function of x and the params."}].
red_follower_command(_Config) ->
    P = #{straight => 70, soft => {70, 40}, hard => {70, 0}, soft_px => 20, hard_px => 40},
    ?assertEqual({70, 70}, torobot_red_follower:command(20, P)),
    ?assertEqual({70, 40}, torobot_red_follower:command(21, P)),
    ?assertEqual({70, 0}, torobot_red_follower:command(41, P)),
    ?assertEqual({40, 70}, torobot_red_follower:command(-21, P)),
    ?assertEqual({0, 70}, torobot_red_follower:command(-41, P)),
    ?assertEqual({80, 80}, torobot_red_follower:command(0, #{})).

%%====================================================================
%% Helpers
%%====================================================================

ir(Side, Level) -> inject({ir, Side}, Level).
blue(V) -> inject({camera, update_trq}, V).
red(V) -> inject({camera, update_red}, V).

press() ->
    inject({push, button}, pressed),
    inject({push, button}, released).

%% Injects one event and returns once everything it caused is handled.
inject(Output, V) ->
    ok = toroco:inject(Output, V),
    settle().

values(Input) ->
    [V || {In, V, _} <- toroco_fake_actuator:history(motors), In =:= Input].

%% The values delivered to Input with repeats in a row collapsed: an avoid's
%% turn arrives twice, once from the avoid and once passed through its hold
%% (which wins, being higher).
changes(Input) ->
    lists:foldr(fun(V, [V | _] = Acc) -> Acc;
                   (V, Acc) -> [V | Acc]
                end, [], values(Input)).

last(Input) ->
    lists:last(values(Input)).

%% Checks that the last value delivered to the motors' Input is V (every
%% event injected so far is handled: see inject/2).
await(Input, V) ->
    case values(Input) of
        [_ | _] = Vs -> ?assertEqual({Input, V}, {Input, lists:last(Vs)});
        [] -> ct:fail({expected, Input, V, got, []})
    end.

%% Checks that the motors' Input has Src as its winner.
winner_is(Input, Src) ->
    #{inputs := #{Input := #{winner := Winner}}} = toroco:inspect(motors),
    ?assertEqual({Input, Src}, {Input, Winner}).

root() ->
    toroco_test_lib:root().
