%% @doc The decisions of one input's router, as a pure function.
%%
%% A router owns one wired input: its sources in priority order (highest
%% first), each source's latched value and suppression hold, and the last value
%% it delivered to the receiver. This module is that state and the rules of
%% SPEC §4 "Suppression" applied to it; `toroco_router' is the process shell that
%% owns the mailbox and the timer. Every function here is pure: time comes in as
%% an argument (monotonic milliseconds), deliveries come out as a list.
%%
%% Rules, in short:
%% <ul>
%% <li>an event of source Sj is delivered iff no higher source holds; delivered
%%     or not, it (re)starts Sj's hold (holds work in series);</li>
%% <li>after every event the highest holding source is re-picked; if it is
%%     latched and its latch differs from the last value delivered, the latch is
%%     re-delivered;</li>
%% <li>when the input goes from having a holder to having none, the `idle'
%%     value (if any) is delivered.</li>
%% </ul>
%%
%% Functions: {@link new/0} and {@link handle/3} drive the state; {@link
%% next_deadline/1} tells the shell when to come back with `tick'; {@link
%% info/2} is the inspection view.
-module(toroco_router_core).

-export([new/0, handle/3, next_deadline/1, info/2, sources/1, view/1, same_view/2]).
-export_type([core/0, event/0, op/0, hold/0, latch/0]).
%% Small steps of every emission, inlined: the event path's calls are its cost.
-compile({inline, [start_hold/3, deadline/2, update_src/4]}).

-type source() :: {atom(), atom()}.
-type hold() :: default | non_neg_integer() | infinity.
-type latch() :: {value, term()} | none.
-type op() :: {send, term(), hold()} | {set, term()} | unset.
-type event() ::
        {op, source(), op()}
      | tick
      | receiver_up
      | {rewire, [{source(), non_neg_integer() | infinity}], #{idle => latch()},
         Synced :: [{source(), latch()}], Reset :: [source()]}
      | {sync, [{source(), latch()}]}
      | unwire.

-record(src, {idx :: pos_integer(),
              default = 0 :: non_neg_integer() | infinity,
              latch = none :: latch(),
              %% none: not holding; infinity: until unset; integer: deadline (ms)
              hold = none :: none | infinity | integer()}).

-record(core, {srcs = #{} :: #{source() => #src{}},
               by_idx = {} :: tuple(),          % idx -> source, priority order
               top = none :: none | pos_integer(), % highest holding source's idx
               next = infinity :: infinity | integer(), % earliest timed hold
               last = none :: latch(),
               idle = none :: latch()}).

-opaque core() :: #core{}.

%%====================================================================
%% API
%%====================================================================

%% @doc A router with no sources yet; wire it with a `rewire' event.
-spec new() -> core().
new() -> #core{}.

