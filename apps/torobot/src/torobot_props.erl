%% @doc Properties of the robustness lab (SPEC §17): what a robot must do
%% over simulated time, checked on the observations of one lockstep run.
%% Pure: `torobot_chaos' gathers the observations (`torobot_sim') and
%% calls {@link violation/3}.
%%
%% A property: `{never, C}', `{within, Ms, C}' (C holds at some tick by
%% Ms), `{always_after, Trigger, Ms, C}' (each time Trigger starts to
%% hold, C holds within Ms; a window the run does not reach is not
%% judged), `{recovers, Ms}' (after each fault ends, the motors' winner is
%% again the one of the run without faults within Ms), `{'and', [P]}', or
%% a fun of the observations answering `true' (holds), `false' (violated at
%% the end) or `{violated, AtMs}'. A file of properties
%% (`config/props/*.props') is the `and' of its terms.
%%
%% Conditions, on one tick's observation: `wall_contact', `blue_contact'
%% (a contact began during the tick), `red_touched', `{distance_to_wall,
%% Op, M}' (Op one of `<', `=<', `>', `>='; metres from the robot's rim to
%% the nearest wall or arena edge), `{winner, motors, Source}' (the
%% behavior that wins the motors, `none' when none), `{motors, {L, R}}'
%% (the wheels' applied velocities), `{emitted, {Emitter, Output}}',
%% `{layer_out, L}', `{restarted, Name}', `{cut, Node}' and `{healed,
%% Node}' (a node of a robot over several nodes cut from the rest, killed,
%% or back: SPEC §13), `{figure, Key}' (a figure of the
%% world's summary, such as the docker's `docked_ms', is set by now),
%% `{'not', C}', `{any, [C]}', or a fun of the observation answering a
%% boolean.
%%
%% An observation: `#{t, wall, blue, red, dist, winner, motors, events,
%% figures}' (`figures': the world's summary then),
%% `events' holding `{emitted, Source}', `{restarted, Name}',
%% `{layer_out, L}', `{cut, Node}' and `{healed, Node}' of that tick.
-module(torobot_props).

-export([check/1, read/1, violation/3, settled/2]).
-export_type([property/0, condition/0, observation/0, violation/0]).

-type condition() :: atom() | tuple() | fun((observation()) -> boolean()).
-type property() :: {never, condition()} | {within, number(), condition()}
                  | {always_after, condition(), number(), condition()}
                  | {recovers, number()} | {'and', [property()]}
                  | fun(([observation()]) -> boolean() | {violated, number()}).
-type observation() :: #{t := non_neg_integer(), wall := boolean(), blue := boolean(),
                         red := boolean(), dist := float(), winner := atom(),
                         motors := {number(), number()}, events := [tuple()],
                         atom() => term()}.
-type violation() :: none | {term(), non_neg_integer()}.

%%====================================================================
%% Checking
%%====================================================================

%% @doc `ok', or `{error, {Reason, Culprit}}' for an unknown condition or
%% a malformed property.
-spec check(term()) -> ok | {error, {atom(), term()}}.
check({never, C}) -> condition(C);
check({within, Ms, C} = P) when is_number(Ms) -> positive(Ms, P, condition(C));
check({always_after, T, Ms, C} = P) when is_number(Ms) ->
    positive(Ms, P, first([condition(T), condition(C)]));
check({recovers, Ms} = P) when is_number(Ms) -> positive(Ms, P, ok);
check({'and', Ps}) when is_list(Ps), Ps =/= [] -> first([check(P) || P <- Ps]);
check(F) when is_function(F, 1) -> ok;
check(P) -> {error, {bad_property, P}}.

positive(Ms, P, _) when Ms < 0 -> {error, {bad_time, P}};
positive(_Ms, _P, R) -> R.

first(Results) ->
    case [R || R <- Results, R =/= ok] of
        [] -> ok;
        [E | _] -> E
    end.

condition(C) when C =:= wall_contact; C =:= blue_contact; C =:= red_touched -> ok;
condition({distance_to_wall, Op, M}) when is_number(M), (Op =:= '<' orelse Op =:= '=<'
                                                          orelse Op =:= '>' orelse Op =:= '>=') -> ok;
condition({winner, _Input, Source}) when is_atom(Source) -> ok;
condition({motors, {L, R}}) when is_number(L), is_number(R) -> ok;
condition({emitted, {E, O}}) when is_atom(E), is_atom(O) -> ok;
condition({layer_out, L}) when is_integer(L), L >= 0 -> ok;
condition({restarted, N}) when is_atom(N) -> ok;
condition({cut, N}) when is_atom(N) -> ok;
condition({healed, N}) when is_atom(N) -> ok;
condition({figure, K}) when is_atom(K) -> ok;
condition({'not', C}) -> condition(C);
condition({any, Cs}) when is_list(Cs) -> first([condition(C) || C <- Cs]);
condition(F) when is_function(F, 1) -> ok;
condition(C) -> {error, {unknown_condition, C}}.

%% @doc A file of property terms, checked; errors name `File:Line'.
-spec read(file:name_all()) -> {ok, property()} | {error, {atom(), term()}}.
read(File) ->
    case torobot_terms:read(File) of
        {ok, []} ->
            {error, {bad_property, {File, empty}}};
        {ok, Located} ->
            case [{Loc, E} || {Loc, T} <- Located, {error, E} <- [check(T)]] of
                [] ->
                    case [T || {_, T} <- Located] of
                        [One] -> {ok, One};
                        Many -> {ok, {'and', Many}}
                    end;
                [{Loc, {Reason, Culprit}} | _] ->
                    {error, {Reason, {Loc, Culprit}}}
            end;
        Error ->
            Error
    end.

%%====================================================================
%% Judging a run
%%====================================================================

%% @doc Whether the observations so far (of a run not over yet) already
%% violate `Prop' whatever comes next: a `never' whose condition held, a
%% `within' past its time, an `always_after' window closed without its
%% condition. A fun or `recovers' is never settled early.
-spec settled(property(), [observation()]) -> boolean().
settled({'and', Ps}, Obs) ->
    lists:any(fun(P) -> settled(P, Obs) end, Ps);
settled({never, _} = P, Obs) ->
    violation(P, Obs, #{}) =/= none;
settled({within, Ms, _} = P, Obs) ->
    last_t(Obs) > Ms andalso violation(P, Obs, #{}) =/= none;
settled({always_after, _, _, _} = P, Obs) ->
    violation(P, Obs, #{}) =/= none;
settled(_P, _Obs) ->
    false.

%% @doc The first violation of `Prop' in a run's observations (in time
%% order), `none' if it holds. `Context': `faults' (the concrete faults,
%% for `recovers') and `reference' (the observations of the same world
%% without faults). A fun that crashes is a violation at 0 naming the
%% crash.
-spec violation(property(), [observation()], map()) -> violation().
violation(Prop, Obs, Context) ->
    try prop(Prop, Obs, Context)
    catch Class:Reason -> {{crash, {Class, Reason}}, 0}
    end.

prop({never, C} = P, Obs, _Ctx) ->
    case [T || #{t := T} = O <- Obs, holds(C, O)] of
        [] -> none;
        [T | _] -> {P, T}
    end;
prop({within, Ms, C} = P, Obs, _Ctx) ->
    case [T || #{t := T} = O <- Obs, T =< Ms, holds(C, O)] of
        [_ | _] -> none;
        [] -> {P, min(round(Ms), last_t(Obs))}
    end;
prop({always_after, Trigger, Ms, C} = P, Obs, _Ctx) ->
    Starts = starts(Trigger, Obs, false, []),
    End = last_t(Obs),
    first_violation([case [T || #{t := T} = O <- Obs, T >= S, T =< S + Ms, holds(C, O)] of
                         [] when S + Ms =< End -> {P, round(S + Ms)};
                         _ -> none
                     end || S <- Starts]);
prop({recovers, Ms} = P, Obs, Ctx) ->
    Ref = maps:from_list([{T, W} || #{t := T, winner := W} <- maps:get(reference, Ctx, [])]),
    End = last_t(Obs),
    Ends = lists:usort([torobot_faults:ends(F) || F <- maps:get(faults, Ctx, [])]),
    first_violation([case [T || #{t := T, winner := W} <- Obs, T >= E, T =< E + Ms,
                                not is_map_key(T, Ref) orelse maps:get(T, Ref) =:= W] of
                         [] when E + Ms =< End -> {P, round(E + Ms)};
                         _ -> none
                     end || E <- Ends]);
prop({'and', Ps}, Obs, Ctx) ->
    first_violation([prop(P, Obs, Ctx) || P <- Ps]);
prop(F, Obs, _Ctx) when is_function(F, 1) ->
    case F(Obs) of
        true -> none;
        ok -> none;
        false -> {fun_property, last_t(Obs)};
        {violated, At} -> {fun_property, round(At)}
    end.

first_violation(Vs) ->
    case lists:sort(fun({_, A}, {_, B}) -> A =< B end, [V || V <- Vs, V =/= none]) of
        [] -> none;
        [V | _] -> V
    end.

starts(_C, [], _Was, Acc) ->
    lists:reverse(Acc);
starts(C, [#{t := T} = O | Rest], Was, Acc) ->
    Now = holds(C, O),
    starts(C, Rest, Now, case Now andalso not Was of
                             true -> [T | Acc];
                             false -> Acc
                         end).

last_t([]) -> 0;
last_t(Obs) -> maps:get(t, lists:last(Obs)).

holds(wall_contact, #{wall := W}) -> W;
holds(blue_contact, #{blue := B}) -> B;
holds(red_touched, #{red := R}) -> R;
holds({distance_to_wall, Op, M}, #{dist := D}) -> erlang:Op(D, M);
holds({winner, _Input, Source}, #{winner := W}) -> W =:= Source;
holds({motors, V}, #{motors := M}) -> M == V;
holds({emitted, Src}, #{events := E}) -> lists:member({emitted, Src}, E);
holds({layer_out, L}, #{events := E}) -> lists:member({layer_out, L}, E);
holds({restarted, N}, #{events := E}) -> lists:member({restarted, N}, E);
holds({cut, N}, #{events := E}) -> lists:member({cut, N}, E);
holds({healed, N}, #{events := E}) -> lists:member({healed, N}, E);
holds({figure, K}, O) ->
    not lists:member(maps:get(K, maps:get(figures, O, #{}), none), [none, undefined, false]);
holds({'not', C}, O) -> not holds(C, O);
holds({any, Cs}, O) -> lists:any(fun(C) -> holds(C, O) end, Cs);
holds(F, O) when is_function(F, 1) -> F(O) =:= true.
