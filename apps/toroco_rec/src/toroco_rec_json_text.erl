%% @doc JSON text of JSON values (as `toroco_rec_json:value/1' makes them,
%% and maps with atom or binary keys), in plain Erlang. The bridge, the
%% recorder and the flight recorder write every event through it: for the
%% small messages of the event path it costs a fraction of a NIF call's
%% fixed price (`jiffy:encode/1', used elsewhere, pays a few microseconds
%% per call however small the value). `jiffy' is the project's JSON
%% encoder (the dashboard's pages, the detector datagrams of the simulated
%% camera, the run's summary line, the links of `toroco_hw'); this module
%% is the one plain-Erlang writer, for hot paths only.
%%
%% Strings are written as they are unless they hold `"', `\' or a control
%% character (found with one precompiled `binary:match/2'), which are
%% escaped; floats in their shortest round-trip form.
-module(toroco_rec_json_text).

-export([encode/1]).

-define(PATTERN_KEY, {?MODULE, escapes}).

%% @doc The JSON text of `Json' (iodata).
-spec encode(term()) -> iodata().
encode(true) -> <<"true">>;
encode(false) -> <<"false">>;
encode(null) -> <<"null">>;
encode(N) when is_integer(N) -> integer_to_binary(N);
encode(F) when is_float(F) -> float_to_binary(F, [short]);
encode(A) when is_atom(A) -> string(atom_to_binary(A, utf8));
encode(B) when is_binary(B) -> string(B);
encode([]) -> <<"[]">>;
encode([H | T]) -> [$[, encode(H), [[$,, encode(X)] || X <- T], $]];
encode({Props}) when is_list(Props) -> object(Props);
encode(M) when is_map(M) -> object(maps:to_list(M)).

object([]) -> <<"{}">>;
object([{K, V} | T]) ->
    [${, key(K), $:, encode(V), [[$,, key(K1), $:, encode(V1)] || {K1, V1} <- T], $}].

key(K) when is_atom(K) -> string(atom_to_binary(K, utf8));
key(K) when is_binary(K) -> string(K).

string(B) ->
    case binary:match(B, pattern()) of
        nomatch -> [$", B, $"];
        _ -> [$", escape(B, <<>>), $"]
    end.

escape(<<$", R/binary>>, Acc) -> escape(R, <<Acc/binary, "\\\"">>);
escape(<<$\\, R/binary>>, Acc) -> escape(R, <<Acc/binary, "\\\\">>);
escape(<<$\n, R/binary>>, Acc) -> escape(R, <<Acc/binary, "\\n">>);
escape(<<$\r, R/binary>>, Acc) -> escape(R, <<Acc/binary, "\\r">>);
escape(<<$\t, R/binary>>, Acc) -> escape(R, <<Acc/binary, "\\t">>);
escape(<<C, R/binary>>, Acc) when C < 32 ->
    Hex = list_to_binary(io_lib:format("\\u~4.16.0b", [C])),
    escape(R, <<Acc/binary, Hex/binary>>);
escape(<<C, R/binary>>, Acc) -> escape(R, <<Acc/binary, C>>);
escape(<<>>, Acc) -> Acc.

pattern() ->
    try persistent_term:get(?PATTERN_KEY)
    catch error:badarg ->
            P = binary:compile_pattern([<<"\"">>, <<"\\">> | [<<C>> || C <- lists:seq(0, 31)]]),
            persistent_term:put(?PATTERN_KEY, P),
            P
    end.
