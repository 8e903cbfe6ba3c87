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
%% A step of every delivery, inlined: the event path's calls are its cost.
-compile({inline, [delivered/3]}).

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
            %% the core whose view that was
            seen = none :: toroco_router_core:core() | none}).

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
-spec run(term(), integer(), #r{}, toroco_shell:shell()) -> {#r{}, toroco_shell:shell()}.
run(Event, Now, D = #r{core = C}, Sh) ->
    {C1, Out} = toroco_router_core:handle(Event, Now, C),
    deliver(Out, D#r{core = C1}, Sh).

%% @doc Tells the tap's subscribers when the winner, holds or latches changed.
-spec settled(#r{}, toroco_shell:shell()) -> {#r{}, toroco_shell:shell()}.
settled(D = #r{tap = #{router := Sinks}, core = C, seen = Seen, view = Old, key = Key}, Sh) ->
    case toroco_router_core:same_view(C, Seen) of
        true ->
            {D, Sh};
        false ->
            case toroco_router_core:view(C) of
                Old ->
                    {D#r{seen = C}, Sh};
                View ->
                    Info = toroco_router_core:info(C, toroco_clock:now_ms()),
                    Event = {router, stamp, Key, maps:with([winner, holds, latches], Info)},
                    {D#r{view = View, seen = C}, toroco_shell:tap(Sinks, Event, Sh)}
            end
    end;
settled(D, Sh) ->
    {D, Sh}.

-spec deadline(#r{}) -> infinity | integer().
deadline(#r{core = C}) -> toroco_router_core:next_deadline(C).

-spec rewired(map(), [{{atom(), atom()}, toroco_router_core:latch()}], [{atom(), atom()}],
              integer(), #r{}, toroco_shell:shell()) -> {#r{}, toroco_shell:shell()}.
rewired(#{sources := Srcs, buffer := Buf, idle := Idle}, Synced, Reset, Now, D, Sh) ->
    run({rewire, Srcs, #{idle => Idle}, Synced, Reset}, Now, D#r{buffer = Buf}, Sh).

-spec late({atom(), atom()}, toroco_router_core:latch() | inhibited) -> [term()].
late(_Src, inhibited) -> [];
late(Src, Latch) -> [{sync, [{Src, Latch}]}].

-spec handle(gen_statem:event_type(), term(), #r{}, toroco_shell:shell()) ->
          {[term()], [gen_statem:action()], #r{}, toroco_shell:shell()} | unknown.
handle(info, ?WIRE_ACK(_Input), D = #r{pending = {value, V}, rx = Rx, input = I}, Sh)
  when is_pid(Rx) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    {[], [], D#r{pending = none}, delivered(D, V, Sh)};
handle(info, ?WIRE_ACK(_Input), D, Sh) ->
    {[], [], D#r{inflight = false}, Sh};
handle(info, ?WIRE_RX(_Input, Pid), D, Sh) ->
    {[receiver_up], [], attach_receiver(Pid, D), Sh};
handle(info, {'DOWN', Ref, process, _, _}, D = #r{rx_mon = Ref}, Sh) ->
    {[], [], D#r{rx = undefined, rx_mon = undefined, inflight = false, pending = none}, Sh};
handle(info, ?WIRE_TAP(Subs), D = #r{key = {R, _}}, Sh) ->
    {[], [], D#r{tap = tap(Subs, R), view = none, seen = none}, Sh};
handle(info, ?WIRE_UNSUB(_, _), D, Sh) ->
    {[], [], D, Sh};
handle({call, From}, unwire, D, Sh) ->
    {[unwire], [{reply, From, ok}], D, Sh};
handle(_Type, _Content, _D, _Sh) ->
    unknown.

-spec info(integer(), #r{}) -> map().
info(Now, #r{core = C, buffer = B, rx = Rx}) ->
    Info = toroco_router_core:info(C, Now),
    Info#{buffer => B, receiver => Rx}.

%%====================================================================
%% Internals
%%====================================================================

deliver([], D, Sh) ->
    {D, Sh};
deliver(_Values, D = #r{rx = undefined}, Sh) ->
    {D, Sh};                                     % receiver down: lost, as specified
deliver([V | Vs], D = #r{buffer = all, rx = Rx, input = I}, Sh) ->
    toroco_wire:send(Rx, ?WIRE_IN(I, V)),
    deliver(Vs, D, delivered(D, V, Sh));
deliver(Values, D = #r{buffer = latest, inflight = true}, Sh) ->
    {D#r{pending = {value, lists:last(Values)}}, Sh};
deliver(Values, D = #r{buffer = latest, rx = Rx, input = I}, Sh) ->
    V = lists:last(Values),
    toroco_wire:send(Rx, ?WIRE_IN(I, V, self())),
    {D#r{inflight = true}, delivered(D, V, Sh)}.

attach_receiver(Pid, D = #r{rx_mon = Old}) ->
    _ = Old =/= undefined andalso erlang:demonitor(Old, [flush]),
    D#r{rx = Pid, rx_mon = erlang:monitor(process, Pid), inflight = false, pending = none}.

%% The observer tap: what the receiver got.
tap(Subs, Receiver) ->
    toroco_tap:select(Subs, [deliver, router], Receiver).

%% The delivery of `V' tapped into the shell.
delivered(#r{tap = #{deliver := Sinks}, key = Key}, V, Sh) ->
    toroco_shell:tap(Sinks, {deliver, stamp, Key, V}, Sh);
delivered(_D, _V, Sh) ->
    Sh.
