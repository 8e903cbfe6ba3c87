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
-export([kind/0, reg/1, init/2, run/4, settled/2, deadline/1, rewired/6, late/2, handle/4,
         info/2]).

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
            view = none :: term()}).

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
-spec run(term(), integer(), #r{}, toroco_tap:batch()) -> {#r{}, toroco_tap:batch()}.
run(Event, Now, D = #r{core = C}, B) ->
    {C1, Out} = toroco_router_core:handle(Event, Now, C),
    deliver(Out, D#r{core = C1}, B).

%% @doc Tells the tap's subscribers when the winner, holds or latches changed.
-spec settled(#r{}, toroco_tap:batch()) -> {#r{}, toroco_tap:batch()}.
settled(D = #r{tap = #{router := Sinks}, core = C, view = Old, key = Key}, B) ->
    case toroco_router_core:view(C) of
        Old -> {D, B};
        View ->
            Info = toroco_router_core:info(C, toroco_clock:now_ms()),
            Event = {router, toroco_tap:timestamp(), Key, maps:with([winner, holds, latches], Info)},
            {D#r{view = View}, toroco_tap:tap(Sinks, Event, B)}
    end;
settled(D, B) ->
    {D, B}.

-spec deadline(#r{}) -> infinity | integer().
deadline(#r{core = C}) -> toroco_router_core:next_deadline(C).

-spec rewired(map(), [{{atom(), atom()}, toroco_router_core:latch()}], [{atom(), atom()}],
              integer(), #r{}, toroco_tap:batch()) -> {#r{}, toroco_tap:batch()}.
rewired(#{sources := Srcs, buffer := Buf, idle := Idle}, Synced, Reset, Now, D, B) ->
    run({rewire, Srcs, #{idle => Idle}, Synced, Reset}, Now, D#r{buffer = Buf}, B).

-spec late({atom(), atom()}, toroco_router_core:latch() | inhibited) -> [term()].
late(_Src, inhibited) -> [];
late(Src, Latch) -> [{sync, [{Src, Latch}]}].

-spec handle(gen_statem:event_type(), term(), #r{}, toroco_tap:batch()) ->
          {[term()], [gen_statem:action()], #r{}, toroco_tap:batch()} | unknown.
handle(info, ?WIRE_ACK(_Input), D = #r{pending = {value, V}, rx = Rx, input = I}, B)
  when is_pid(Rx) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    {[], [], D#r{pending = none}, delivered(D, V, B)};
handle(info, ?WIRE_ACK(_Input), D, B) ->
    {[], [], D#r{inflight = false}, B};
handle(info, ?WIRE_RX(_Input, Pid), D, B) ->
    {[receiver_up], [], attach_receiver(Pid, D), B};
handle(info, {'DOWN', Ref, process, _, _}, D = #r{rx_mon = Ref}, B) ->
    {[], [], D#r{rx = undefined, rx_mon = undefined, inflight = false, pending = none}, B};
handle(info, ?WIRE_TAP(Subs), D = #r{key = {R, _}}, B) ->
    {[], [], D#r{tap = tap(Subs, R), view = none}, B};
handle(info, ?WIRE_UNSUB(_, _), D, B) ->
    {[], [], D, B};
handle({call, From}, unwire, D, B) ->
    {[unwire], [{reply, From, ok}], D, B};
handle(_Type, _Content, _D, _B) ->
    unknown.

-spec info(integer(), #r{}) -> map().
info(Now, #r{core = C, buffer = B, rx = Rx}) ->
    Info = toroco_router_core:info(C, Now),
    Info#{buffer => B, receiver => Rx}.

%%====================================================================
%% Internals
%%====================================================================

deliver([], D, B) ->
    {D, B};
deliver(_Values, D = #r{rx = undefined}, B) ->
    {D, B};                                     % receiver down: lost, as specified
deliver([V | Vs], D = #r{buffer = all, rx = Rx, input = I}, B) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V)),
    deliver(Vs, D, delivered(D, V, B));
deliver(Values, D = #r{buffer = latest, inflight = true}, B) ->
    {D#r{pending = {value, lists:last(Values)}}, B};
deliver(Values, D = #r{buffer = latest, rx = Rx, input = I}, B) ->
    V = lists:last(Values),
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    {D#r{inflight = true}, delivered(D, V, B)}.

attach_receiver(Pid, D = #r{rx_mon = Old}) ->
    _ = Old =/= undefined andalso erlang:demonitor(Old, [flush]),
    D#r{rx = Pid, rx_mon = erlang:monitor(process, Pid), inflight = false, pending = none}.

%% The observer tap: what the receiver got.
tap(Subs, Receiver) ->
    toroco_tap:select(Subs, [deliver, router], Receiver).

%% The tap's batch with the delivery of `V'.
delivered(#r{tap = #{deliver := Sinks}, key = Key}, V, B) ->
    toroco_tap:tap(Sinks, {deliver, toroco_tap:timestamp(), Key, V}, B);
delivered(_D, _V, B) ->
    B.
