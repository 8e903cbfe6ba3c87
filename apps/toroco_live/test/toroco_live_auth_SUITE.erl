%% The limit on wrong tokens (`toroco_live_auth''s pure core) against a
%% brute-force oracle: the verdict on every check of a random history of
%% checks from a few addresses, recomputed from the whole history by the
%% rule as written (ten failures within a minute, not themselves refused,
%% refuse the address for a minute from the tenth).
-module(toroco_live_auth_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("proper/include/proper.hrl").
-compile([export_all, nowarn_export_all]).

-define(MAX_FAILURES, 10).
-define(WINDOW_MS, 60000).
-define(BAN_MS, 60000).
-define(ADDRESSES, [{127, 0, 0, 2}, {127, 0, 0, 3}, {10, 0, 0, 7}]).

all() -> [core_matches_oracle, one_address_never_limits_another].

suite() -> [{timetrap, {minutes, 5}}].

%%====================================================================
%% Cases
%%====================================================================

core_matches_oracle() ->
    [{doc, "Every verdict of the core (true, false, {limited, Ms}) on random histories of "
      "checks is the oracle's"}].
core_matches_oracle(_Config) ->
    true = proper:quickcheck(prop_core_matches_oracle(), [{numtests, 300}, {to_file, user}]).

one_address_never_limits_another() ->
    [{doc, "The verdicts on one address's checks are the same with or without the other "
      "addresses' checks in between"}].
one_address_never_limits_another(_Config) ->
    true = proper:quickcheck(prop_addresses_independent(), [{numtests, 200}, {to_file, user}]).

%%====================================================================
%% Generators
%%====================================================================

%% Checks: an address, whether the credential was right (mostly not),
%% and the time since the last check (bursts and long pauses); long enough
%% that addresses reach their limit, and are let go again, often.
history() ->
    ?LET(Steps, resize(150, list({oneof(?ADDRESSES), frequency([{5, false}, {1, true}]),
                      frequency([{6, choose(0, 3000)}, {1, choose(20000, 70000)}])})),
         element(2, lists:foldl(fun({Ip, Good, Dt}, {T, Acc}) -> {T + Dt, [{Ip, Good, T + Dt} | Acc]} end,
                                {0, []}, Steps))).

%%====================================================================
%% Properties
%%====================================================================

prop_core_matches_oracle() ->
    ?FORALL(Rev, history(),
            begin
                History = lists:reverse(Rev),
                Core = run(History),
                Oracle = oracle(History),
                ?WHENFAIL(ct:pal("history ~p~ncore ~p~noracle ~p", [History, Core, Oracle]),
                          Core =:= Oracle)
            end).

prop_addresses_independent() ->
    ?FORALL(Rev, history(),
            begin
                History = lists:reverse(Rev),
                All = lists:zip(History, run(History)),
                lists:all(fun(Ip) ->
                                  Own = [E || E = {I, _, _} <- History, I =:= Ip],
                                  run(Own) =:= [V || {{I, _, _}, V} <- All, I =:= Ip]
                          end, ?ADDRESSES)
            end).

%% The core's verdicts, check after check.
run(History) ->
    {Verdicts, _} = lists:mapfoldl(fun({Ip, Good, T}, Core) -> toroco_live_auth:check(Ip, Good, T, Core) end,
                                   toroco_live_auth:new(), History),
    Verdicts.

%%====================================================================
%% The oracle
%%====================================================================

%% Check k from Ip at T is refused when an earlier check j of Ip opened a
%% ban still running at T (T_j =< T < T_j + ban); j opens a ban when it is
%% a failure, not refused itself, and Ip had at least ten such failures
%% within the window ending at j (j included). Each verdict is recomputed
%% from the whole history before it (the verdicts before it kept only so
%% that "not refused itself" is not recomputed again and again).
oracle(History) ->
    Indexed = lists:zip(lists:seq(1, length(History)), History),
    {Verdicts, _} = lists:foldl(fun({K, _}, {Acc, Seen}) ->
                                        V = verdict(K, Indexed, Seen),
                                        {[V | Acc], Seen#{K => V}}
                                end, {[], #{}}, Indexed),
    lists:reverse(Verdicts).

verdict(K, Indexed, Seen) ->
    {K, {Ip, Good, T}} = lists:keyfind(K, 1, Indexed),
    Bans = [Tj + ?BAN_MS || {J, {I, _, Tj}} <- Indexed, J < K, I =:= Ip, opens_ban(J, Indexed, Seen),
                            Tj =< T, T < Tj + ?BAN_MS],
    case Bans of
        [] -> Good;
        _ -> {limited, lists:max(Bans) - T}
    end.

opens_ban(J, Indexed, Seen) ->
    {J, {Ip, Good, Tj}} = lists:keyfind(J, 1, Indexed),
    not Good andalso maps:get(J, Seen) =:= false andalso
        length([I || {I, {Ip2, false, Ti}} <- Indexed, I =< J, Ip2 =:= Ip,
                     Ti > Tj - ?WINDOW_MS, maps:get(I, Seen) =:= false]) >= ?MAX_FAILURES.
