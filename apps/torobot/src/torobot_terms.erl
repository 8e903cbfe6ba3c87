%% @doc Files of Erlang terms read with where each term starts
%% (`"File:Line"'), so that the robustness lab's fault schedules,
%% properties and replay files (SPEC §17) name the line of a bad entry.
-module(torobot_terms).

-export([read/1]).

%% @doc The terms of a file with where each is (`"File:Line"'), or
%% `{error, {Reason, "File:Line"}}'.
-spec read(file:name_all()) -> {ok, [{string(), term()}]} | {error, {atom(), term()}}.
read(File) ->
    case file:open(File, [read, {encoding, utf8}]) of
        {ok, Fd} ->
            try read_terms(Fd, File, 1, [])
            after file:close(Fd)
            end;
        {error, Reason} ->
            {error, {Reason, lists:flatten(io_lib:format("~ts", [File]))}}
    end.

read_terms(Fd, File, Line, Acc) ->
    case io:request(Fd, {get_until, unicode, '', erl_scan, tokens, [Line]}) of
        {ok, Tokens = [First | _], End} ->
            case erl_parse:parse_term(Tokens) of
                {ok, Term} ->
                    read_terms(Fd, File, End, [{loc(File, erl_scan:line(First)), Term} | Acc]);
                {error, {L, Mod, Why}} ->
                    {error, {malformed, {loc(File, L), lists:flatten(Mod:format_error(Why))}}}
            end;
        {eof, _} ->
            {ok, lists:reverse(Acc)};
        {error, {L, Mod, Why}, _} ->
            {error, {malformed, {loc(File, L), lists:flatten(Mod:format_error(Why))}}};
        {error, Why} ->
            {error, {malformed, {loc(File, Line), Why}}}
    end.

loc(File, {L, _}) -> loc(File, L);
loc(File, L) -> lists:flatten(io_lib:format("~ts:~b", [File, L])).

