%% The pure timeouts of the event path's processes (toroco_timeouts): what
%% a gen_statem timeout becomes in real time and in lockstep, as a function
%% of the timeout, the clock and the timers already set.
-module(toroco_timeouts_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

all() -> [real_time_scales_relative_timeouts, lockstep_keeps_timeouts_as_effects,
          lockstep_cancel_update_and_stale, hold_moves_only_when_the_deadline_does,
          event_timeouts_are_told_apart].

-define(SPEED10, {10, 1000, 5000}).   % speed 10, set at real 1000 ms, simulated 5000 ms

real_time_scales_relative_timeouts() ->
    [{doc, "In real time a relative timeout counts simulated ms (a 500 ms state timeout at "
           "speed 10 is 50 real ms, rounded up); absolute ones, cancels and other actions pass."}].
real_time_scales_relative_timeouts(_Config) ->
    Clock = {realtime, ?SPEED10},
    {[{state_timeout, 50, m}], #{}, []} = toroco_timeouts:action({state_timeout, 500, m}, Clock, #{}),
    {[{{timeout, t}, 1, m, []}], #{}, []} =
        toroco_timeouts:action({{timeout, t}, 3, m, []}, Clock, #{}),
    {[{{timeout, t}, 7, m, [{abs, true}]}], #{}, []} =
        toroco_timeouts:action({{timeout, t}, 7, m, [{abs, true}]}, Clock, #{}),
    {[25], #{}, []} = toroco_timeouts:action(250, Clock, #{}),
    {[{state_timeout, 500, m}], #{}, []} = toroco_timeouts:action({state_timeout, 500, m}, {realtime, 1}, #{}),
    {[postpone], #{}, []} = toroco_timeouts:action(postpone, Clock, #{}),
    {[{reply, f, ok}], #{}, []} = toroco_timeouts:action({reply, f, ok}, Clock, #{}).

lockstep_keeps_timeouts_as_effects() ->
    [{doc, "In lockstep gen_statem sees no relative timeout: each is a deadline kept by the "
           "process and an effect for toroco_lockstep at simulated now + T; an event timeout's "
           "message is its time; absolute ones stay gen_statem's."}].
lockstep_keeps_timeouts_as_effects(_Config) ->
    Clock = {lockstep, 1000},
    {[], #{state_timeout := 1500}, [{set, state_timeout, 1500, m}]} =
        toroco_timeouts:action({state_timeout, 500, m}, Clock, #{}),
    {[], #{{timeout, t} := 1010}, [{set, {timeout, t}, 1010, m}]} =
        toroco_timeouts:action({{timeout, t}, 10, m, []}, Clock, #{}),
    {[], #{timeout := 1250}, [{set, timeout, 1250, 250}]} = toroco_timeouts:action(250, Clock, #{}),
    Abs = {{timeout, t}, 7, m, [{abs, true}]},
    {[Abs], #{}, []} = toroco_timeouts:action(Abs, Clock, #{}).

lockstep_cancel_update_and_stale() ->
    [{doc, "In lockstep a cancel (or an infinite time) of a set timeout is an effect and drops "
           "its deadline, of an unset one nothing; an update re-sets the same deadline with the "
           "new message; a fired timeout no longer set is stale."}].
lockstep_cancel_update_and_stale(_Config) ->
    Clock = {lockstep, 0},
    Set = #{state_timeout => 40},
    {[], #{}, [{cancel, state_timeout}]} = toroco_timeouts:action({state_timeout, cancel}, Clock, Set),
    {[], #{}, [{cancel, state_timeout}]} = toroco_timeouts:action({state_timeout, infinity, m}, Clock, Set),
    {[], #{}, []} = toroco_timeouts:action({state_timeout, cancel}, Clock, #{}),
    {[], Set, [{set, state_timeout, 40, n}]} = toroco_timeouts:action({state_timeout, update, n}, Clock, Set),
    {[], #{}, []} = toroco_timeouts:action({state_timeout, update, n}, Clock, #{}),
    {ok, #{}} = toroco_timeouts:fired(state_timeout, Set),
    stale = toroco_timeouts:fired(state_timeout, #{}),
    {#{}, [{cancel, state_timeout}]} = toroco_timeouts:cancel(state_timeout, Set),
    {#{}, []} = toroco_timeouts:cancel(timeout, #{}).

hold_moves_only_when_the_deadline_does() ->
    [{doc, "A consumer's hold timer is touched only when its earliest deadline changed: an "
           "absolute real deadline (scaled) or a cancel in real time, an effect and a kept "
           "deadline in lockstep."}].
hold_moves_only_when_the_deadline_does(_Config) ->
    Hold = {timeout, hold},
    {300, [], #{}, []} = toroco_timeouts:hold(300, 300, {realtime, 1}, #{}),
    {5500, [{Hold, 1050, expire, [{abs, true}]}], #{}, []} =
        toroco_timeouts:hold(5500, infinity, {realtime, ?SPEED10}, #{}),
    {infinity, [{Hold, cancel}], #{}, []} = toroco_timeouts:hold(infinity, 300, {realtime, 1}, #{}),
    {300, [], #{Hold := 300}, [{set, Hold, 300, expire}]} =
        toroco_timeouts:hold(300, infinity, {lockstep, 0}, #{}),
    {infinity, [], #{}, [{cancel, Hold}]} = toroco_timeouts:hold(infinity, 300, {lockstep, 0}, #{Hold => 300}).

event_timeouts_are_told_apart() ->
    [{doc, "Event timeouts (an integer, {timeout, T, Msg}) are told from named and state "
           "timeouts, which an event does not cancel."}].
event_timeouts_are_told_apart(_Config) ->
    true = toroco_timeouts:event_timeout(10),
    true = toroco_timeouts:event_timeout({timeout, 10, m}),
    true = toroco_timeouts:event_timeout({timeout, 10, m, []}),
    false = toroco_timeouts:event_timeout({{timeout, t}, 10, m}),
    false = toroco_timeouts:event_timeout({state_timeout, 10, m}),
    false = toroco_timeouts:event_timeout(postpone).
