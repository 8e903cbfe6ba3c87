%% @doc Properties of SPEC §4 suppression and inhibition.
%%
%% Three properties, each against the oracles of `prop_router_model':
%% <ul>
%% <li>{@link prop_router_core/0}: `toroco_router_core' driven with random
%% events (sources 1..5 with random wiring holds; send/set/unset with emit-time
%% holds default, 0, timed or infinity; time steps; re-wiring; late syncs;
%% receiver restarts) delivers exactly what the oracle delivers, and its
%% `info/2' and next deadline agree.</li>
%% <li>{@link prop_gate_core/0} (and {@link prop_gate_core_untimed/0}, the
%% same without timed holds): `toroco_gate_core', ticked at its deadlines as
%% its process does, forwards exactly what the oracle forwards.</li>
%% <li>{@link prop_network/0}: a `proper_statem' property. It starts the
%% `toroco' application, builds a random valid network (behaviors of
%% `prop_emitter' in layers 0..2 as sources of a fake actuator's input,
%% optionally inhibited by an outside behavior or as a same-layer mutual pair)
%% and issues random commands: emissions, kills, timed holds left to expire,
%% re-wiring, inhibitors on and off, a receiver restart, refused wiring. After
%% each command the actuator's history, its input's winner, holds and
%% latches, and each emitter's latch and inhibition must be those of a model
%% built from the two oracles.</li>
%% </ul>
%% Sections: generators, pure properties, the process model, the statem.
-module(prop_router).

-define(PROPER_NO_TRANS, true).
-include_lib("proper/include/proper.hrl").

-export([prop_router_core/0, prop_gate_core/0, prop_gate_core_untimed/0, prop_network/0]).
-export([run_router/1, run_gate/1, counts/0]).
%% proper_statem
-export([initial_state/0, command/1, precondition/2, postcondition/3, next_state/3]).
%% commands of the statem
-export([inject/3, kill/1, hold_expire/3, set_inputs/2, unwire/0, inhibit_on/1,
         inhibit_off/1, kill_receiver/0, bad_inputs/1]).

-define(SRCS, [{s1, out}, {s2, out}, {s3, out}, {s4, out}, {s5, out}]).
-define(GATE_SRCS, [{a, out}, {b, out}, {x, out}, {y, out}, {z, out}]).
%% A "timed" hold the processes never see expire within a command sequence:
%% holds the statem lets expire are short and waited for in one command.
-define(LONG, 60000).
-define(ACT, pact).
-define(INH, pinh).
-define(CALL_TIMEOUT, 500).

%%====================================================================
%% Generators
%%====================================================================

value() -> oneof([a, b, c]).

latch() -> frequency([{1, none}, {2, {value, value()}}]).

delay() -> frequency([{3, 0}, {6, range(1, 30)}, {1, range(31, 150)}]).

%% Emit-time holds, and wiring holds (the default of a send that gives none).
emit_hold(timed) -> frequency([{3, default}, {2, 0}, {3, range(1, 100)}, {2, infinity}]);
emit_hold(untimed) -> frequency([{3, default}, {2, 0}, {2, infinity}]).

wiring_hold(timed) -> frequency([{3, 0}, {3, range(1, 100)}, {1, infinity}]);
wiring_hold(untimed) -> frequency([{3, 0}, {1, infinity}]).

op(Timing) ->
    frequency([{4, {send, value(), emit_hold(Timing)}}, {3, {set, value()}}, {2, unset}]).

%% A random order of some of `Pool', each with a wiring hold.
some_of(Pool, Timing) ->
    ?LET({Keys, N}, {vector(length(Pool), int()), range(1, length(Pool))},
         ?LET(Holds, vector(N, wiring_hold(Timing)),
              lists:zip(lists:sublist([S || {_, S} <- lists:sort(lists:zip(Keys, Pool))], N),
                        Holds))).

