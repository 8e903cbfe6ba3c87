%% The messages of the event path, defined once. `toroco_wire' documents
%% them (who sends each, to whom, when, and what answers it); these macros
%% are the only way the runtime builds and matches them, so that they can
%% appear in function heads at no cost.

%% emitter -> consumer (a router or a gate): one emission of Src.
-define(WIRE_EVENT(Src, Op), {'$toroco', Src, Op}).
%% gate -> consumer: an emission of a gated output, let through.
-define(WIRE_GATED(Src, Op), {'$toroco_gate', Src, Op}).
%% consumer -> upstream: attach Consumer (an address) to Src.
-define(WIRE_SUB(Src, Consumer), {'$toroco_sub', Src, Consumer}).
%% consumer -> upstream: detach.
-define(WIRE_UNSUB(Src, Consumer), {'$toroco_unsub', Src, Consumer}).
%% upstream -> consumer: the answer to a subscription, Src's current state.
-define(WIRE_STATE(Kind, Src, Pid, Latch), {'$toroco_state', Kind, Src, Pid, Latch}).
%% upstream -> its consumers: a new incarnation is running.
-define(WIRE_HELLO(Kind, Src, Pid), {'$toroco_hello', Kind, Src, Pid}).
%% receiver -> router: (re)started, resumed or asking for a redelivery.
-define(WIRE_RX(Input, Pid), {'$toroco_rx', Input, Pid}).
%% router -> receiver: a delivery; with `buffer => latest' it names the
%% router, which waits for the ack before sending the next.
-define(WIRE_IN(Input, Value), {'$toroco_in', Input, Value}).
-define(WIRE_IN(Input, Value, Router), {'$toroco_in', Input, Value, Router}).
-define(WIRE_ACK(Input), {'$toroco_ack', Input}).
%% upstream -> its consumers on other nodes: Src is alive, with its latch
%% (`{value, V}' or `none'), every `remote_keepalive_ms' (SPEC §13).
-define(WIRE_ALIVE(Kind, Src, Latch), {'$toroco_alive', Kind, Src, Latch}).
%% a process -> itself: the idle tick (toroco_wire:idle_arm/0); a process
%% whose reductions grew by no more than IDLE_REDUCTIONS since (a tick of its
%% own costs 34 to 42 here, the lightest event about 30 more) did nothing.
-define(WIRE_IDLE, '$toroco_idle').
%% toroco_tap -> emitters and routers (its pg group): the observer tap's
%% subscriptions changed (SPEC §10); each keeps the sinks that concern it.
-define(WIRE_TAP(Subs), {'$toroco_tap', Subs}).
%% a subscription's feeder -> emitters and routers (toroco_tap_feeder): send
%% your batch now, then answer toroco_tap:flushed/3 (SPEC §10, a drain).
-define(WIRE_TAP_FLUSH(Feeder, Tag), {'$toroco_tap_flush', Feeder, Tag}).
%% the wiring server -> consumers: a node came back, subscribe again to
%% the remote sources no incarnation answers for (SPEC §13).
-define(WIRE_RESUBSCRIBE, '$toroco_resubscribe').
-define(IDLE_REDUCTIONS, 50).
%% toroco_lockstep -> a process of the event path, in lockstep (SPEC §14):
%% one message of the path (or a stimulus) to handle; the receiver answers
%% toroco_lockstep:done(Token) once it and the events it inserted are handled.
-define(WIRE_STEP(Token, Msg), {'$toroco_step', Token, Msg}).
-define(WIRE_BARRIER(Ref), {'$toroco_barrier', Ref}).
%% a process -> itself: the step is handled (an internal event queued after
%% the step's own, see toroco_wire:step_done/2).
-define(WIRE_STEP_DONE(Token), {'$toroco_step_done', Token}).
%% toroco_lockstep -> a timer's owner, inside a step: the simulated timer
%% `Kind' (a gen_statem timeout type) fired with `Msg'.
-define(WIRE_TIMER(Kind, Msg), {'$toroco_timer', Kind, Msg}).
