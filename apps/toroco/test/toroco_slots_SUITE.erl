%% The listeners' admission core (`toroco_slots') on its own: who is
%% admitted, who is shed, who is refused, and when each deadline falls.
-module(toroco_slots_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0]).
-export([admits_within_limits/1, peer_share_sheds_within_peer/1, full_sheds_longest_idle/1,
         too_young_refused/1, busy_never_shed_nor_timed_out/1, deadlines/1,
         random_against_brute_force/1]).

-define(LIMITS, #{max => 4, max_per_peer => 2, min_age => 100, request_timeout => 50,
                  idle_timeout => 500}).

all() ->
    [admits_within_limits, peer_share_sheds_within_peer, full_sheds_longest_idle,
     too_young_refused, busy_never_shed_nor_timed_out, deadlines, random_against_brute_force].

admits_within_limits(doc) ->
    ["Below both limits every newcomer is admitted and counted per address"];
admits_within_limits(_Config) ->
    S = admit_all([{a, p1, 0}, {b, p2, 0}, {c, p1, 1}], toroco_slots:new(?LIMITS)),
    ?assertEqual(3, toroco_slots:size(S)),
    ?assertEqual(#{p1 => 2, p2 => 1}, toroco_slots:peers(S)).

peer_share_sheds_within_peer(doc) ->
    ["An address at its share sheds its own longest-idle connection, never another's"];
peer_share_sheds_within_peer(_Config) ->
    S0 = admit_all([{a, p1, 0}, {x, p2, 0}, {b, p1, 10}], toroco_slots:new(?LIMITS)),
    S1 = toroco_slots:done(a, 150, S0),
    %% b has been idle longer than a now (a ended a request at 150)
    ?assertMatch({shed, b, _}, toroco_slots:admit(c, p1, 200, S1)),
    {shed, b, S2} = toroco_slots:admit(c, p1, 200, S1),
    ?assertEqual(#{p1 => 2, p2 => 1}, toroco_slots:peers(S2)),
    ?assert(toroco_slots:is_member(x, S2)).

full_sheds_longest_idle(doc) ->
    ["A full listener sheds the longest-idle connection of any address"];
full_sheds_longest_idle(_Config) ->
    S0 = admit_all([{a, p1, 0}, {b, p2, 5}, {c, p3, 10}, {d, p4, 20}], toroco_slots:new(?LIMITS)),
    S1 = toroco_slots:done(a, 120, S0),
    {shed, b, S2} = toroco_slots:admit(e, p5, 200, S1),
    ?assertEqual(4, toroco_slots:size(S2)),
    ?assert(toroco_slots:is_member(e, S2)).

too_young_refused(doc) ->
    ["When no candidate is min_age old the newcomer is refused and nothing changes"];
too_young_refused(_Config) ->
    S0 = admit_all([{a, p1, 0}, {b, p1, 10}], toroco_slots:new(?LIMITS)),
    ?assertEqual({refuse, too_many_from_peer, S0}, toroco_slots:admit(c, p1, 50, S0)),
    S1 = admit_all([{c, p2, 20}, {d, p3, 30}], S0),
    ?assertEqual({refuse, too_many_clients, S1}, toroco_slots:admit(e, p4, 99, S1)).

busy_never_shed_nor_timed_out(doc) ->
    ["A busy connection (serving, or a WebSocket) has no deadline and is never shed"];
busy_never_shed_nor_timed_out(_Config) ->
    S0 = admit_all([{a, p1, 0}, {b, p1, 0}], toroco_slots:new(?LIMITS)),
    S1 = toroco_slots:busy(a, toroco_slots:busy(b, S0)),
    ?assertEqual(infinity, toroco_slots:next_deadline(S1)),
    ?assertEqual({[], S1}, toroco_slots:expired(1000000, S1)),
    ?assertMatch({refuse, too_many_from_peer, _}, toroco_slots:admit(c, p1, 1000000, S1)).

deadlines(doc) ->
    ["A request must end request_timeout after it began (a begun one keeps its start); "
     "an idle connection goes idle_timeout after its last request"];
deadlines(_Config) ->
    S0 = admit_all([{a, p1, 0}], toroco_slots:new(?LIMITS)),
    ?assertEqual(50, toroco_slots:next_deadline(S0)),
    ?assertMatch({[], _}, toroco_slots:expired(49, S0)),
    ?assertMatch({[{a, request_timeout}], _}, toroco_slots:expired(50, S0)),
    S1 = toroco_slots:done(a, 40, S0),
    ?assertEqual(540, toroco_slots:next_deadline(S1)),
    S2 = toroco_slots:started(a, 100, S1),
    ?assertEqual(150, toroco_slots:next_deadline(toroco_slots:started(a, 120, S2))),
    %% begun late in an idle spell: still ends with the spell
    ?assertEqual(540, toroco_slots:next_deadline(toroco_slots:started(a, 520, S1))),
    {[{a, idle_timeout}], S3} = toroco_slots:expired(540, S1),
    ?assertEqual(0, toroco_slots:size(S3)),
    ?assertEqual(#{}, toroco_slots:peers(S3)).

random_against_brute_force(doc) ->
    ["2,000 random operations: the slots never exceed max nor a peer's share, a shed "
     "victim is the longest-idle eligible one, and a refusal happens only with no "
     "eligible one (recomputed from a plain list)"];
random_against_brute_force(_Config) ->
    rand:seed(exsss, {7, 8, 9}),
    #{max := Max, max_per_peer := PerPeer, min_age := MinAge, request_timeout := RT,
      idle_timeout := IT} = ?LIMITS,
    %% the model: [{Id, Peer, Since, Last, Phase}]
    Deadline = fun({_, _, Since, _, request}) -> Since + RT;
                  ({_, _, _, Last, idle}) -> Last + IT;
                  ({_, _, _, _, busy}) -> infinity
               end,
    Step = fun(I, {S, Model, Now0}) ->
                   Now = Now0 + rand:uniform(40),
                   case rand:uniform(4) of
                       1 ->
                           Peer = rand:uniform(4),
                           Eligible = fun(Pred) ->
                                              lists:sort([{L, Id} || {Id, P, Since, L, Ph} <- Model,
                                                                     Ph =/= busy,
                                                                     Now - Since >= MinAge,
                                                                     Pred(P)])
                                      end,
                           FromPeer = length([x || {_, P, _, _, _} <- Model, P =:= Peer]),
                           Expected = case {FromPeer >= PerPeer, length(Model) >= Max} of
                                          {true, _} -> Eligible(fun(P) -> P =:= Peer end);
                                          {false, true} -> Eligible(fun(_) -> true end);
                                          {false, false} -> room
                                      end,
                           New = {I, Peer, Now, Now, request},
                           case {toroco_slots:admit(I, Peer, Now, S), Expected} of
                               {{ok, S1}, room} ->
                                   {S1, [New | Model], Now, admitted};
                               {{shed, V, S1}, [{_, V} | _]} ->
                                   {S1, [New | lists:keydelete(V, 1, Model)], Now, shed};
                               {{refuse, Why, S}, []} ->
                                   {S, Model, Now, Why};
                               Other ->
                                   ct:fail({admit, I, Other, Model})
                           end;
                       2 when Model =/= [] ->
                           {Id, P, Since, _, _} = lists:nth(rand:uniform(length(Model)), Model),
                           {toroco_slots:done(Id, Now, S),
                            lists:keystore(Id, 1, Model, {Id, P, Since, Now, idle}), Now, done};
                       3 when Model =/= [] ->
                           {Id, P, Since, L, _} = lists:nth(rand:uniform(length(Model)), Model),
                           {toroco_slots:busy(Id, S),
                            lists:keystore(Id, 1, Model, {Id, P, Since, L, busy}), Now, busy};
                       _ ->
                           {Gone, S1} = toroco_slots:expired(Now, S),
                           Due = lists:sort([Id || M = {Id, _, _, _, _} <- Model,
                                                   Deadline(M) =< Now]),
                           ?assertEqual(Due, lists:sort([Id || {Id, _} <- Gone])),
                           Left = [M || M = {Id, _, _, _, _} <- Model, not lists:member(Id, Due)],
                           ?assertEqual(lists:min([infinity | [Deadline(M) || M <- Left]]),
                                        toroco_slots:next_deadline(S1)),
                           {S1, Left, Now, case Due of [] -> none_due; _ -> expired end}
                   end
           end,
    Count = fun(I, {S, Model, Now, Seen}) ->
                    {S1, Model1, Now1, What} = Step(I, {S, Model, Now}),
                    {S1, Model1, Now1, maps:update_with(What, fun(N) -> N + 1 end, 1, Seen)}
            end,
    {S, Model, _, Seen} = lists:foldl(Count, {toroco_slots:new(?LIMITS), [], 0, #{}},
                                      lists:seq(1, 2000)),
    ct:pal("outcomes: ~p", [Seen]),
    %% every kind of outcome came up, so each comparison above was made
    [?assert(maps:get(K, Seen, 0) > 10)
     || K <- [admitted, shed, too_many_from_peer, too_many_clients, expired, done, busy]],
    ?assertEqual(length(Model), toroco_slots:size(S)),
    ?assert(lists:all(fun(N) -> N =< PerPeer end, maps:values(toroco_slots:peers(S)))).

admit_all(List, S0) ->
    lists:foldl(fun({Id, Peer, Now}, S) -> {ok, S1} = toroco_slots:admit(Id, Peer, Now, S), S1 end,
                S0, List).
