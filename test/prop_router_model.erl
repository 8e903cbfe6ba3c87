%% @doc Brute-force oracles of SPEC §4, written from the SPEC and not from
%% `toroco_router_core' or `toroco_gate_core': the properties in `prop_router'
%% check those cores, and the processes, against them.
%%
%% <b>Suppression</b> (one input's router). The oracle keeps nothing but the
%% whole event history `[{T, Event}]' (events as `toroco_router_core' takes
%% them) and the values delivered so far. Who holds, with which latch, is
%% recomputed at every question from that history: a source's state is the fold
%% of its own emissions since it last became fresh (was newly wired, or re-wired
%% with a new upstream). A hold ends at its deadline D: at D it no longer
%% holds. Every hold end between two events is a moment of its own at which the
%% winner is re-picked, so the oracle also checks that a core which handles
%% several expiries at once decides as if it had handled each at its time.
%% {@link router_new/0}, {@link router_step/3}, {@link router_info/2},
%% {@link router_next_deadline/2}.
%%
%% <b>Inhibition</b> (one gate: an inhibited output, or a same-layer pair).
%% Whether a member is inhibited is a closed formula of who holds on it: an
%% outside inhibitor that holds inhibits it; of a pair, a member that holds on
%% the other inhibits it unless it is inhibited itself, and when both hold the
%% one whose hold started first wins (hold starts are numbered in the order the
%% gate takes them; the members' latches at wiring time are taken in term
%% order, so "simultaneous" means "smaller first"). The oracle applies the
%% consequences until nothing changes: a member that becomes inhibited is cut
%% (an `unset' goes downstream and its own holds end); released members are
%% freed one at a time, smallest first, and a latched one re-enters as a fresh
%% `set'. {@link gate_new/0}, {@link gate_step/3}, {@link gate_info/2},
%% {@link gate_state_for/2}, {@link gate_next_deadline/2}.
-module(prop_router_model).

-export([router_new/0, router_step/3, router_info/2, router_next_deadline/2,
         router_sources/1, router_delivered/1]).
-export([gate_new/0, gate_step/3, gate_info/2, gate_state_for/2, gate_next_deadline/2,
         gate_inhibited/2, gate_members/1]).

%%====================================================================
%% Suppression: the router oracle
%%====================================================================

%% hist: [{Seq, T, Event}] oldest first; out: every delivery, with
%% `receiver_up' marks (the last value is forgotten there); t: the time of the
%% last step.
router_new() ->
    #{hist => [], out => [], t => 0}.

%% @doc The deliveries the receiver must see for `Event' at `T' (including the
%% hold ends since the previous step), and the new oracle.
router_step(R = #{hist := H, t := Tprev}, T, Event) ->
    Ends = lists:usort([E || {_, {_, E}} <- states(H), is_integer(E), E > Tprev, E =< T]),
    {R1, Out1} = lists:foldl(fun(D, {RAcc, OAcc}) ->
                                     {RA, O} = expiry(RAcc, D),
                                     {RA, OAcc ++ O}
                             end, {R, []}, Ends),
    {R2, Out2} = event(R1, T, Event),
    {R2#{t := T}, Out1 ++ Out2}.

%% @doc What `toroco_router_core:info/2' must say at `T' (right after a step).
router_info(#{hist := H} = R, T) ->
    States = states(H),
    #{sources => [S || {S, _} <- States],
      winner => winner(H, T),
      holds => [{S, remaining(E, T)} || {S, {_, E}} <- States, holding(E, T)],
      latches => [{S, V} || {S, {{value, V}, _}} <- States],
      last => last(R)}.

%% @doc The earliest hold end after `T', or `infinity'.
router_next_deadline(#{hist := H}, T) ->
    lists:min([infinity | [E || {_, {_, E}} <- states(H), is_integer(E), E > T]]).

router_sources(#{hist := H}) -> [S || {S, _} <- wiring(H)].

%% @doc Every value delivered so far, oldest first (receiver restarts left out).
router_delivered(#{out := Out}) -> [V || {value, V} <- Out].

%% A moment at which one or more holds end.
expiry(R = #{hist := H}, D) ->
    repick(R, winner(H, D - 1) =/= none, winner(H, D), idle(H)).

event(R = #{hist := H}, T, Ev) ->
    H1 = H ++ [{length(H) + 1, T, Ev}],
    Before = winner(H, T),
    R1 = R#{hist := H1},
    case Ev of
        {op, Src, Op} ->
            case position(Src, wiring(H)) of
                none ->
                    {R1, []};
                J ->
                    Higher = [S || {S, St} <- states(H), position(S, wiring(H)) < J,
                                   holding(element(2, St), T)],
                    {R2, Out} = case {Higher, Op} of
                                    {[], {send, V, _}} -> deliver(R1, V);
                                    {[], {set, V}} -> deliver(R1, V);
                                    _ -> {R1, []}
                                end,
                    {R3, Out2} = repick(R2, Before =/= none, winner(H1, T), idle(H1)),
                    {R3, Out ++ Out2}
            end;
        tick ->
            {R1, []};
        receiver_up ->
            #{out := Out} = R1,
            repick(R1#{out := Out ++ [receiver_up]}, false, winner(H1, T), idle(H1));
        {sync, _} ->
            repick(R1, Before =/= none, winner(H1, T), idle(H1));
        {rewire, _, _, _, _} ->
            repick(R1, Before =/= none, winner(H1, T), idle(H1))
    end.

%% After anything: the highest holder's latch is re-delivered if it differs
%% from the last value; with no holder left after having one, the idle value.
repick(R, HadHolder, none, Idle) ->
    case {HadHolder, Idle} of
        {true, {value, V}} -> deliver(R, V);
        _ -> {R, []}
    end;
repick(R = #{hist := H}, _HadHolder, Src, _Idle) ->
    {Latch, _} = proplists:get_value(Src, states(H)),
    case {Latch, last(R)} of
        {L, L} -> {R, []};
        {{value, V}, _} -> deliver(R, V);
        {none, _} -> {R, []}
    end.

deliver(R = #{out := Out}, V) -> {R#{out := Out ++ [{value, V}]}, [V]}.

last(#{out := Out}) ->
    case lists:reverse(Out) of
        [{value, _} = L | _] -> L;
        _ -> none                       % nothing yet, or forgotten at receiver_up
    end.

%% The wiring in effect after history H: [{Src, WiringHold}] in priority order.
wiring(H) ->
    case [W || {_, _, {rewire, W, _, _, _}} <- H] of
        [] -> [];
        Ws -> lists:last(Ws)
    end.

idle(H) ->
    case [O || {_, _, {rewire, _, O, _, _}} <- H] of
        [] -> none;
        Os -> maps:get(idle, lists:last(Os), none)
    end.

position(Src, W) -> position(Src, W, 1).
position(_Src, [], _I) -> none;
position(Src, [{Src, _} | _], I) -> I;
position(Src, [_ | W], I) -> position(Src, W, I + 1).

winner(H, T) ->
    case [S || {S, {_, E}} <- states(H), holding(E, T)] of
        [] -> none;
        [S | _] -> S
    end.

holding(none, _T) -> false;
holding(infinity, _T) -> true;
holding(E, T) -> T < E.

remaining(infinity, _T) -> infinity;
remaining(E, T) -> E - T.

%% Each wired source's {Latch, HoldEnd}, in priority order.
states(H) -> [{S, state(S, H)} || {S, _} <- wiring(H)].

%% A source's state: the fold of what happened to it since its last fresh
%% start. Hold ends are absolute: none | infinity | T.
state(Src, H) ->
    Fresh = fresh_start(Src, H),
    {_, St} = lists:foldl(
                fun({Seq, _, _}, Acc) when Seq < Fresh -> Acc;
                   ({_, _, {rewire, W, _, Synced, _}}, {_, St}) ->
                        {W, synced(Src, Synced, St)};
                   ({_, _, {sync, Synced}}, {W, St}) ->
                        {W, synced(Src, Synced, St)};
                   ({_, T, {op, S, Op}}, {W, _}) when S =:= Src ->
                        {W, apply_op(Op, T, proplists:get_value(Src, W))};
                   (_, Acc) -> Acc
                end, {[], {none, none}}, H),
    St.

%% The sequence number of the re-wiring at which the source's current life at
%% this router began.
fresh_start(Src, H) ->
    {Start, _} = lists:foldl(
                   fun({Seq, _, {rewire, W, _, _, Reset}}, {Start, Prev}) ->
                           Now = lists:keymember(Src, 1, W),
                           Was = lists:keymember(Src, 1, Prev),
                           case Now andalso (not Was orelse lists:member(Src, Reset)) of
                               true -> {Seq, W};
                               false -> {Start, W}
                           end;
                      (_, Acc) -> Acc
                   end, {0, []}, H),
    Start.

synced(Src, Synced, St) ->
    case lists:keyfind(Src, 1, Synced) of
        {Src, {value, V}} -> {{value, V}, infinity};
        _ -> St
    end.

apply_op({send, _V, Hold}, T, Default) ->
    H = case Hold of default -> Default; _ -> Hold end,
    {none, hold_end(H, T)};
apply_op({set, V}, _T, _Default) -> {{value, V}, infinity};
apply_op(unset, _T, _Default) -> {none, none}.

hold_end(0, _T) -> none;
hold_end(infinity, _T) -> infinity;
hold_end(Ms, T) -> T + Ms.

%%====================================================================
%% Inhibition: the gate oracle
%%====================================================================

%% members: sorted; entries: member -> [{Inhibitor, WiringHold}];
%% latch: member -> latch; inh: inhibited members; holds: {Member, Inhibitor}
%% -> {End, StartNo}; n: the next hold start number.
gate_new() ->
    #{members => [], entries => #{}, latch => #{}, inh => [], holds => #{}, n => 0,
      t => 0}.

%% @doc The operations forwarded downstream, `[{Member, Op}]' in order, for
%% `Event' at `T' (including the hold ends since the previous step).
gate_step(G = #{t := Tprev, holds := Hs}, T, Event) ->
    Ends = lists:usort([E || {E, _} <- maps:values(Hs), is_integer(E), E > Tprev, E =< T]),
    {G1, Fwd1} = lists:foldl(fun(D, {GAcc, FAcc}) ->
                                     {GA, F} = settle(GAcc, D, []),
                                     {GA, FAcc ++ F}
                             end, {G, []}, Ends),
    {G2, Fwd2} = gate_event(G1, T, Event),
    {G2#{t := T}, Fwd1 ++ Fwd2}.

gate_event(G, _T, tick) ->
    {G, []};
gate_event(G, T, {op, Src, Op}) ->
    {G1, F} = emission(G, T, Src, Op),
    settle(G1, T, F);
gate_event(G = #{members := OldMs, latch := OldL, inh := OldInh, holds := OldHs}, T,
           {rewire, Members, Entries, Synced, Reset}) ->
    Kept = [M || M <- Members, lists:member(M, OldMs), not lists:member(M, Reset)],
    Latch = maps:from_list([{M, case lists:member(M, Kept) of
                                    true -> maps:get(M, OldL);
                                    false -> none
                                end} || M <- Members]),
    Hs = maps:filter(fun({M, I}, _) ->
                             lists:member(M, Kept) andalso
                                 lists:keymember(I, 1, maps:get(M, Entries, [])) andalso
                                 not lists:member(I, Reset)
                     end, OldHs),
    G1 = G#{members := lists:sort(Members), entries := Entries, latch := Latch,
            inh := [M || M <- OldInh, lists:member(M, Kept)], holds := Hs},
    %% A latched inhibitor inhibits as it is wired; then the members' latches
    %% re-enter as fresh sets, smaller first.
    {MemberSync, InhSync} = lists:partition(fun({S, _}) -> lists:member(S, Members) end,
                                            lists:sort(Synced)),
    G2 = lists:foldl(fun({I, {value, V}}, Acc) -> as_inhibitor(Acc, T, I, {set, V});
                        (_, Acc) -> Acc
                     end, G1, InhSync),
    lists:foldl(fun({M, {value, V}}, {GAcc, FAcc}) ->
                        {GA, F} = emission(GAcc, T, M, {set, V}),
                        settle(GA, T, FAcc ++ F);
                   (_, Acc) -> Acc
                end, settle(G2, T, []), MemberSync).

%% One emission reaching the gate.
emission(G = #{members := Ms, latch := L, inh := Inh}, T, Src, Op) ->
    case {lists:member(Src, Ms), lists:member(Src, Inh)} of
        {true, true} ->
            %% Inhibited: the latch follows (a set updates it, a send clears
            %% it); nothing goes downstream and it inhibits nothing.
            {G#{latch := L#{Src := latch_after(Op)}}, []};
        {true, false} ->
            G1 = G#{latch := L#{Src := latch_after(Op)}},
            {as_inhibitor(G1, T, Src, Op), [{Src, Op}]};
        {false, _} ->
            {as_inhibitor(G, T, Src, Op), []}
    end.

latch_after({set, V}) -> {value, V};
latch_after(_) -> none.

%% Src's emission replaces its hold on each member it inhibits.
as_inhibitor(G = #{entries := Es}, T, Src, Op) ->
    maps:fold(fun(M, Entry, Acc = #{holds := Hs, n := N}) ->
                      case lists:keyfind(Src, 1, Entry) of
                          false -> Acc;
                          {Src, Default} ->
                              End = case Op of
                                        {set, _} -> infinity;
                                        unset -> none;
                                        {send, _, default} -> hold_end(Default, T);
                                        {send, _, Hold} -> hold_end(Hold, T)
                                    end,
                              case End of
                                  none -> Acc#{holds := maps:remove({M, Src}, Hs)};
                                  _ -> Acc#{holds := Hs#{{M, Src} => {End, N}}, n := N + 1}
                              end
                      end
              end, G, Es).

live(Hs, Key, T) ->
    case Hs of
        #{Key := {E, _}} -> holding(E, T);
        #{} -> false
    end.

%% The members that must be inhibited now, from the holds alone.
should_be_inhibited(#{members := Ms, entries := Es, holds := Hs}, T) ->
    Outside = fun(M) ->
                      lists:any(fun({I, _}) -> not lists:member(I, Ms) andalso
                                                   live(Hs, {M, I}, T)
                                end, maps:get(M, Es, []))
              end,
    case Ms of
        [M] ->
            [M || Outside(M)];
        [A, B] ->
            case {Outside(A), Outside(B)} of
                {true, true} -> [A, B];
                {true, false} -> [A];
                {false, true} -> [B];
                {false, false} ->
                    AonB = live(Hs, {B, A}, T),
                    BonA = live(Hs, {A, B}, T),
                    case {AonB, BonA} of
                        {true, true} ->
                            {_, NA} = maps:get({B, A}, Hs),
                            {_, NB} = maps:get({A, B}, Hs),
                            [case NA < NB of true -> B; false -> A end];
                        {true, false} -> [B];
                        {false, true} -> [A];
                        {false, false} -> []
                    end
            end;
        [] -> []
    end.

%% Applies the consequences until the inhibited set is what the holds say.
settle(G = #{inh := Inh, holds := Hs, latch := L}, T, Fwd) ->
    Should = should_be_inhibited(G, T),
    case {lists:sort(Should -- Inh), lists:sort(Inh -- Should)} of
        {[_ | _] = New, _} ->
            %% Cut: an unset downstream, and an inhibited output inhibits nothing.
            Hs1 = maps:filter(fun({_, I}, _) -> not lists:member(I, New) end, Hs),
            settle(G#{inh := lists:sort(Inh ++ New), holds := Hs1}, T,
                   Fwd ++ [{M, unset} || M <- New]);
        {[], [M | _]} ->
            G1 = G#{inh := Inh -- [M]},
            case maps:get(M, L) of
                {value, V} -> settle(as_inhibitor(G1, T, M, {set, V}), T,
                                     Fwd ++ [{M, {set, V}}]);
                none -> settle(G1, T, Fwd)
            end;
        {[], []} ->
            {G, Fwd}
    end.

gate_members(#{members := Ms}) -> Ms.

gate_inhibited(#{inh := Inh}, M) -> lists:member(M, Inh).

%% @doc What a new subscriber of member `M' starts from.
gate_state_for(#{inh := Inh, latch := L}, M) ->
    case lists:member(M, Inh) of
        true -> none;
        false -> maps:get(M, L, none)
    end.

%% @doc Per member, what `toroco_gate_core:info/2' must say at `T'.
gate_info(#{members := Ms, entries := Es, latch := L, inh := Inh, holds := Hs}, T) ->
    maps:from_list(
      [{M, #{inhibited => lists:member(M, Inh), latch => maps:get(M, L),
             inhibitors => [I || {I, _} <- maps:get(M, Es, [])],
             holds => [{I, remaining(element(1, maps:get({M, I}, Hs)), T)}
                       || {I, _} <- maps:get(M, Es, []), live(Hs, {M, I}, T)]}}
       || M <- Ms]).

gate_next_deadline(#{holds := Hs}, T) ->
    lists:min([infinity | [E || {E, _} <- maps:values(Hs), is_integer(E), E > T]]).
