%% @doc The router of one wired input: `toroco_router_core' run in the
%% consumer shell (`toroco_consumer'), with what is a router's own: its
%% receiver, its deliveries, and what it tells the observer tap.
%%
%% It lives under `toroco_routers_sup', registered as
%% `toroco_names:router(Receiver, Input)', and reads its configuration from the
%% wiring table, so a restarted router finds its place again: it re-subscribes
%% to its sources' upstreams, which hand over their latches, and re-delivers
%% the winner (emitters are the authority for their latches; timed holds in
%% flight are lost).
%%
%% Out to the receiver: `WIRE_IN(Input, Value)', or with `buffer => latest'
%% `WIRE_IN(Input, Value, Router)', acked by `WIRE_ACK(Input)' before the
%% next (the newest value meanwhile waits, older ones count as delivered).
%% A receiver announces itself with `WIRE_RX' (see `toroco_wire').
-module(toroco_router).
-behaviour(toroco_consumer).

-include("toroco_wire.hrl").

-export([unwire/1, info/1]).
-export([kind/0, reg/1, init/2, run/3, settled/1, deadline/1, rewired/5, late/2, handle/3,
         info/2, tap_batch/1, tap_batch/2]).

-record(r, {key :: {atom(), atom()},
            input :: atom(),
            core = toroco_router_core:new() :: toroco_router_core:core(),
            rx :: pid() | undefined,
            rx_mon :: reference() | undefined,
            buffer = all :: all | latest,
            inflight = false :: boolean(),
            pending = none :: none | {value, term()},
            %% the observer tap's sinks about this input's receiver, and
            %% what it last reported of the router's state
            tap = #{} :: toroco_tap:sinks(),
            view = none :: term(),
            %% the tapped events not sent yet (toroco_tap:after_event/3)
            batch = [] :: toroco_tap:batch()}).

%%====================================================================
%% API
%%====================================================================

%% @doc The input is being unwired as a whole: drop every source (delivering
%% `idle' if one held) before the router is stopped.
-spec unwire({atom(), atom()}) -> ok.
unwire(Key) ->
    _ = toroco_consumer:call(?MODULE, Key, unwire, 5000),
    ok.

%% @doc The inspection view of the input (SPEC §6), or `none' if the router is
%% not running.
-spec info({atom(), atom()}) -> map() | none.
info(Key) ->
    toroco_consumer:info(?MODULE, Key).

%%====================================================================
%% toroco_consumer
%%====================================================================

-spec kind() -> router.
kind() -> router.

-spec reg({atom(), atom()}) -> atom().
reg({R, I}) -> toroco_names:router(R, I).

-spec init({atom(), atom()}, map()) -> #r{}.
init(Key = {R, I}, _Cfg) ->
    ok = toroco_tap:join(),
    D = #r{key = Key, input = I, tap = tap(toroco_tap:current(), R)},
    case whereis(toroco_names:process(R)) of
        undefined -> D;
        Pid -> attach_receiver(Pid, D)
    end.

%% @doc Feeds one event to the core and delivers what comes out.
-spec run(term(), integer(), #r{}) -> #r{}.
run(Event, Now, D = #r{core = C}) ->
    {C1, Out} = toroco_router_core:handle(Event, Now, C),
    deliver(Out, D#r{core = C1}).

%% @doc Tells the tap's subscribers when the winner, holds or latches changed.
-spec settled(#r{}) -> #r{}.
settled(D = #r{tap = #{router := Sinks}, core = C, view = Old, key = Key}) ->
    case toroco_router_core:view(C) of
        Old -> D;
        View ->
            Info = toroco_router_core:info(C, toroco_clock:now_ms()),
            Event = {router, toroco_tap:timestamp(), Key, maps:with([winner, holds, latches], Info)},
            D#r{view = View, batch = toroco_tap:tap(Sinks, Event, D#r.batch)}
    end;
settled(D) ->
    D.

-spec deadline(#r{}) -> infinity | integer().
deadline(#r{core = C}) -> toroco_router_core:next_deadline(C).

-spec rewired(map(), [{{atom(), atom()}, toroco_router_core:latch()}], [{atom(), atom()}],
              integer(), #r{}) -> #r{}.
rewired(#{sources := Srcs, buffer := B, idle := Idle}, Synced, Reset, Now, D) ->
    run({rewire, Srcs, #{idle => Idle}, Synced, Reset}, Now, D#r{buffer = B}).

-spec late({atom(), atom()}, toroco_router_core:latch() | inhibited) -> [term()].
late(_Src, inhibited) -> [];
late(Src, Latch) -> [{sync, [{Src, Latch}]}].

-spec handle(gen_statem:event_type(), term(), #r{}) ->
          {events, [term()], #r{}} | {reply, term(), [term()], #r{}} | unknown.
handle(info, ?WIRE_ACK(_Input), D = #r{pending = {value, V}, rx = Rx, input = I})
  when is_pid(Rx) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    {events, [], delivered(D#r{pending = none}, V)};
handle(info, ?WIRE_ACK(_Input), D) ->
    {events, [], D#r{inflight = false}};
handle(info, ?WIRE_RX(_Input, Pid), D) ->
    {events, [receiver_up], attach_receiver(Pid, D)};
handle(info, {'DOWN', Ref, process, _, _}, D = #r{rx_mon = Ref}) ->
    {events, [], D#r{rx = undefined, rx_mon = undefined, inflight = false, pending = none}};
handle(info, ?WIRE_TAP(Subs), D = #r{key = {R, _}}) ->
    {events, [], D#r{tap = tap(Subs, R), view = none}};
handle(info, ?WIRE_UNSUB(_, _), D) ->
    {events, [], D};
handle({call, _}, unwire, D) ->
    {reply, ok, [unwire], D};
handle(_Type, _Content, _D) ->
    unknown.

%% @doc The tapped events not sent yet (toroco_tap:after_event/3).
-spec tap_batch(#r{}) -> toroco_tap:batch().
tap_batch(#r{batch = B}) -> B.

-spec tap_batch(toroco_tap:batch(), #r{}) -> #r{}.
tap_batch(B, D) -> D#r{batch = B}.

-spec info(integer(), #r{}) -> map().
info(Now, #r{core = C, buffer = B, rx = Rx}) ->
    Info = toroco_router_core:info(C, Now),
    Info#{buffer => B, receiver => Rx}.

%%====================================================================
%% Internals
%%====================================================================

deliver([], D) ->
    D;
deliver(_Values, D = #r{rx = undefined}) ->
    D;                                          % receiver down: lost, as specified
deliver([V | Vs], D = #r{buffer = all, rx = Rx, input = I}) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V)),
    deliver(Vs, delivered(D, V));
deliver(Values, D = #r{buffer = latest, inflight = true}) ->
    D#r{pending = {value, lists:last(Values)}};
deliver(Values, D = #r{buffer = latest, rx = Rx, input = I}) ->
    V = lists:last(Values),
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    delivered(D#r{inflight = true}, V).

attach_receiver(Pid, D = #r{rx_mon = Old}) ->
    _ = Old =/= undefined andalso erlang:demonitor(Old, [flush]),
    D#r{rx = Pid, rx_mon = erlang:monitor(process, Pid), inflight = false, pending = none}.

%% The observer tap: what the receiver got.
tap(Subs, Receiver) ->
    toroco_tap:select(Subs, [deliver, router], Receiver).

delivered(D = #r{tap = #{deliver := Sinks}, key = Key, batch = B}, V) ->
    D#r{batch = toroco_tap:tap(Sinks, {deliver, toroco_tap:timestamp(), Key, V}, B)};
delivered(D, _V) ->
    D.
