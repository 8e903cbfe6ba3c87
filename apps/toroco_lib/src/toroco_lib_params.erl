%% @doc The parameters of the library's behaviors: each behavior declares
%% its parameters once (name, kind, default) in `params/0', and its `init/1'
%% checks what it was given with {@link check/2}, so a bad parameter is
%% refused when the behavior is added and the reason names it:
%% `toroco:add_behavior/3' answers `{error, {start_failed, {Name,
%% {bad_param, {Param, Value}}}}}' (or `{unknown_param, Param}').
%%
%% Kinds: `speed' (a wheel velocity, -100..100), `pos_speed' (0..100),
%% `ms' (a positive integer of milliseconds), `metres' (a positive number),
%% `pos_number', `non_neg_number', `integer', `wheels' (a `{Left, Right}'
%% pair of speeds), `{one_of, [Atom]}' and `term' (anything).
-module(toroco_lib_params).

-export([check/2, refuse/2]).
-export_type([spec/0, kind/0, error/0]).

-type kind() :: speed | pos_speed | ms | metres | pos_number | non_neg_number
              | integer | wheels | {one_of, [atom()]} | term.
-type spec() :: {Name :: atom(), kind(), Default :: term()}.
-type error() :: {bad_param, {atom(), term()}} | {unknown_param, term()}.

%% @doc The parameters with the defaults filled in, or the first parameter
%% that is unknown or of the wrong kind.
-spec check(term(), [spec()]) -> {ok, map()} | {error, error()}.
check(Params, Specs) when is_map(Params) ->
    Known = [Name || {Name, _, _} <- Specs],
    case [K || K <- maps:keys(Params), not lists:member(K, Known)] of
        [Unknown | _] ->
            {error, {unknown_param, Unknown}};
        [] ->
            Merged = maps:merge(maps:from_list([{N, D} || {N, _, D} <- Specs]), Params),
            case [{N, maps:get(N, Merged)} || {N, Kind, _} <- Specs,
                                              not valid(Kind, maps:get(N, Merged))] of
                [] -> {ok, Merged};
                [Bad | _] -> {error, {bad_param, Bad}}
            end
    end;
check(Params, _Specs) ->
    {error, {bad_param, {params, Params}}}.

%% @doc The error for a parameter whose value is fine alone but not with
%% the others (a `far' below `near', say).
-spec refuse(atom(), map()) -> {error, error()}.
refuse(Name, Params) ->
    {error, {bad_param, {Name, maps:get(Name, Params)}}}.

-spec valid(kind(), term()) -> boolean().
valid(speed, V) -> is_number(V) andalso V >= -100 andalso V =< 100;
valid(pos_speed, V) -> is_number(V) andalso V >= 0 andalso V =< 100;
valid(ms, V) -> is_integer(V) andalso V > 0;
valid(metres, V) -> is_number(V) andalso V > 0;
valid(pos_number, V) -> is_number(V) andalso V > 0;
valid(non_neg_number, V) -> is_number(V) andalso V >= 0;
valid(integer, V) -> is_integer(V);
valid(wheels, {L, R}) -> valid(speed, L) andalso valid(speed, R);
valid(wheels, _) -> false;
valid({one_of, Values}, V) -> lists:member(V, Values);
valid(term, _) -> true.
