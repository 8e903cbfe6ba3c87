%% @doc (API) Terms become JSON one way everywhere (SPEC §11): the dashboard, the
%% Foxglove bridge and the recordings all use this module.
%%
%% {@link value/1} is the JSON form of a term (as a `jiffy'-encodable term):
%% numbers stay numbers, `true'/`false'/`null' stay, other atoms and UTF-8
%% binaries become strings, lists and tuples become arrays, maps with atom or
%% binary keys become objects, anything else becomes its printed form.
%% {@link term_text/1} is the Erlang literal (`io_lib:format("~0p")'), and
%% {@link parse_term/1} reads such a literal back (literals only, never
%% evaluated). {@link carry/1} is the pair a message carries.
-module(toroco_rec_json).

-export([value/1, term_text/1, parse_term/1, carry/1, encode/1]).

%% The longest term text accepted back (bytes).
-define(MAX_TERM_TEXT, 65536).

%% @doc The JSON form of `Term', ready for `jiffy:encode/1'.
-spec value(term()) -> jiffy:json_value().
value(N) when is_integer(N); is_float(N) -> N;
value(A) when A =:= true; A =:= false; A =:= null -> A;
value(A) when is_atom(A) -> atom_to_binary(A, utf8);
value(B) when is_binary(B) ->
    case unicode:characters_to_binary(B, utf8, utf8) of
        B -> B;
        _ -> printed(B)
    end;
value(L) when is_list(L) ->
    case is_proper(L) of
        true -> [value(X) || X <- L];
        false -> printed(L)
    end;
value(T) when is_tuple(T) -> [value(X) || X <- tuple_to_list(T)];
value(M) when is_map(M) ->
    case lists:all(fun(K) -> is_atom(K) orelse is_binary(K) end, maps:keys(M)) of
        true -> {[{key(K), value(V)} || {K, V} <- lists:sort(maps:to_list(M))]};
        false -> printed(M)
    end;
value(Other) -> printed(Other).

is_proper([_ | T]) -> is_proper(T);
is_proper([]) -> true;
is_proper(_) -> false.

key(K) when is_atom(K) -> atom_to_binary(K, utf8);
key(K) when is_binary(K) -> value(K).

printed(T) -> term_text(T).

%% @doc The Erlang literal of `Term' as UTF-8 text.
-spec term_text(term()) -> binary().
term_text(Term) ->
    unicode:characters_to_binary(io_lib:format("~0tp", [Term])).

%% @doc Reads a term literal sent back by a person or a program: only
%% literals (numbers, atoms, strings, binaries, lists, tuples, maps); never
%% evaluated. A trailing full stop is optional.
-spec parse_term(binary() | string()) -> {ok, term()} | {error, {bad_term, binary()}}.
parse_term(Text) when is_binary(Text), byte_size(Text) > ?MAX_TERM_TEXT ->
    {error, {bad_term, <<"too long">>}};
parse_term(Text) when is_binary(Text) ->
    case unicode:characters_to_list(Text) of
        L when is_list(L) -> parse_term(L);
        _ -> {error, {bad_term, <<"not UTF-8">>}}
    end;
parse_term(Text) when is_list(Text) ->
    Dotted = case lists:reverse(string:trim(Text)) of
                 [$. | _] -> Text;
                 _ -> Text ++ "."
             end,
    case erl_scan:string(Dotted) of
        {ok, Tokens, _} ->
            case erl_parse:parse_term(Tokens) of
                {ok, Term} -> {ok, Term};
                {error, {_, _, Msg}} -> {error, {bad_term, reason(Msg)}}
            end;
        {error, {_, _, Msg}, _} -> {error, {bad_term, reason(Msg)}}
    end;
parse_term(_) ->
    {error, {bad_term, <<"not text">>}}.

reason(Msg) ->
    unicode:characters_to_binary(io_lib:format("~ts", [erl_parse:format_error(Msg)])).

%% @doc The two fields of every message that carries a value.
-spec carry(term()) -> #{binary() => jiffy:json_value()}.
carry(Term) ->
    #{<<"value">> => value(Term), <<"term">> => term_text(Term)}.

%% @doc JSON text of a term already in JSON form (see {@link value/1}).
-spec encode(jiffy:json_value()) -> binary().
encode(Json) ->
    iolist_to_binary(jiffy:encode(Json)).
