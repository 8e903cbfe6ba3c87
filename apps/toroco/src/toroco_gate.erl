%% @doc The inhibition gate of one inhibited output (or of a same-layer pair
%% of outputs that inhibit each other): `toroco_gate_core' run in the
%% consumer shell (`toroco_consumer'), with what is a gate's own: being an
%% upstream in its turn.
%%
%% It lives under `toroco_routers_sup' beside the routers, registered as
%% `toroco_names:gate(SmallestMember)'. Upstream it is a consumer like a router:
%% it subscribes to its members' emitters and to its inhibitors' upstreams.
%% Downstream it is an upstream like an emitter: routers and other gates that
%% list a member subscribe to it (`WIRE_SUB', answered with `WIRE_STATE') and
%% receive `WIRE_GATED(Src, Op)'. While a member is inhibited nothing of it
%% goes downstream; becoming inhibited sends an `unset' (its holds end
%% everywhere), becoming free again re-sends its latch as a fresh `set'.
-module(toroco_gate).
-behaviour(toroco_consumer).

-include("toroco_wire.hrl").

-export([info/1]).
-export([kind/0, reg/1, init/2, run/4, settled/2, deadline/1, rewired/6, late/2, handle/4,
         info/2]).

-record(g, {core = toroco_gate_core:new() :: toroco_gate_core:core(),
            %% member -> the addresses of its subscribers downstream
            subs = #{} :: #{{atom(), atom()} => [toroco_wire:address()]},
            %% whether a keep-alive for remote subscribers is on its way
            beating = false :: boolean()}).

%%====================================================================
%% API
%%====================================================================

%% @doc Per member: inhibited, inhibitors, latch, inhibitor holds; `none' if the
%% gate is not running.
-spec info({atom(), atom()}) -> #{{atom(), atom()} => map()} | none.
info(Key) ->
    toroco_consumer:info(?MODULE, Key).

%%====================================================================
%% toroco_consumer
%%====================================================================

-spec kind() -> gate.
kind() -> gate.

-spec reg({atom(), atom()}) -> atom().
reg(Key) -> toroco_names:gate(Key).

%% A restarted gate announces itself before anything else, so its
%% subscribers listen to this incarnation from here on.
-spec init({atom(), atom()}, map()) -> #g{}.
init(_Key, #{subs := Subs}) ->
    maps:foreach(fun(M, Regs) ->
                         [toroco_wire:send(toroco_wire:address(R), ?WIRE_HELLO(gate, M, self()))
                          || R <- Regs]
                 end, Subs),
    #g{}.

%% @doc Feeds one event to the core and forwards what comes out. A gate
%% taps nothing: the batch passes.
-spec run(term(), integer(), #g{}, toroco_shell:shell()) -> {#g{}, toroco_shell:shell()}.
run(Event, Now, D = #g{core = C, subs = Subs}, Sh) ->
    {C1, Fwd} = toroco_gate_core:handle(Event, Now, C),
    _ = [toroco_wire:send(R, ?WIRE_GATED(M, Op)) || {M, Op} <- Fwd, R <- maps:get(M, Subs, [])],
    {D#g{core = C1}, Sh}.

-spec settled(#g{}, toroco_shell:shell()) -> {#g{}, toroco_shell:shell()}.
settled(D, Sh) -> {D, Sh}.

-spec deadline(#g{}) -> infinity | integer().
deadline(#g{core = C}) -> toroco_gate_core:next_deadline(C).

%% Subscribers that attached on their own stay; the planned ones are added.
-spec rewired(map(), [{{atom(), atom()}, toroco_router_core:latch()}], [{atom(), atom()}],
              integer(), #g{}, toroco_shell:shell()) -> {#g{}, toroco_shell:shell()}.
rewired(#{members := Members, entries := Entries, subs := Planned}, Synced, Reset, Now,
        D = #g{subs = Old}, Sh) ->
    Subs = maps:from_list(
             [{M, lists:usort([toroco_wire:address(R) || R <- maps:get(M, Planned, [])]
                              ++ maps:get(M, Old, []))}
              || M <- Members]),
    run({rewire, Members, Entries, Synced, Reset}, Now, D#g{subs = Subs}, Sh).

-spec late({atom(), atom()}, toroco_router_core:latch() | inhibited) -> [term()].
late(Src, {value, V}) -> [{op, Src, {set, V}}];
late(_Src, _NoLatch) -> [].

-spec handle(gen_statem:event_type(), term(), #g{}, toroco_shell:shell()) ->
          {[], [gen_statem:action()], #g{}, toroco_shell:shell()} | unknown.
handle(info, ?WIRE_SUB(Src, Consumer), D = #g{core = C, subs = Subs}, Sh) ->
    case lists:member(Src, toroco_gate_core:members(C)) of
        true ->
            State = member_state(Src, C),
            toroco_wire:send(Consumer, ?WIRE_STATE(gate, Src, self(), State)),
            D1 = D#g{subs = Subs#{Src => lists:usort([Consumer | maps:get(Src, Subs, [])])}},
            beat(D1, Sh);
        false ->
            toroco_wire:send(Consumer, ?WIRE_STATE(gate, Src, self(), none)),
            {[], [], D, Sh}
    end;
handle(info, ?WIRE_UNSUB(Src, Consumer), D = #g{subs = Subs}, Sh) ->
    {[], [], D#g{subs = Subs#{Src => lists:delete(Consumer, maps:get(Src, Subs, []))}}, Sh};
handle({timeout, '$toroco_alive'}, beat, D = #g{core = C, subs = Subs}, Sh) ->
    %% Remote subscribers hear from each member now and then, with what
    %% they would get on subscribing (SPEC §13).
    maps:foreach(fun(M, Consumers) ->
                         Msg = ?WIRE_ALIVE(gate, M, member_state(M, C)),
                         [toroco_wire:send(R, Msg) || R <- Consumers, toroco_wire:remote(R)]
                 end, Subs),
    beat(D#g{beating = false}, Sh);
handle(_Type, _Content, _D, _Sh) ->
    unknown.

member_state(M, C) ->
    case toroco_gate_core:is_inhibited(M, C) of
        true -> inhibited;
        false -> toroco_gate_core:state_for(M, C)
    end.

%% The keep-alive, while there are remote subscribers: a named gen_statem
%% timeout in real time (as the emitters' is: it is about the network, not
%% the robot's time), set once and again when it fires; in lockstep a
%% timer of the world's (toroco_clock:link_timer/3).
beat(D = #g{beating = true}, Sh) -> {[], [], D, Sh};
beat(D = #g{subs = Subs}, Sh) ->
    case lists:any(fun toroco_wire:remote/1, lists:append(maps:values(Subs))) of
        true ->
            {[], toroco_clock:link_timer({timeout, '$toroco_alive'}, toroco_wire:keepalive_ms(), beat),
             D#g{beating = true}, Sh};
        false -> {[], [], D, Sh}
    end.

-spec info(integer(), #g{}) -> #{{atom(), atom()} => map()}.
info(Now, #g{core = C}) ->
    toroco_gate_core:info(C, Now).
