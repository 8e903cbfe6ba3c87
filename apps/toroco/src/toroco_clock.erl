%% @doc The runtime's clock: the one place where the runtime reads time and
%% turns durations into timers (SPEC §14).
%%
%% Routers' and gates' hold deadlines, the pure cores' `Now', and the
%% engine's handling of a behavior's gen_statem timeouts (`state_timeout',
%% `{timeout, Name}', event timeouts) all count simulated milliseconds read
%% here. The real-time factor (`speed') is 1 unless set: the simulated lab
%% sets it (10 runs ten times faster), and then a hold of 500 ms lasts 50 ms
%% of real time, so a run at speed 10 behaves as the same run at speed 1.
%% Safety timers of real hardware (the servo watchdog of `pru_port') do not
%% use this clock: they stay in real time.
%%
%% At speed 1 {@link now_ms/0} is the monotonic clock and {@link real_ms/1}
%% the identity; the factor lives in a `persistent_term', read without a
%% copy, and changing it keeps simulated time continuous.
%%
%% Lockstep (SPEC §14, "Lockstep"): {@link lockstep/1} makes a simulated
%% world the node's clock. Time starts at 0 and moves only with {@link
%% tick/2}; every timer of the runtime (holds, gate timers, behaviors'
%% gen_statem timeouts) is kept by `toroco_lockstep' and fires at its
%% simulated deadline, and the event path runs one step at a time, so a run
%% depends only on its world, wiring and seed. {@link realtime/0} ends it.
%%
%% The rule for callback modules: a behavior or device reads time with
%% {@link now_ms/0} and sets timers with the engine's gen_statem timeout
%% actions (relative times), nothing else; one that reads the OS clock or
%% calls `erlang:send_after' itself cannot run in lockstep. What stays in
%% real time, on purpose: absolute gen_statem timeouts (`{abs, true}': the
%% servos' keepalive, which feeds the real hardware's watchdog; a
%% simulation in lockstep turns that watchdog off), the idle tick that
%% hibernates quiet processes, the keep-alives between nodes, and OTP
%% supervisors' restart intensity (counted by OTP in real seconds).
-module(toroco_clock).

-export([now_ms/0, speed/0, set_speed/1, real_ms/1, real_deadline/1]).
-export([timebase/0, real_ms/2, real_deadline/2]).
-export_type([timebase/0, scale/0]).
-export([mode/0, lockstep/1, realtime/0, tick/2, tick/3, settle/0, timestamp_ns/0]).
-export([lockstep_cell/1, lockstep_server/0, set_timer/3, cancel_timer/1, notify/2, notify/3]).
-export([link_ms/0, link_timer/3, cut/2]).
-export_type([speed/0, stimulus/0]).

-type stimulus() :: toroco_lockstep:stimulus().

-type speed() :: number().
%% How real time relates to simulated time outside lockstep: the identity,
%% or a speed with the real and simulated times it was set at (while
%% lockstep starts or ends, its cell: the identity too).
-type scale() :: 1 | {speed(), integer(), integer()} | {lockstep, atomics:atomics_ref()}.
%% What a timeout is set against: simulated time now, in lockstep, or
%% the scale of real time (see `toroco_timeouts').
-type timebase() :: {lockstep, integer()} | {realtime, scale()}.

-define(KEY, toroco_clock).

%% @doc Simulated monotonic time in milliseconds.
-spec now_ms() -> integer().
now_ms() ->
    case persistent_term:get(?KEY, 1) of
        1 -> erlang:monotonic_time(millisecond);
        {lockstep, Cell} -> atomics:get(Cell, 1);
        {Speed, RealBase, SimBase} -> SimBase + floor((real_now() - RealBase) * Speed)
    end.

%% @doc The real-time factor.
-spec speed() -> speed().
speed() ->
    case persistent_term:get(?KEY, 1) of
        {Speed, _, _} -> Speed;
        _ -> 1
    end.

%% @doc Sets the real-time factor; simulated time goes on from where it is.
%% Refused in lockstep, where the world moves time.
-spec set_speed(speed()) -> ok | {error, {bad_speed, term()} | lockstep}.
set_speed(Speed) ->
    case mode() of
        lockstep -> {error, lockstep};
        realtime -> scale(Speed)
    end.

scale(Speed) when is_number(Speed), Speed > 0 ->
    Sim = now_ms(),
    Real = real_now(),
    case Speed == 1 andalso Sim =:= Real of
        true -> persistent_term:put(?KEY, 1);
        false -> persistent_term:put(?KEY, {Speed, Real, Sim})
    end;
scale(Speed) ->
    {error, {bad_speed, Speed}}.

%% @doc A duration of simulated milliseconds as real milliseconds (rounded
%% up, so a timer never fires early).
-spec real_ms(timeout()) -> timeout().
real_ms(Ms) ->
    real_ms(Ms, persistent_term:get(?KEY, 1)).

%% @doc {@link real_ms/1} against a scale read before (`timebase/0').
-spec real_ms(timeout(), scale()) -> timeout().
real_ms(infinity, _Scale) -> infinity;
real_ms(Ms, {Speed, _, _}) -> ceil(Ms / Speed);
real_ms(Ms, _Scale) -> Ms.

%% @doc A simulated monotonic deadline as a real monotonic one, in ms (for
%% gen_statem's absolute timeouts).
-spec real_deadline(integer()) -> integer().
real_deadline(SimMs) ->
    real_deadline(SimMs, persistent_term:get(?KEY, 1)).

%% @doc {@link real_deadline/1} against a scale read before (`timebase/0').
-spec real_deadline(integer(), scale()) -> integer().
real_deadline(SimMs, {Speed, RealBase, SimBase}) -> RealBase + ceil((SimMs - SimBase) / Speed);
real_deadline(SimMs, _Scale) -> SimMs.

%% @doc What the timeouts a process sets now are set against: in lockstep
%% (a lockstep process runs), simulated time now; else the scale of real
%% time. Read once per callback result that sets a timeout.
-spec timebase() -> timebase().
timebase() ->
    case lockstep_server() of
        none -> {realtime, persistent_term:get(?KEY, 1)};
        _ -> {lockstep, now_ms()}
    end.

real_now() ->
    erlang:monotonic_time(millisecond).

%%====================================================================
%% Lockstep
%%====================================================================

%% @doc `realtime' (the monotonic clock, maybe scaled by a speed) or
%% `lockstep' (a world moves time).
-spec mode() -> realtime | lockstep.
mode() ->
    case persistent_term:get(?KEY, 1) of
        {lockstep, _} -> lockstep;
        _ -> realtime
    end.

%% @doc Makes this node's clock virtual: simulated time is 0 and moves only
%% with {@link tick/2}. `trace => true' keeps a line per step for {@link
%% tick/2} to hand over. Start it before the behaviors and devices of the
%% run, end it with {@link realtime/0}.
%% `nodes => [Node]': the robot's other nodes (connected) join this clock,
%% one world over several nodes (SPEC §13, §17); `{error, {node_not_connected,
%% Node}}' and this node back in real time if one is not connected.
-spec lockstep(#{trace => boolean(), nodes => [node()]}) -> ok | {error, {atom(), term()}}.
lockstep(Opts) ->
    ok = toroco_lockstep:start(maps:with([trace], Opts)),
    ok = toroco_devices_sup:follow_clock(),
    case maps:get(nodes, Opts, []) -- [node()] of
        [] ->
            ok;
        Nodes ->
            case toroco_lockstep:join(Nodes) of
                ok -> ok;
                Error -> ok = realtime(), Error
            end
    end.

%% @doc In lockstep over several nodes: cuts `Node' from the rest of the
%% robot for `Ms' simulated ms (`forever': kills it). `{error, {own_node,
%% Node}}' for this node, `{error, {unknown_node, Node}}' for one not in
%% the world.
-spec cut(node(), non_neg_integer() | forever) -> ok | {error, {atom(), node()}}.
cut(Node, Ms) ->
    toroco_lockstep:cut(Node, Ms).

%% @doc Back to the monotonic clock (speed 1).
-spec realtime() -> ok.
realtime() ->
    ok = toroco_lockstep:stop(),
    toroco_devices_sup:follow_clock().

%% @doc Moves simulated time to `T' ms, firing the timers due on the way at
%% their deadlines, then hands over the stimuli (`{Device, Msg}', each a
%% step to that process, in order), and returns once the node is quiescent:
%% nothing queued or in flight, no timer due at or before `T'. With the
%% trace on, its lines since the last tick.
-spec tick(integer(), [stimulus()]) -> {ok, [iodata()]} | {error, term()}.
tick(T, Stimuli) ->
    tick(T, Stimuli, 60000).

-spec tick(integer(), [stimulus()], timeout()) -> {ok, [iodata()]} | {error, term()}.
tick(T, Stimuli, Timeout) ->
    toroco_lockstep:tick(T, Stimuli, Timeout).

%% @doc Returns once the node is quiescent, time unchanged.
-spec settle() -> ok | {error, term()}.
settle() ->
    toroco_lockstep:settle().

%% @doc The time stamp of observed events (SPEC §10), in ns: the system
%% clock, or in lockstep the simulated time since the run began.
-spec timestamp_ns() -> integer().
timestamp_ns() ->
    case persistent_term:get(?KEY, 1) of
        {lockstep, Cell} -> atomics:get(Cell, 1) * 1000000;
        _ -> erlang:system_time(nanosecond)
    end.

%% @private Set by `toroco_lockstep' as lockstep starts and ends.
-spec lockstep_cell(atomics:atomics_ref() | undefined) -> ok.
lockstep_cell(undefined) ->
    persistent_term:put(?KEY, 1);
lockstep_cell(Cell) ->
    persistent_term:put(?KEY, {lockstep, Cell}).

%% @doc The lockstep process of this node, or `none' in real time.
-spec lockstep_server() -> pid() | none.
lockstep_server() ->
    persistent_term:get(toroco_lockstep, none).

%% @doc In lockstep: sets the calling process's timer `Kind' (a gen_statem
%% timeout type) to fire at simulated `Deadline' with `Msg', as the step
%% message `WIRE_TIMER(Kind, Msg)'.
-spec set_timer(term(), integer(), term()) -> ok.
set_timer(Kind, Deadline, Msg) ->
    toroco_lockstep:timer(lockstep_server(), Kind, Deadline, Msg).

%% @doc A message from outside the event path (a port program's owner
%% telling its devices or Lua behaviors that the program died and was
%% started again) to `Pid', a process of the path. In real time a plain
%% send; in lockstep a step, traced as `notice Msg', queued in the order
%% the notices were sent, so what the receivers do about it happens at the
%% simulated instant and in an order that does not depend on the
%% schedulers. A `Pid' that is not a process of the path gets it as a
%% plain send in both.
-spec notify(pid(), term()) -> ok.
notify(Pid, Msg) ->
    notify(Pid, Msg, Msg).

%% @doc As {@link notify/2}, the trace showing `Shown' instead of `Msg'
%% (what differs from one run to the next, such as a count kept across
%% runs, left out).
-spec notify(pid(), term(), term()) -> ok.
notify(Pid, Msg, Shown) when is_pid(Pid) ->
    case lockstep_server() of
        none -> Pid ! Msg, ok;
        Lockstep -> toroco_lockstep:send(Lockstep, Pid, {notice, Msg, Shown})
    end.

%% @doc In lockstep: cancels the calling process's timer `Kind'.
-spec cancel_timer(term()) -> ok.
cancel_timer(Kind) ->
    toroco_lockstep:cancel(lockstep_server(), Kind).

%% @doc The time of the links between nodes (keep-alives, the silence of
%% remote sources, resubscriptions): the monotonic clock in real time,
%% unscaled; in lockstep the world's, so that a robot over several nodes
%% lets a silent source go at its simulated deadline (SPEC §13, §17).
-spec link_ms() -> integer().
link_ms() ->
    case mode() of
        lockstep -> now_ms();
        realtime -> erlang:monotonic_time(millisecond)
    end.

%% @doc A timer of the links in `link_ms/0' time: `Ms' from now, `{at, T}',
%% or `cancel'. The gen_statem actions to return (in lockstep none: the
%% timer is `toroco_lockstep''s, and comes as `WIRE_TIMER(Kind,
%% {'$toroco_link', Msg})', which the process shell (`toroco_shell') hands
%% on as the timeout `Kind' with `Msg', whatever timeouts it keeps itself).
-spec link_timer(term(), non_neg_integer() | {at, integer()} | cancel, term()) ->
          [gen_statem:action()].
link_timer(Kind, When, Msg) ->
    case {lockstep_server(), When} of
        {none, cancel} -> [{Kind, cancel}];
        {none, {at, T}} -> [{Kind, T, Msg, [{abs, true}]}];
        {none, Ms} -> [{Kind, Ms, Msg}];
        {_, cancel} -> cancel_timer(Kind), [];
        {_, {at, T}} -> set_timer(Kind, T, {'$toroco_link', Msg}), [];
        {_, Ms} -> set_timer(Kind, now_ms() + Ms, {'$toroco_link', Msg}), []
    end.
