%% The suites wait on events (STYLE, tests): on a message, a condition
%% with a bounded timeout or a paced load's end, through toroco_test_lib
%% when it is not a `receive' with a pattern. A `timer:sleep' or a bare
%% `receive after' (a receive whose only clause is its `after') in a suite
%% or test module of any application or of test/ is a wait on time alone,
%% and this suite names its file and line.
-module(toroco_waits_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

all() ->
    [the_check_finds_planted_waits, no_suite_waits_on_time_alone].

the_check_finds_planted_waits() ->
    [{doc, "The check names the line of each timer:sleep and bare receive after of a planted "
      "module (also one split over lines), and not a sleep in a comment or a string, nor a "
      "receive with a pattern"}].
the_check_finds_planted_waits(Config) ->
    File = filename:join(?config(data_dir, Config), "planted_waits.txt"),
    ?assertEqual([{File, 8, 'timer:sleep'}, {File, 11, 'receive after'},
                  {File, 14, 'receive after'}],
                 waits_on_time(File)).

no_suite_waits_on_time_alone() ->
    [{doc, "No suite or test module under apps/*/test or test/ calls timer:sleep or has a bare "
      "receive after: its waits go through toroco_test_lib (apps/toroco_test)"}].
no_suite_waits_on_time_alone(_Config) ->
    Root = toroco_test_lib:root(),
    Files = filelib:wildcard(filename:join(Root, "apps/*/test/*.erl"))
        ++ filelib:wildcard(filename:join(Root, "test/*.erl")),
    %% the scan reads this suite and the runtime's suites, at the least
    ?assert(length(Files) > 10, Files),
    Found = lists:append([waits_on_time(F) || F <- Files]),
    ?assertEqual([], [{relative(Root, F), Line, What} || {F, Line, What} <- Found]).

%% Each wait on time alone in `File': `{File, Line, What}'. Read as
%% tokens, so comments and strings do not count.
waits_on_time(File) ->
    {ok, Bin} = file:read_file(File),
    {ok, Tokens, _} = erl_scan:string(unicode:characters_to_list(Bin)),
    [{File, Line, What} || {Line, What} <- waits(Tokens)].

waits([{atom, A, timer}, {':', _}, {atom, _, sleep} | Rest]) ->
    [{erl_anno:line(A), 'timer:sleep'} | waits(Rest)];
waits([{'receive', A}, {'after', _} | Rest]) ->
    [{erl_anno:line(A), 'receive after'} | waits(Rest)];
waits([_ | Rest]) ->
    waits(Rest);
waits([]) ->
    [].

relative(Root, File) ->
    lists:nthtail(length(Root) + 1, File).
