%% @doc The credit of one subscription to the observer tap (SPEC §10): how
%% its producers and its feeder (`toroco_tap_feeder') share the bound of
%% `buffer' pending events without talking to each other. It is an
%% `atomics' array, written by the producers (behaviors, devices, routers,
%% in their own processes) and by the feeder:
%%
%% <table>
%% <tr><th>cell</th><th>what</th><th>who adds</th><th>who takes off</th></tr>
%% <tr><td>held</td><td>room taken for events not passed on yet</td>
%%     <td>a producer, `?CREDIT' at a time ({@link reserve/1}); the feeder
%%         for relayed events ({@link admit/2})</td>
%%     <td>a producer, the room its batch did not use ({@link give_back/2});
%%         the feeder once it passed them on ({@link passed/2})</td></tr>
%% <tr><td>dropped</td><td>events dropped, not reported yet</td>
%%     <td>producers ({@link dropped/2}), the feeder ({@link dropped/2})</td>
%%     <td>the feeder, when it reports them ({@link take_dropped/1})</td></tr>
%% <tr><td>seen</td><td>events the feeder counts as pending at the
%%     subscriber</td><td>the feeder ({@link passed/2})</td>
%%     <td>the feeder, from the subscriber's queue ({@link seen/2})</td></tr>
%% </table>
%%
%% A producer takes room only while held + seen &lt; buffer, else drops:
%% the count errs on the side of dropping early, never of growing the
%% subscriber's queue.
-module(toroco_tap_credit).

-export([new/1, max/1, reserve/1, give_back/2, dropped/2, admit/2, passed/2, seen/2,
         unreported/1, take_dropped/1, tight/1]).
-export_type([credit/0]).

-define(HELD, 1).
-define(DROPPED, 2).
-define(SEEN, 3).
-define(CREDIT, 16).

-opaque credit() :: {atomics:atomics_ref(), pos_integer()}.

%% @doc The credit of a subscription of `buffer' `Max'.
-spec new(pos_integer()) -> credit().
new(Max) ->
    {atomics:new(3, [{signed, true}]), Max}.

-spec max(credit()) -> pos_integer().
max({_, Max}) -> Max.

%% @doc Room for up to `?CREDIT' events taken at once by a producer, or 0
%% (the sink is full). A full sink is seen with reads alone.
-spec reserve(credit()) -> non_neg_integer().
reserve({A, Max}) ->
    case atomics:get(A, ?HELD) + atomics:get(A, ?SEEN) >= Max of
        true ->
            0;
        false ->
            Over = atomics:add_get(A, ?HELD, ?CREDIT) + atomics:get(A, ?SEEN) - Max,
            if
                Over =< 0 -> ?CREDIT;
                Over >= ?CREDIT -> atomics:sub(A, ?HELD, ?CREDIT), 0;
                true -> atomics:sub(A, ?HELD, Over), ?CREDIT - Over
            end
    end.

%% @doc Room taken and not used goes back.
-spec give_back(credit(), non_neg_integer()) -> ok.
give_back(_, 0) -> ok;
give_back({A, _}, Room) -> atomics:sub(A, ?HELD, Room).

%% @doc `D' more events dropped; `true' if they are the first since the
%% feeder last reported (it may have stopped looking: it is to be told).
-spec dropped(credit(), non_neg_integer()) -> boolean().
dropped(_, 0) -> false;
dropped({A, _}, D) -> atomics:add_get(A, ?DROPPED, D) =:= D.

%% @doc How many of `N' relayed events fit, room taken for them; the rest
%% are counted as dropped.
-spec admit(credit(), non_neg_integer()) -> non_neg_integer().
admit({A, Max}, N) ->
    Over = atomics:add_get(A, ?HELD, N) + atomics:get(A, ?SEEN) - Max,
    Admitted = case Over > 0 of
                   true -> atomics:sub(A, ?HELD, min(N, Over)), N - min(N, Over);
                   false -> N
               end,
    _ = dropped({A, Max}, N - Admitted),
    Admitted.

%% @doc `N' events passed on to the subscriber (of which `Held' had room
%% held for them): counted as pending before their room is given back.
-spec passed(credit(), {non_neg_integer(), non_neg_integer()}) -> ok.
passed({A, _}, {N, Held}) ->
    atomics:add(A, ?SEEN, N),
    atomics:sub(A, ?HELD, Held).

%% @doc The events pending at the subscriber, as its queue says; whether
%% there is room for one more message.
-spec seen(credit(), non_neg_integer()) -> boolean().
seen({A, Max}, Pending) ->
    atomics:put(A, ?SEEN, Pending),
    Pending < Max.

%% @doc How many drops wait to be reported.
-spec unreported(credit()) -> non_neg_integer().
unreported({A, _}) -> atomics:get(A, ?DROPPED).

%% @doc The drops not reported yet, now taken to be reported.
-spec take_dropped(credit()) -> non_neg_integer().
take_dropped({A, _}) ->
    D = atomics:get(A, ?DROPPED),
    _ = D > 0 andalso atomics:sub(A, ?DROPPED, D),
    D.

%% @doc Whether the subscriber's queue may be filling up (half the bound or
%% more pending) or drops wait to be reported: the feeder keeps looking.
-spec tight(credit()) -> boolean().
tight({A, Max}) ->
    Pending = atomics:get(A, ?SEEN) + atomics:get(A, ?HELD),
    (Pending > 0 andalso 2 * Pending >= Max) orelse atomics:get(A, ?DROPPED) > 0.