router_event() ->
    frequency([{12, {op, oneof(?SRCS), op(timed)}},
               {2, {rewire, some_of(?SRCS, timed),
                    oneof([#{}, #{idle => none}, ?LET(I, oneof([idle, a]), #{idle => {value, I}})]),
                    list({oneof(?SRCS), latch()}), list(oneof(?SRCS))}},
               {1, {sync, [{oneof(?SRCS), latch()}]}},
               {2, tick},
               {2, tick_at_deadline},
               {1, receiver_up}]).

gate_rewire(Timing) ->
    Inhibitors = ?LET(L, list({oneof([{x, out}, {y, out}]), wiring_hold(Timing)}), dedup(L)),
    Single = fun(M) -> ?LET(Es, Inhibitors,
                            #{M => case Es of [] -> [{{x, out}, 0}]; _ -> Es end})
             end,
    Pair = ?LET({Ea, Eb, Da, Db, FirstA, FirstB},
                {Inhibitors, Inhibitors, wiring_hold(Timing), wiring_hold(Timing), bool(), bool()},
                #{{a, out} => place({{b, out}, Db}, Ea, FirstA),
                  {b, out} => place({{a, out}, Da}, Eb, FirstB)}),
    ?LET({Entries, Synced, Reset},
         {oneof([Single({a, out}), Single({b, out}), Pair, Pair]),
          list({oneof(?GATE_SRCS), latch()}), list(oneof(?GATE_SRCS))},
         {rewire, lists:sort(maps:keys(Entries)), Entries, Synced, Reset}).

place(E, Es, true) -> [E | Es];
place(E, Es, false) -> Es ++ [E].

dedup(L) -> lists:reverse(lists:foldl(fun({K, _} = E, Acc) ->
                                              case lists:keymember(K, 1, Acc) of
                                                  true -> Acc;
                                                  false -> [E | Acc]
                                              end
                                      end, [], L)).

gate_event(Timing) ->
    frequency([{10, {op, oneof(?GATE_SRCS), op(Timing)}},
               {2, gate_rewire(Timing)},
               {1, tick}]).

%%====================================================================
%% Pure properties
%%====================================================================

%% @doc `toroco_router_core' against the suppression oracle.
prop_router_core() ->
    ?FORALL(Steps, list({delay(), router_event()}),
            begin
                Result = run_router(Steps),
                ?WHENFAIL(io:format("~nrouter core disagrees with the oracle:~n~p~n", [Result]),
                          measure("events per case", length(Steps),
                                  aggregate([kind(E) || {_, E} <- Steps],
                                            Result =:= ok)))
            end).

kind(E) when is_tuple(E) -> element(1, E);
kind(E) -> E.

%% @doc `toroco_gate_core' against the inhibition oracle.
prop_gate_core() ->
    gate_property(timed).

%% @doc The same, with holds only 0 or infinity (no hold ever expires).
prop_gate_core_untimed() ->
    gate_property(untimed).

gate_property(Timing) ->
    ?FORALL(Steps, ?LET({First, Rest}, {gate_rewire(Timing), list({delay(), gate_event(Timing)})},
                        [{0, First} | Rest]),
            begin
                Result = run_gate(Steps),
                ?WHENFAIL(io:format("~ngate core disagrees with the oracle:~n~p~n", [Result]),
                          measure("events per case", length(Steps), Result =:= ok))
            end).

%% Feeds both the core and the oracle; stops at the first disagreement.
run_router(Steps) ->
    run_router(Steps, 0, toroco_router_core:new(), prop_router_model:router_new(), [], 1).

run_router([], _T, _C, _R, _Wired, _N) ->
    ok;
run_router([{Dt, Ev0} | Rest], T0, C, R, Wired, N) ->
    {T, Ev} = case Ev0 of
                  tick_at_deadline ->
                      case toroco_router_core:next_deadline(C) of
                          infinity -> {T0 + Dt, tick};
                          D -> {max(D, T0), tick}
                      end;
                  _ ->
                      {T0 + Dt, normalize_rewire(Ev0, Wired)}
              end,
    {R1, Expected} = prop_router_model:router_step(R, T, Ev),
    case guarded(fun() -> toroco_router_core:handle(Ev, T, C) end) of
        {ok, {C1, Out}} ->
            %% A deadline earlier than the oracle's only wakes the process for
            %% nothing; a later one would miss a hold end.
            Next = toroco_router_core:next_deadline(C1),
            WantNext = prop_router_model:router_next_deadline(R1, T),
            Got = {Out, maps:with([sources, winner, holds, latches, last],
                                  toroco_router_core:info(C1, T)),
                   case Next =< WantNext of true -> WantNext; false -> Next end},
            Want = {Expected, prop_router_model:router_info(R1, T), WantNext},
            case Got =:= Want of
                true ->
                    run_router(Rest, T, C1, R1, prop_router_model:router_sources(R1), N + 1);
                false ->
                    {mismatch, #{step => N, time => T, event => Ev, got => Got, want => Want}}
            end;
        Failed ->
            {Failed, #{step => N, time => T, event => Ev}}
    end.

%% A re-wiring as a router takes it: sources whose upstream is new come fresh
%% (`Reset') with the latch their upstream handed over (`Synced').
normalize_rewire({rewire, Srcs, Opts, Synced, Reset}, Wired) ->
    New = [S || {S, _} <- Srcs],
    Fresh = (New -- Wired) ++ [S || S <- lists:usort(Reset), lists:member(S, New),
                                    lists:member(S, Wired)],
    {rewire, Srcs, Opts, dedup([E || E = {S, _} <- Synced, lists:member(S, Fresh)]), Fresh};
normalize_rewire(Ev, _Wired) ->
    Ev.

run_gate(Steps) ->
    run_gate(Steps, 0, toroco_gate_core:new(), prop_router_model:gate_new(), [], 1).

run_gate([], _T, _C, _G, _Ups, _N) ->
    ok;
run_gate([{Dt, Ev0} | Rest], T0, C, G, Ups, N) ->
    T = T0 + Dt,
    %% The process ticks at every deadline before it takes the next event.
    case toroco_gate_core:next_deadline(C) of
        D when D =< T ->
            Td = max(D, T0),
            case gate_step(tick, Td, C, G, N) of
                {ok, C1, G1} -> run_gate([{T - Td, Ev0} | Rest], Td, C1, G1, Ups, N + 1);
                Failed -> Failed
            end;
        _ ->
            Ev = normalize_gate_rewire(Ev0, Ups),
            Ups1 = case Ev of
                       {rewire, Ms, Es, _, _} -> gate_upstreams(Ms, Es);
                       _ -> Ups
                   end,
            case gate_step(Ev, T, C, G, N) of
                {ok, C1, G1} -> run_gate(Rest, T, C1, G1, Ups1, N + 1);
                Failed -> Failed
            end
    end.

gate_step(Ev, T, C, G, N) ->
    {G1, Expected} = prop_router_model:gate_step(G, T, Ev),
    case guarded(fun() -> toroco_gate_core:handle(Ev, T, C) end) of
        {ok, {C1, Fwd}} ->
            Members = prop_router_model:gate_members(G1),
            Got = {Fwd, toroco_gate_core:info(C1, T),
                   [toroco_gate_core:state_for(M, C1) || M <- Members],
                   toroco_gate_core:next_deadline(C1)},
            Want = {Expected, prop_router_model:gate_info(G1, T),
                    [prop_router_model:gate_state_for(G1, M) || M <- Members],
                    prop_router_model:gate_next_deadline(G1, T)},
            case Got =:= Want of
                true -> {ok, C1, G1};
                false -> {mismatch, #{step => N, time => T, event => Ev, got => Got,
                                      want => Want}}
            end;
        Failed ->
            {Failed, #{step => N, time => T, event => Ev}}
    end.

gate_upstreams(Members, Entries) ->
    lists:usort(Members ++ [I || Es <- maps:values(Entries), {I, _} <- Es]).

normalize_gate_rewire({rewire, Members, Entries, Synced, Reset}, Ups) ->
    New = gate_upstreams(Members, Entries),
    Fresh = (New -- Ups) ++ [S || S <- lists:usort(Reset), lists:member(S, New),
                                  lists:member(S, Ups)],
    {rewire, Members, Entries, dedup([E || E = {S, _} <- Synced, lists:member(S, Fresh)]),
     Fresh};
normalize_gate_rewire(Ev, _Ups) ->
    Ev.

%% Runs a pure call with a time limit: a core that loops is a failure too.
guarded(Fun) ->
    {Pid, Ref} = spawn_monitor(fun() -> exit({done, catch_all(Fun)}) end),
    receive
        {'DOWN', Ref, process, Pid, {done, Result}} -> Result;
        {'DOWN', Ref, process, Pid, Other} -> {crashed, Other}
    after ?CALL_TIMEOUT ->
            exit(Pid, kill),
            receive {'DOWN', Ref, process, Pid, _} -> ok end,
            {no_answer_within_ms, ?CALL_TIMEOUT}
    end.

catch_all(Fun) ->
    try {ok, Fun()}
    catch Class:Reason:Stack -> {crashed, {Class, Reason, Stack}}
    end.

%%====================================================================
%% The process model
%%====================================================================
%%
%% What the network must do, from the two oracles: every emission goes to the
%% actuator's router directly, or through the gate when its output is a gate
%% member or the inhibitor; what the gate forwards goes to the router. Model
%% time advances 1 ms per command; the short holds of `hold_expire' advance it
%% by their length, and nothing else ever expires (`?LONG' is a minute).

source(N) -> {N, out}.

whold(none) -> 0;
whold(H) -> H.

gate_members(#{inhib := {single, T, _}}) -> [source(T)];
gate_members(#{inhib := {pair, A, B}}) -> lists:sort([source(A), source(B)]);
gate_members(_) -> [].

gate_entries(#{inhib := {single, T, D}}) -> #{source(T) => [{source(?INH), whold(D)}]};
gate_entries(#{inhib := {pair, A, B}}) -> #{source(A) => [{source(B), 0}],
                                            source(B) => [{source(A), 0}]}.

gate_sources(#{inhib := {single, T, _}}) -> [T, ?INH];
gate_sources(#{inhib := {pair, A, B}}) -> [A, B];
gate_sources(_) -> [].

on_gate_path(#{cfg := Cfg, inhib_on := On}, E) -> On andalso lists:member(E, gate_sources(Cfg)).

wired(#{wiring := W}, E) -> lists:keymember(E, 1, W).

m_tick(S = #{vt := VT}) -> S#{vt := VT + 1}.

latch_after({set, V}) -> {value, V};
latch_after(_) -> none.

%% One emission of emitter E: its latch follows, and it travels on.
m_emit(S = #{latch := L}, E, Op) ->
    route(S#{latch := L#{E := latch_after(Op)}}, E, Op).

route(S, E, Op) ->
    case on_gate_path(S, E) of
        true -> m_gate(S, {op, source(E), Op});
        false ->
            case wired(S, E) of
                true -> m_router(S, {op, source(E), Op});
                false -> S
            end
    end.

m_gate(S = #{gate := G, vt := VT}, Ev) ->
    {G1, Fwd} = prop_router_model:gate_step(G, VT, Ev),
    lists:foldl(fun({{M, out}, Op}, Acc) ->
                        case wired(Acc, M) of
                            true -> m_router(Acc, {op, source(M), Op});
                            false -> Acc
                        end
                end, S#{gate := G1}, Fwd).

m_router(S = #{router := undefined}, _Ev) ->
    S;
m_router(S = #{router := R, vt := VT, delivered := D}, Ev) ->
    {R1, Out} = prop_router_model:router_step(R, VT, Ev),
    S#{router := R1, delivered := D ++ Out}.

%% The latch a router is handed when it subscribes to E's output.
upstream_latch(S = #{latch := L, gate := G}, E) ->
    case on_gate_path(S, E) andalso lists:member(source(E), gate_members(maps:get(cfg, S))) of
        true -> prop_router_model:gate_state_for(G, source(E));
        false -> maps:get(E, L)
    end.

m_set_inputs(S = #{router := R0}, W, Idle) ->
    Srcs = [{source(N), whold(H)} || {N, H} <- W],
    {R, Old} = case R0 of
                   undefined -> {prop_router_model:router_new(), []};
                   _ -> {R0, prop_router_model:router_sources(R0)}
               end,
    Fresh = [Src || {Src, _} <- Srcs, not lists:member(Src, Old)],
    Synced = [{Src, upstream_latch(S, N)} || Src = {N, _} <- Fresh],
    IdleL = case Idle of true -> {value, idle}; false -> none end,
    m_router(S#{router := R, wiring := W},
             {rewire, Srcs, #{idle => IdleL}, Synced, Fresh}).

%% `[]' stops the router: its sources all let go first (a holder letting go
%% delivers the idle value), then nothing more reaches the actuator there.
m_unwire(S = #{router := undefined}) ->
    S#{wiring := []};
m_unwire(S = #{cfg := #{idle := Idle}}) ->
    IdleL = case Idle of true -> {value, idle}; false -> none end,
    S1 = m_router(S, {rewire, [], #{idle => IdleL}, [], []}),
    S1#{router := undefined, wiring := []}.

%% Attaching a gate: it takes the current latches; a member it inhibits is cut
%% at the router, a free one keeps its state there.
m_inhibit_on(S = #{cfg := Cfg, latch := L, vt := VT}) ->
    Members = gate_members(Cfg),
    Ups = lists:usort([source(E) || E <- gate_sources(Cfg)]),
    Ev = {rewire, Members, gate_entries(Cfg), [{U, maps:get(E, L)} || U = {E, _} <- Ups], Ups},
    %% What the new gate sends before the routers have moved to it is ignored.
    {G, _Ignored} = prop_router_model:gate_step(prop_router_model:gate_new(), VT, Ev),
    S1 = S#{gate := G, inhib_on := true},
    lists:foldl(fun(M = {E, _}, Acc) ->
                        case wired(Acc, E) andalso prop_router_model:gate_inhibited(G, M) of
                            true -> m_router(Acc, {op, M, unset});
                            false -> Acc
                        end
                end, S1, Members).

%% Removing it: a member that was inhibited re-enters with its latch.
m_inhibit_off(S = #{cfg := Cfg, gate := G, latch := L}) ->
    S1 = S#{gate := undefined, inhib_on := false},
    lists:foldl(fun(M = {E, _}, Acc) ->
                        case wired(Acc, E) andalso prop_router_model:gate_inhibited(G, M) of
                            true -> case maps:get(E, L) of
                                        {value, _} = Latch -> m_router(Acc, {sync, [{M, Latch}]});
                                        none -> Acc
                                    end;
                            false -> Acc
                        end
                end, S1, gate_members(Cfg)).

%% A killed emitter: its consumers see it go down and then the new
%% incarnation say hello; each ends its holds and clears its latch.
m_kill(S = #{latch := L}, E) ->
    S1 = S#{latch := L#{E := none}},
    route(route(S1, E, unset), E, unset).

m_hold_expire(S, E, V, H) ->
    S1 = #{vt := VT} = m_emit(S, E, {send, V, H}),
    S2 = S1#{vt := VT + H},
    S3 = case S2 of
             #{gate := undefined} -> S2;
             _ -> m_gate(S2, tick)
         end,
    m_router(S3, tick).

m_kill_receiver(S) ->
    m_router(S#{delivered := []}, receiver_up).

%% The blank network, then the wiring and inhibition the network starts with.
initial_model(Cfg = #{srcs := Srcs, wiring := W, idle := Idle, inhib_on := On}) ->
    S0 = #{cfg => Cfg, vt => 0, latch => maps:from_list([{E, none} || {E, _} <- Srcs] ++
                                                             [{?INH, none}]),
           inhib_on => false, gate => undefined, wiring => [], router => undefined,
           delivered => []},
    S1 = m_tick(m_set_inputs(S0, W, Idle)),
    case On of
        true -> m_tick(m_inhibit_on(S1));
        false -> S1
    end.

%% What observing the network must show.
expected(S = #{cfg := #{srcs := Srcs}, latch := L, router := R, vt := VT, delivered := D}) ->
    Act = case R of
              undefined -> #{sources => [], winner => none, holds => [], latches => [],
                             last => none};
              _ -> prop_router_model:router_info(R, VT)
          end,
    #{history => D,
      act => Act#{holds := [{Src, finite(Ms)} || {Src, Ms} <- maps:get(holds, Act)]},
      emitters => maps:from_list([{E, {maps:get(E, L), inhibited(S, E)}}
                                  || E <- [N || {N, _} <- Srcs] ++ [?INH]])}.

inhibited(S = #{gate := G, cfg := Cfg}, E) ->
    on_gate_path(S, E) andalso lists:member(source(E), gate_members(Cfg)) andalso
        prop_router_model:gate_inhibited(G, source(E)).

finite(infinity) -> infinity;
finite(_) -> timed.

%%====================================================================
%% The statem
%%====================================================================

network() ->
    ?LET(N, range(2, 4),
         ?LET(Layers, vector(N, range(0, 2)),
              begin
                  Srcs = lists:zip([list_to_atom("ps" ++ integer_to_list(I))
                                    || I <- lists:seq(1, N)], Layers),
                  ?LET({Inhib, W, Idle, On},
                       {inhibition(Srcs), wiring(Srcs), bool(), bool()},
                       #{srcs => Srcs, inhib => Inhib, wiring => W, idle => Idle,
                         inhib_on => On andalso Inhib =/= none})
              end)).

inhibition(Srcs) ->
    Pairs = [{A, B} || {A, La} <- Srcs, {B, Lb} <- Srcs, A < B, La =:= Lb],
    frequency([{2, none},
               {3, {single, oneof([E || {E, _} <- Srcs]),
                    oneof([none, 0, ?LONG, infinity])}}] ++
              [{3, ?LET({A, B}, oneof(Pairs), {pair, A, B})} || Pairs =/= []]).

%% A valid input list: some of the sources, higher layers first.
wiring(Srcs) ->
    ?LET(Picks, vector(length(Srcs), {bool(), int(), oneof([none, 0, ?LONG, infinity])}),
         begin
             Chosen = [{L, K, E, H} || {{E, L}, {true, K, H}} <- lists:zip(Srcs, Picks)],
             Some = case Chosen of
                        [] -> [{L, K, E, H} || {{E, L}, {_, K, H}} <- [hd(lists:zip(Srcs, Picks))]];
                        _ -> Chosen
                    end,
             [{E, H} || {_, _, E, H} <- lists:sort(fun({La, Ka, _, _}, {Lb, Kb, _, _}) ->
                                                           {-La, Ka} =< {-Lb, Kb}
                                                   end, Some)]
         end).

%% A list that puts a lower layer above a higher one, if the layers allow.
bad_wiring(Srcs) ->
    case [[{Lo, out}, {Hi, out}] || {Lo, Ll} <- Srcs, {Hi, Lh} <- Srcs, Ll < Lh] of
        [] -> none;
        Bad -> oneof(Bad)
    end.

emitters(#{cfg := #{srcs := Srcs}}) -> [E || {E, _} <- Srcs] ++ [?INH].

%% Emitters whose short hold may be left to expire with a deterministic
%% outcome: not a pair member (gate and router timers would race). The
%% single inhibitor's hold expires at the gate, the member's at the router.
expirable(S = #{cfg := Cfg}) ->
    [E || E <- emitters(S), not on_gate_path(S, E) orelse expirable_on_gate(Cfg, E)].

expirable_on_gate(#{inhib := {single, T, _}}, T) -> true;
expirable_on_gate(#{inhib := {single, _, _}}, ?INH) -> true;
expirable_on_gate(_, _) -> false.

process_op() ->
    frequency([{4, {send, value(), oneof([default, 0, ?LONG, infinity])}},
               {3, {set, value()}}, {2, unset}]).

initial_state() ->
    error(use_commands_2).

command(S = #{cfg := Cfg = #{srcs := Srcs}, inhib_on := On}) ->
    frequency([{8, {call, ?MODULE, inject, [oneof(emitters(S)), process_op(), oneof([api, call])]}},
               {2, {call, ?MODULE, kill, [oneof(emitters(S))]}},
               {2, {call, ?MODULE, set_inputs, [wiring(Srcs), bool()]}},
               {1, {call, ?MODULE, unwire, []}},
               {1, {call, ?MODULE, kill_receiver, []}}] ++
              [{2, {call, ?MODULE, hold_expire, [oneof(expirable(S)), value(), range(60, 100)]}}
               || expirable(S) =/= []] ++
              [{2, {call, ?MODULE, inhibit_on, [Cfg]}}
               || maps:get(inhib, Cfg) =/= none, not On] ++
              [{2, {call, ?MODULE, inhibit_off, [Cfg]}} || On] ++
              [{1, {call, ?MODULE, bad_inputs, [bad_wiring(Srcs)]}} || bad_wiring(Srcs) =/= none]).

precondition(S, {call, _, hold_expire, [E, _, _]}) -> lists:member(E, expirable(S));
precondition(#{inhib_on := On}, {call, _, inhibit_on, _}) -> not On;
precondition(#{inhib_on := On}, {call, _, inhibit_off, _}) -> On;
precondition(_S, _Call) -> true.

next_state(S, _Res, {call, _, Fun, Args}) ->
    transition(m_tick(S), Fun, Args).

transition(S, inject, [E, Op, _Via]) -> m_emit(S, E, Op);
transition(S, kill, [E]) -> m_kill(S, E);
transition(S, hold_expire, [E, V, H]) -> m_hold_expire(S, E, V, H);
transition(S = #{cfg := #{idle := Idle}}, set_inputs, [W, _]) -> m_set_inputs(S, W, Idle);
transition(S, unwire, []) -> m_unwire(S);
transition(S, inhibit_on, [_]) -> m_inhibit_on(S);
transition(S, inhibit_off, [_]) -> m_inhibit_off(S);
transition(S, kill_receiver, []) -> m_kill_receiver(S);
transition(S, bad_inputs, [_]) -> S.

postcondition(S, Call = {call, _, Fun, _}, {Ret, Obs}) ->
    Want = expected(next_state(S, Ret, Call)),
    ExpectedRet = case Fun of
                      bad_inputs -> hierarchy;
                      _ -> ok
                  end,
    count(commands),
    case {returned(Ret), ExpectedRet} of
        {R, R} -> agree(Fun, Want, Obs, 40);
        {R, _} -> io:format("~n~p returned ~p~n", [Call, R]), false
    end.

returned(ok) -> ok;
returned({error, {hierarchy, _}}) -> hierarchy;
returned(Other) -> Other.

%% The network may still be on its way: look again, bounded. Second looks
%% are counted by command, and the first sight of each is logged.
agree(_Fun, Want, Obs, _Tries) when Want =:= Obs -> true;
agree(_Fun, Want, Obs, 0) ->
    io:format("~nthe network disagrees with the model~n  model:   ~p~n  network: ~p~n",
              [Want, Obs]),
    false;
agree(Fun, Want = #{history := H}, Obs, Tries) ->
    case count({second_look, Fun}) of
        1 -> io:format("~nfirst second look (~p):~n  model:   ~p~n  network: ~p~n",
                       [Fun, Want, Obs]);
        _ -> ok
    end,
    _ = toroco_fake_actuator:await(?ACT, fun(Hist) -> [V || {_, V, _} <- Hist] =:= H end, 25),
    agree(Fun, Want, observe(), Tries - 1).

%% @doc The property: `numtests' sequences on networks built afresh each time.
prop_network() ->
    ?FORALL(Cfg, network(),
            begin
                ?FORALL(Cmds, commands(?MODULE, initial_model(Cfg)),
                        begin
                            Start = start_network(Cfg),
                            {History, State, Result} = run_commands(?MODULE, Cmds),
                            stop_network(),
                            count(sequences),
                            ?WHENFAIL(io:format("~nnetwork ~p~nstart ~p~nresult ~p~n"
                                                "last model ~p~nhistory ~p~n",
                                                [Cfg, Start, Result, State,
                                                 [Obs || {_, Obs} <- History]]),
                                      measure("commands per sequence", length(Cmds) - 1,
                                              aggregate(command_names(Cmds),
                                                        Start =:= ok andalso Result =:= ok)))
                        end)
            end).

count(What) ->
    catch ets:update_counter(prop_router_counts, What, 1, {What, 0}).

%% @doc Sequences and commands run since the counters were made.
counts() ->
    try maps:from_list(ets:tab2list(prop_router_counts))
    catch error:badarg -> #{}
    end.

start_network(Cfg = #{srcs := Srcs, wiring := W, idle := Idle, inhib_on := On}) ->
    stop_network(),
    _ = application:load(toroco),
    %% Kills are commands here; a layer must not be taken out for them.
    ok = application:set_env(toroco, layer_restart_intensity, {100000, 1}),
    ok = application:set_env(toroco, device_restart_intensity, {100000, 1}),
    {ok, _} = application:ensure_all_started(toroco_hw),
    persistent_term:put(prop_router_cfg, Cfg),
    try
        [ok = toroco:add_behavior(E, prop_emitter, #{layer => L}) || {E, L} <- Srcs],
        ok = toroco:add_behavior(?INH, prop_emitter, #{layer => 2}),
        ok = toroco:add_device(?ACT, toroco_fake_actuator, #{inputs => [in]}),
        ok = do_set_inputs(W, Idle),
        case On of
            true -> ok = do_inhibit_on(Cfg);
            false -> ok
        end
    catch error:{badmatch, Err} -> {start_failed, Err}
    end.

stop_network() ->
    toroco_test_lib:stop().

%%--------------------------------------------------------------------
%% Commands: each acts, waits for what it set in motion, and observes
%%--------------------------------------------------------------------

inject(E, Op, Via) ->
    Ret = case {Op, Via} of
              {{send, V, default}, api} -> toroco:inject(source(E), V);
              {{send, V, H}, api} -> toroco:inject(source(E), V, #{hold => H});
              {{set, V}, api} -> toroco:inject(source(E), V, #{latch => true});
              {{send, V, default}, call} -> prop_emitter:emit(E, [{send, #{out => V}}]);
              {{send, V, H}, call} -> prop_emitter:emit(E, [{send, #{out => V}, #{hold => H}}]);
              {{set, V}, call} -> prop_emitter:emit(E, [{set, #{out => V}}]);
              {unset, api} -> prop_emitter:emit(E, [{unset, [out]}]);
              {unset, call} -> prop_emitter:emit(E, [unset])
          end,
    {Ret, observe()}.

kill(E) ->
    {restart(toroco_names:process(E), fun() -> toroco_behavior:info(E) end), observe()}.

kill_receiver() ->
    {restart(toroco_names:process(?ACT), fun() -> toroco_fake_actuator:history(?ACT) end),
     observe()}.

%% Kills a process and waits until its successor has finished its init.
restart(Reg, Ready) ->
    Old = whereis(Reg),
    exit(Old, kill),
    case toroco_test_lib:poll(fun() -> case whereis(Reg) of
                                 P when is_pid(P), P =/= Old -> true;
                                 _ -> false
                             end
                    end, 3000) of
        ok -> _ = Ready(), ok;
        timeout -> {not_restarted, Reg}
    end.

%% A short hold, left to expire: waits until the router and the gate hold
%% nothing short any more and the router's winner has caught up.
hold_expire(E, V, H) ->
    ok = toroco:inject(source(E), V, #{hold => H}),
    Ret = toroco_test_lib:poll(fun() -> short_holds_over() end, 3000 + H),
    {case Ret of ok -> ok; timeout -> short_hold_did_not_end end, observe()}.

%% The gate answers first: what it forwarded is then at the router before
%% the router is asked.
short_holds_over() ->
    Gate = case gate_key() of
               none -> true;
               Key ->
                   case toroco_gate:info(Key) of
                       none -> true;
                       Info -> [] =:= [I || #{holds := Hs} <- maps:values(Info),
                                            {I, Ms} <- Hs, is_integer(Ms), Ms < ?LONG div 2]
                   end
           end,
    Router = case toroco_router:info({?ACT, in}) of
                 none -> true;
                 #{holds := Hs, winner := W} ->
                     Short = [S || {S, Ms} <- Hs, is_integer(Ms), Ms < ?LONG div 2],
                     Top = case Hs of [] -> none; [{S, _} | _] -> S end,
                     Short =:= [] andalso W =:= Top
             end,
    Gate andalso Router.

gate_key() ->
    case gate_members(persistent_term:get(prop_router_cfg)) of
        [] -> none;
        Ms -> lists:min(Ms)
    end.

set_inputs(W, _) ->
    #{idle := Idle} = persistent_term:get(prop_router_cfg),
    {do_set_inputs(W, Idle), observe()}.

do_set_inputs(W, Idle) ->
    Srcs = [case H of
                none -> source(E);
                _ -> {E, out, #{hold => H}}
            end || {E, H} <- W],
    toroco:set_inputs(?ACT, #{in => case Idle of
                                        true -> #{sources => Srcs, idle => idle};
                                        false -> Srcs
                                    end}).

unwire() ->
    {toroco:set_inputs(?ACT, #{in => []}), observe()}.

bad_inputs(Srcs) ->
    {toroco:set_inputs(?ACT, #{in => Srcs}), observe()}.

inhibit_on(Cfg) ->
    {do_inhibit_on(Cfg), observe()}.

inhibit_off(Cfg) ->
    {do_inhibit_off(Cfg), observe()}.

do_inhibit_on(#{inhib := {single, T, D}}) ->
    toroco:set_inhibitors(T, #{out => [case D of
                                           none -> source(?INH);
                                           _ -> {?INH, out, #{hold => D}}
                                       end]});
do_inhibit_on(#{inhib := {pair, A, B}}) ->
    %% Both halves of a pair at once: a wiring file is applied atomically.
    load_terms([{inhibitors, A, #{out => [source(B)]}}, {inhibitors, B, #{out => [source(A)]}}]).

do_inhibit_off(#{inhib := {single, T, _}}) ->
    toroco:set_inhibitors(T, #{out => []});
do_inhibit_off(#{inhib := {pair, A, B}}) ->
    load_terms([{inhibitors, A, #{out => []}}, {inhibitors, B, #{out => []}}]).

load_terms(Terms) ->
    File = filename:join(os:getenv("TMPDIR", "/tmp"),
                         "prop_router_" ++ os:getpid() ++ ".wiring"),
    ok = file:write_file(File, [io_lib:format("~p.~n", [T]) || T <- Terms]),
    try toroco:load_wiring(File)
    after file:delete(File)
    end.

%% Everything sent so far has been handled once every emitter (and, through
%% `inspect', its gate), then the router, then the actuator have answered.
observe() ->
    #{srcs := Srcs} = persistent_term:get(prop_router_cfg),
    Emitters = maps:from_list(
                 [{E, case toroco:inspect(E) of
                          #{outputs := #{out := #{latch := L, inhibited := I}}} -> {L, I};
                          Other -> Other
                      end} || E <- [N || {N, _} <- Srcs] ++ [?INH]]),
    Act = case toroco:inspect(?ACT) of
              #{inputs := #{in := In}} ->
                  I = maps:with([sources, winner, holds, latches, last], In),
                  I#{holds := [{Src, finite(Ms)} || {Src, Ms} <- maps:get(holds, I, [])]};
              Other -> Other
          end,
    History = try [V || {_, V, _} <- toroco_fake_actuator:history(?ACT)]
              catch exit:Reason -> {no_history, Reason}
              end,
    #{history => History, act => Act, emitters => Emitters}.