%% @doc Applies one event at time `Now' and returns the new state with the
%% values to deliver to the receiver, oldest first.
-spec handle(event(), integer(), core()) -> {core(), [term()]}.
handle(Event, Now, C0 = #core{next = Next}) when Next =< Now ->
    {C1, Expired} = expire(Now, C0),
    {C2, Out} = handle(Event, Now, C1),
    {C2, Expired ++ Out};
handle({op, Src, Op}, Now, C = #core{srcs = Srcs}) ->
    case Srcs of
        #{Src := S} -> emission(Src, S, Op, Now, C);
        #{} -> {C, []}                      % not (or no longer) wired here
    end;
handle(tick, _Now, C) ->
    {C, []};
handle(unwire, Now, C = #core{idle = Idle}) ->
    %% The whole input goes: a holder lets go of it, so `idle' is delivered.
    handle({rewire, [], #{idle => Idle}, [], []}, Now, C);
handle(receiver_up, _Now, C) ->
    repick(false, C#core{last = none}, []);
handle({sync, Synced}, _Now, C = #core{top = Top0}) ->
    repick(Top0 =/= none, retop(apply_synced(Synced, C)), []);
handle({rewire, Sources, Opts, Synced, Reset}, _Now, C = #core{top = Top0}) ->
    C1 = rewire(Sources, Reset, C),
    C2 = apply_synced(Synced, C1#core{idle = maps:get(idle, Opts, none)}),
    repick(Top0 =/= none, retop(C2), []).

%% @doc When the earliest timed hold ends, or `infinity'.
-spec next_deadline(core()) -> infinity | integer().
next_deadline(#core{next = Next}) -> Next.

%% @doc The sources in priority order.
-spec sources(core()) -> [source()].
sources(#core{by_idx = ByIdx}) -> tuple_to_list(ByIdx).

%% @doc What the observer tap compares to tell that the winner, the holds
%% or the latches changed: the winner, each holding source with its
%% deadline, each latch.
-spec view(core()) -> {none | pos_integer(), [{source(), infinity | integer()}],
                       [{source(), latch()}]}.
view(#core{srcs = Srcs, top = Top}) ->
    L = lists:sort(maps:to_list(Srcs)),
    {Top, [{Src, H} || {Src, #src{hold = H}} <- L, H =/= none],
     [{Src, La} || {Src, #src{latch = La}} <- L, La =/= none]}.

%% @doc Whether `C' has the {@link view/1} of `Seen' (a core of before, or
%% `none') for sure, without building it: the same winner and the same
%% sources (the view is made of these). `false' may still mean the same
%% view: build it and compare.
-spec same_view(core(), core() | none) -> boolean().
same_view(#core{top = Top, srcs = Srcs}, #core{top = Top, srcs = Srcs}) -> true;
same_view(#core{}, _Seen) -> false.

%% @doc The inspection view of SPEC §6 (lists in priority order).
-spec info(core(), integer()) -> map().
info(C = #core{next = Next}, Now) when Next =< Now ->
    %% as of Now, even if the shell's timer has not fired yet
    {C1, _} = expire(Now, C),
    info(C1, Now);
info(C = #core{srcs = Srcs, top = Top, last = Last}, Now) ->
    Order = sources(C),
    #{sources => Order,
      winner => case Top of none -> none; I -> element(I, C#core.by_idx) end,
      holds => [{Src, remaining(H, Now)}
                || Src <- Order, #src{hold = H} <- [maps:get(Src, Srcs)],
                   holding(H, Now)],
      latches => [{Src, V} || Src <- Order,
                              #src{latch = {value, V}} <- [maps:get(Src, Srcs)]],
      last => Last}.

%%====================================================================
%% Emissions
%%====================================================================

emission(Src, S = #src{idx = J}, Op, Now, C = #core{top = Top}) ->
    Delivered = (Top =:= none) orelse J =< Top,
    S1 = case Op of
             {send, _, Hold} -> S#src{latch = none, hold = start_hold(Hold, S, Now)};
             {set, V} -> S#src{latch = {value, V}, hold = infinity};
             unset -> S#src{latch = none, hold = none}
         end,
    C1 = update_src(Src, S, S1, C),
    {C2, Out} = case {Delivered, Op} of
                    {true, {send, V1, _}} -> {C1#core{last = {value, V1}}, [V1]};
                    {true, {set, V1}} -> {C1#core{last = {value, V1}}, [V1]};
                    _ -> {C1, []}
                end,
    repick(Top =/= none, C2, Out).

start_hold(default, #src{default = D}, Now) -> deadline(D, Now);
start_hold(Hold, _S, Now) -> deadline(Hold, Now).

deadline(0, _Now) -> none;
deadline(infinity, _Now) -> infinity;
deadline(Ms, Now) -> Now + Ms.

%% Keeps the cached top index and earliest deadline right after one source
%% changed, touching the whole table only when that source was the top or the
%% earliest deadline.
update_src(Src, #src{hold = Old}, S1 = #src{idx = J, hold = New},
           C = #core{srcs = Srcs, top = Top, next = Next}) ->
    C1 = C#core{srcs = Srcs#{Src := S1}},
    C2 = if New =/= none, (Top =:= none orelse J < Top) -> C1#core{top = J};
            New =:= none, J =:= Top -> retop(C1);
            true -> C1
         end,
    if is_integer(New), New < Next -> C2#core{next = New};
       is_integer(Old), Old =:= Next -> C2#core{next = earliest(C2)};
       true -> C2
    end.

%%====================================================================
%% Re-picking the winner
%%====================================================================

%% After any event: the highest holding source's latch is re-delivered if it
%% differs from the last value; with no holder left, `idle' is delivered if
%% the input had one before.
repick(HadHolder, C = #core{top = none, idle = Idle}, Out) ->
    case {HadHolder, Idle} of
        {true, {value, V}} -> {C#core{last = Idle}, Out ++ [V]};
        _ -> {C, Out}
    end;
repick(_HadHolder, C = #core{top = Top, by_idx = ByIdx, srcs = Srcs, last = Last},
       Out) ->
    case maps:get(element(Top, ByIdx), Srcs) of
        #src{latch = Last} -> {C, Out};
        #src{latch = {value, V} = L} -> {C#core{last = L}, Out ++ [V]};
        #src{latch = none} -> {C, Out}
    end.

expire(Now, C = #core{srcs = Srcs, top = Top0}) ->
    Srcs1 = maps:map(fun(_, S = #src{hold = H}) when is_integer(H), H =< Now ->
                             S#src{hold = none};
                        (_, S) -> S
                     end, Srcs),
    C1 = retop(C#core{srcs = Srcs1}),
    repick(Top0 =/= none, C1#core{next = earliest(C1)}, []).

retop(C = #core{srcs = Srcs}) ->
    Top = maps:fold(fun(_, #src{hold = none}, T) -> T;
                       (_, #src{idx = I}, none) -> I;
                       (_, #src{idx = I}, T) -> min(I, T)
                    end, none, Srcs),
    C#core{top = Top}.

earliest(#core{srcs = Srcs}) ->
    maps:fold(fun(_, #src{hold = H}, E) when is_integer(H) -> min(H, E);
                 (_, _, E) -> E
              end, infinity, Srcs).

%%====================================================================
%% Wiring
%%====================================================================

%% Sources that stay keep their latch and hold unless listed in Reset (their
%% upstream changed, so their state comes afresh with Synced).
rewire(Sources, Reset, C = #core{srcs = Old}) ->
    {Srcs, _} = lists:foldl(
                  fun({Src, Default}, {Acc, I}) ->
                          S = case {Old, lists:member(Src, Reset)} of
                                  {#{Src := Kept}, false} -> Kept;
                                  _ -> #src{idx = I}
                              end,
                          {Acc#{Src => S#src{idx = I, default = Default}}, I + 1}
                  end, {#{}, 1}, Sources),
    C1 = C#core{srcs = Srcs, by_idx = list_to_tuple([S || {S, _} <- Sources])},
    C1#core{next = earliest(C1)}.

apply_synced(Synced, C = #core{srcs = Srcs}) ->
    Srcs1 = lists:foldl(fun({Src, {value, _} = L}, Acc) ->
                                case Acc of
                                    #{Src := S} -> Acc#{Src := S#src{latch = L, hold = infinity}};
                                    #{} -> Acc
                                end;
                           ({_Src, none}, Acc) -> Acc
                        end, Srcs, Synced),
    C#core{srcs = Srcs1}.

%%====================================================================
%% Helpers for info
%%====================================================================

holding(none, _Now) -> false;
holding(infinity, _Now) -> true;
holding(D, Now) -> D > Now.

remaining(infinity, _Now) -> infinity;
remaining(D, Now) -> max(0, D - Now).
