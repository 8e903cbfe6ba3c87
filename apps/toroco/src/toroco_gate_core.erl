%% @doc The decisions of an inhibition gate, as a pure function.
%%
%% A gate is the single authority on whether its outputs are inhibited (SPEC §4
%% "Inhibition"). It sits between an inhibited output's emitter and every
%% router (or other gate) that lists the output, and it tracks the holds of the
%% output's inhibitors. Usually a gate has one member output; two outputs of
%% the same layer that inhibit each other (the Torobot's avoids) share one gate,
%% so that who inhibits whom is decided in one place, in one order: the output
%% whose hold started first wins, and outputs that start holding at the same
%% moment are taken in Erlang term order (the smaller wins).
%%
%% The process shell is `toroco_gate'. Here: {@link handle/3} takes an event and
%% returns the operations to forward downstream as `{Member, Op}', oldest
%% first; {@link state_for/2} is what a new subscriber is told; {@link info/2}
%% is the inspection view.
-module(toroco_gate_core).

-export([new/0, handle/3, next_deadline/1, state_for/2, is_inhibited/2, info/2, members/1]).
-export_type([core/0]).

-type source() :: {atom(), atom()}.
-type latch() :: toroco_router_core:latch().
-type op() :: toroco_router_core:op().
-type default() :: non_neg_integer() | infinity.
-type event() ::
        {op, source(), op()}
      | tick
      | {rewire, [source()], #{source() => [{source(), default()}]},
         Synced :: [{source(), latch()}], Reset :: [source()]}.

-record(member, {latch = none :: latch(), inhibited = false :: boolean()}).
-record(gate, {members = #{} :: #{source() => #member{}},
               %% member -> its inhibitors with their wiring hold
               entries = #{} :: #{source() => [{source(), default()}]},
               %% inhibitor -> the members of this gate it inhibits
               targets = #{} :: #{source() => [source()]},
               %% {member, inhibitor} -> infinity | deadline
               holds = #{} :: #{{source(), source()} => infinity | integer()},
               next = infinity :: infinity | integer()}).

-opaque core() :: #gate{}.

%%====================================================================
%% API
%%====================================================================

-spec new() -> core().
new() -> #gate{}.

%% @doc Applies one event at `Now'; returns the operations to forward to the
%% subscribers of each member, in order.
-spec handle(event(), integer(), core()) -> {core(), [{source(), op()}]}.
handle(Event, Now, G = #gate{next = Next}) when Next =< Now ->
    {G1, Fwd1} = evaluate(expire(Now, G), []),
    {G2, Fwd2} = handle(Event, Now, G1),
    {G2, Fwd1 ++ Fwd2};
handle(tick, _Now, G) ->
    {G, []};
handle({op, Src, Op}, Now, G) ->
    {G1, Fwd} = emission(Src, Op, Now, G),
    finish(evaluate(G1, Fwd));
handle({rewire, Members, Entries, Synced, Reset}, Now, G) ->
    G1 = rewire(Members, Entries, Reset, G),
    %% Inhibitors' latches first, then each latched member as a fresh `set', in
    %% term order, so that of two members already holding the smaller wins.
    {MemberSync, InhSync} = lists:partition(
                              fun({Src, _}) -> maps:is_key(Src, G1#gate.members) end,
                              lists:sort(Synced)),
    G2 = lists:foldl(fun({I, {value, V}}, Acc) -> inhibitor_op(I, {set, V}, Now, Acc);
                        ({_, none}, Acc) -> Acc
                     end, G1, InhSync),
    {G3, Fwd} = evaluate(G2, []),
    finish(lists:foldl(fun({M, {value, V}}, {GAcc, FAcc}) ->
                               {GAcc1, F1} = emission(M, {set, V}, Now, GAcc),
                               evaluate(GAcc1, FAcc ++ F1);
                          ({_, none}, Acc) -> Acc
                       end, {G3, Fwd}, MemberSync)).

-spec next_deadline(core()) -> infinity | integer().
next_deadline(#gate{next = Next}) -> Next.

-spec members(core()) -> [source()].
members(#gate{members = Ms}) -> lists:sort(maps:keys(Ms)).

%% @doc The latch a new subscriber of `Member' starts from: none while the
%% member is inhibited (an inhibited wire carries nothing).
-spec state_for(source(), core()) -> latch().
state_for(Member, #gate{members = Ms}) ->
    case Ms of
        #{Member := #member{inhibited = false, latch = L}} -> L;
        #{} -> none
    end.

%% @doc Whether `Member' is inhibited now.
-spec is_inhibited(source(), core()) -> boolean().
is_inhibited(Member, #gate{members = Ms}) ->
    case Ms of
        #{Member := #member{inhibited = I}} -> I;
        #{} -> false
    end.

-spec info(core(), integer()) -> #{source() => map()}.
info(#gate{members = Ms, entries = Es, holds = Hs}, Now) ->
    maps:map(fun(M, #member{latch = L, inhibited = Inh}) ->
                     Inhibitors = [I || {I, _} <- maps:get(M, Es, [])],
                     #{inhibited => Inh, latch => L, inhibitors => Inhibitors,
                       holds => [{I, remaining(maps:get({M, I}, Hs), Now)}
                                 || I <- Inhibitors, maps:is_key({M, I}, Hs)]}
             end, Ms).

%%====================================================================
%% Emissions
%%====================================================================

emission(Src, Op, Now, G = #gate{members = Ms}) ->
    case Ms of
        #{Src := M = #member{inhibited = true}} ->
            %% A set while inhibited still updates the latch; a send is dropped
            %% and clears it. Nothing goes downstream and nothing is inhibited.
            {G#gate{members = Ms#{Src := M#member{latch = latch_after(Op)}}}, []};
        #{Src := M} ->
            G1 = G#gate{members = Ms#{Src := M#member{latch = latch_after(Op)}}},
            {inhibitor_op(Src, Op, Now, G1), [{Src, Op}]};
        #{} ->
            {inhibitor_op(Src, Op, Now, G), []}
    end.

latch_after({set, V}) -> {value, V};
latch_after(_) -> none.

%% The inhibitor I's new emission replaces its hold at each member it inhibits.
inhibitor_op(I, Op, Now, G = #gate{targets = Ts}) ->
    lists:foldl(fun(M, Acc) -> set_hold(M, I, Op, Now, Acc) end, G, maps:get(I, Ts, [])).

set_hold(M, I, Op, Now, G = #gate{holds = Hs, entries = Es}) ->
    Hold = case Op of
               {set, _} -> infinity;
               unset -> none;
               {send, _, default} -> deadline(default_hold(I, maps:get(M, Es)), Now);
               {send, _, H} -> deadline(H, Now)
           end,
    case Hold of
        none -> G#gate{holds = maps:remove({M, I}, Hs)};
        _ -> G#gate{holds = Hs#{{M, I} => Hold}}
    end.

default_hold(I, Entries) ->
    {I, D} = lists:keyfind(I, 1, Entries),
    D.

deadline(0, _Now) -> none;
deadline(infinity, _Now) -> infinity;
deadline(Ms, Now) -> Now + Ms.

%%====================================================================
%% Deciding who is inhibited
%%====================================================================

%% Inhibitions first (so whoever already holds keeps winning), then releases,
%% one member at a time, smallest first, until nothing changes.
evaluate(G = #gate{members = Ms}, Fwd) ->
    Sorted = lists:sort(maps:keys(Ms)),
    ToInhibit = [M || M <- Sorted, not inhibited(M, G), should_inhibit(M, G)],
    ToRelease = [M || M <- Sorted, inhibited(M, G), not should_inhibit(M, G)],
    case {ToInhibit, ToRelease} of
        {[M | _], _} -> evaluate(inhibit(M, G), Fwd ++ [{M, unset}]);
        {[], [M | _]} ->
            {G1, F} = release(M, G),
            evaluate(G1, Fwd ++ F);
        {[], []} -> {G, Fwd}
    end.

inhibited(M, #gate{members = Ms}) ->
    #member{inhibited = I} = maps:get(M, Ms),
    I.

should_inhibit(M, G = #gate{entries = Es, holds = Hs, members = Ms}) ->
    lists:any(fun({I, _}) ->
                      maps:is_key({M, I}, Hs) andalso
                          not (maps:is_key(I, Ms) andalso inhibited(I, G))
              end, maps:get(M, Es, [])).

%% An inhibited output inhibits nothing: its holds at the other members end.
inhibit(M, G = #gate{members = Ms, targets = Ts, holds = Hs}) ->
    Member = maps:get(M, Ms),
    Hs1 = lists:foldl(fun(T, Acc) -> maps:remove({T, M}, Acc) end, Hs, maps:get(M, Ts, [])),
    G#gate{members = Ms#{M := Member#member{inhibited = true}}, holds = Hs1}.

%% Released with a latch: the latch re-enters everywhere as a fresh set.
release(M, G = #gate{members = Ms}) ->
    Member = #member{latch = L} = maps:get(M, Ms),
    G1 = G#gate{members = Ms#{M := Member#member{inhibited = false}}},
    case L of
        {value, V} -> {inhibitor_op(M, {set, V}, 0, G1), [{M, {set, V}}]};
        none -> {G1, []}
    end.

finish({G, Fwd}) -> {G#gate{next = earliest(G)}, Fwd}.

expire(Now, G = #gate{holds = Hs}) ->
    G1 = G#gate{holds = maps:filter(fun(_, D) -> not (is_integer(D) andalso D =< Now) end, Hs)},
    G1#gate{next = earliest(G1)}.

earliest(#gate{holds = Hs}) ->
    maps:fold(fun(_, D, E) when is_integer(D) -> min(D, E);
                 (_, _, E) -> E
              end, infinity, Hs).

%%====================================================================
%% Wiring
%%====================================================================

rewire(Members, Entries, Reset, G = #gate{members = OldMs, holds = OldHs}) ->
    Ms = maps:from_list([{M, case {OldMs, lists:member(M, Reset)} of
                                 {#{M := Kept}, false} -> Kept;
                                 _ -> #member{}
                             end} || M <- Members]),
    Targets = maps:fold(fun(M, Inhs, Acc) ->
                                lists:foldl(fun({I, _}, A) ->
                                                    maps:update_with(I, fun(L) -> [M | L] end,
                                                                     [M], A)
                                            end, Acc, Inhs)
                        end, #{}, Entries),
    Hs = maps:filter(fun({M, I}, _) ->
                             maps:is_key(M, Ms) andalso
                                 lists:keymember(I, 1, maps:get(M, Entries, [])) andalso
                                 not lists:member(I, Reset) andalso
                                 not lists:member(M, Reset)
                     end, OldHs),
    G#gate{members = Ms, entries = Entries, targets = Targets, holds = Hs}.

remaining(infinity, _Now) -> infinity;
remaining(D, Now) -> max(0, D - Now).
