%% The guides say what is true. The runtime's supervision tree, as the
%% README and the concepts guide draw it, is `toroco_sup''s children in
%% their order. Every block of README.md and doc/*.md marked runnable (the
%% line `<!-- runnable -->' just before its opening fence) runs as written,
%% from the project's top folder, on the code `make' built:
%% <ul>
%% <li>a `sh' block in `bash -eu': it must exit 0;</li>
%% <li>an `erlang' block written as a shell session (`1> expr.' lines, each
%%     followed by the output it shows) in a fresh `erl': no command may
%%     raise, and every output line shown must appear, in order (white
%%     space aside; a console device prints on its own time, so the session
%%     is given a bounded while to print them).</li>
%% </ul>
-module(toroco_docs_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, suite/0, init_per_suite/1, end_per_suite/1]).
-export([supervision_trees/1, runnable_blocks/1, shell_blocks/1, erlang_sessions/1]).
-export([links_resolve/1, cited_sections_exist/1, nothing_outside_the_repository/1]).
-export([bench_run_has_its_header/1, no_hand_kept_figures/1]).

-define(MARK, "<!-- runnable -->").
-define(SHELL_TIMEOUT, 600000).
-define(SESSION_TIMEOUT, 120000).
%% The fields of doc/bench-run.md's header, as scripts/bench-report writes them.
-define(BENCH_FIELDS, ["Run", "Quick mode", "Date", "Commit", "CPU", "Memory", "OS", "OTP",
                       "Load", "CPU time", "Note"]).
%% Guides written by a run, not by hand: the bench's and the lab's reports.
%% Units of time, memory and rate, in a header or after a figure.
-define(UNIT, "(µs|\\bms\\b|\\bns\\b|MiB|\\bMB\\b|KiB|\\bKB\\b|\\bkB\\b|events/s)").
-define(GENERATED, ["bench-run.md", "lab_eval_report.md"]).

suite() ->
    [{timetrap, {minutes, 25}}].

all() ->
    [links_resolve, cited_sections_exist, nothing_outside_the_repository,
     bench_run_has_its_header, no_hand_kept_figures,
     supervision_trees, runnable_blocks, shell_blocks, erlang_sessions].

init_per_suite(Config) ->
    Root = toroco_test_lib:root(),
    Guides = [filename:join(Root, "README.md") | filelib:wildcard(filename:join([Root, "doc", "*.md"]))],
    [{root, Root}, {blocks, lists:append([blocks(G) || G <- Guides])} | Config].

end_per_suite(_Config) ->
    ok.

%%====================================================================
%% Cases
%%====================================================================

links_resolve(doc) ->
    ["Every relative link and image of README.md and doc/*.md names a file or folder that "
     "exists inside the repository"];
links_resolve(Config) ->
    Root = ?config(root, Config),
    Links = [{File, T} || File <- guides(Root), T <- links(File)],
    ct:comment("~b relative links", [length(Links)]),
    ?assert(length(Links) > 10),
    Broken = [{rel(Root, File), Target}
              || {File, Target} <- Links, not resolves(Root, File, Target)],
    ?assertEqual([], Broken).

cited_sections_exist(doc) ->
    ["Every \"SPEC §N\" cited in the code, scripts and guides is a section of doc/spec.md, "
     "the contract in the repository"];
cited_sections_exist(Config) ->
    Root = ?config(root, Config),
    {ok, Spec} = file:read_file(filename:join([Root, "doc", "spec.md"])),
    Sections = [S || [S] <- match_all(Spec, "(?m)^## ([0-9]+[a-z]?)\\. ")],
    ?assert(length(Sections) >= 17),
    Missing = [{rel(Root, File), N}
               || File <- sources(Root),
                  {ok, Bin} <- [file:read_file(File)],
                  [N] <- match_all(Bin, "SPEC §\\s?([0-9]+[a-z]?)"),
                  not lists:member(N, Sections)],
    ?assertEqual([], lists:usort(Missing)).

nothing_outside_the_repository(doc) ->
    ["No file of the project points outside the repository for its contract (no path "
     "through the sibling folder the contract once lived in)"];
nothing_outside_the_repository(Config) ->
    Root = ?config(root, Config),
    Outside = [rel(Root, File) || File <- sources(Root),
                                  {ok, Bin} <- [file:read_file(File)],
                                  binary:match(Bin, <<"../", "shared/">>) =/= nomatch],
    ?assertEqual([], Outside).

supervision_trees(doc) ->
    ["The supervision tree drawn in the README and in doc/concepts.md is toroco_sup's "
     "children, in the order they start"];
supervision_trees(Config) ->
    {ok, {_, Specs}} = toroco_sup:init([]),
    Children = [child_label(S) || S <- Specs],
    Root = ?config(root, Config),
    [?assertEqual({File, Children}, {File, drawn_tree(filename:join(Root, File))})
     || File <- ["README.md", "doc/concepts.md"]],
    ok.

runnable_blocks(doc) ->
    ["The guides mark shell blocks and Erlang sessions runnable, and every marked block "
     "is one this suite knows how to run"];
runnable_blocks(Config) ->
    Blocks = ?config(blocks, Config),
    ct:comment("~p runnable blocks: ~p", [length(Blocks), [{F, L, Lang} || {F, L, Lang, _} <- Blocks]]),
    ?assert(lists:any(fun({_, _, Lang, _}) -> Lang =:= "sh" end, Blocks)),
    ?assert(lists:any(fun({_, _, Lang, _}) -> Lang =:= "erlang" end, Blocks)),
    [?assert(lists:member(Lang, ["sh", "erlang"]), {File, Line, Lang}) || {File, Line, Lang, _} <- Blocks],
    [?assertNotEqual([], commands(Lines), {File, Line}) || {File, Line, "erlang", Lines} <- Blocks],
    ok.

shell_blocks(doc) ->
    ["Every runnable sh block of the guides exits 0, run as written from the top folder"];
shell_blocks(Config) ->
    Root = ?config(root, Config),
    [run_shell(Root, File, Line, Lines) || {File, Line, "sh", Lines} <- ?config(blocks, Config)],
    ok.

erlang_sessions(doc) ->
    ["Every runnable Erlang shell session of the guides runs in a fresh erl: no command "
     "raises, and the output lines it shows appear in order"];
erlang_sessions(Config) ->
    Root = ?config(root, Config),
    [run_session(Root, File, Line, Lines) || {File, Line, "erlang", Lines} <- ?config(blocks, Config)],
    ok.

bench_run_has_its_header(doc) ->
    ["doc/bench-run.md, the tables of one `make bench', opens with the header the run "
     "wrote: the run (full or partial), quick mode, date, commit, CPU, memory, OS, OTP, "
     "load, CPU time and a note, each filled in, before the first table; a quick run says "
     "it is partial"];
bench_run_has_its_header(Config) ->
    Root = ?config(root, Config),
    {ok, Bin} = file:read_file(filename:join([Root, "doc", "bench-run.md"])),
    Fields = maps:from_list([{K, V} || [K, V] <- match_all(Bin, "(?m)^- \\*\\*([^*]+):\\*\\* (\\S.*)$")]),
    ?assertEqual([], [F || F <- ?BENCH_FIELDS, not maps:is_key(F, Fields)]),
    #{"Run" := Run, "Quick mode" := Quick} = Fields,
    ?assert(lists:member(Quick, ["yes", "no"])),
    ?assert(lists:prefix("full", Run) orelse lists:prefix("partial", Run)),
    ?assert(Quick =:= "no" orelse lists:prefix("partial", Run)),
    {Note, _} = binary:match(Bin, <<"- **Note:** ">>),
    {Table, _} = binary:match(Bin, <<"\n|---">>),
    ?assert(Note < Table).

no_hand_kept_figures(doc) ->
    ["README.md and the guides keep no table of measured figures by hand (a cell that is a "
     "number with a time, memory or rate unit, or two bare numbers in a row under a header "
     "naming such a unit): figures come from the files runs write (doc/bench-run.md, the "
     "lab's eval report)"];
no_hand_kept_figures(Config) ->
    Root = ?config(root, Config),
    Guides = [G || G <- guides(Root), not lists:member(filename:basename(G), ?GENERATED)],
    Rows = [{rel(Root, G), R} || G <- Guides, R <- figure_rows(G)],
    ?assertEqual([], Rows).

%%====================================================================
%% Reading the guides
%%====================================================================

%% {File, Line of the fence, Language, Lines} of every block marked runnable.
blocks(Path) ->
    {ok, Bin} = file:read_file(Path),
    Lines = string:split(unicode:characters_to_list(Bin), "\n", all),
    File = relative(Path),
    marked(lists:zip(lists:seq(1, length(Lines)), Lines), File, []).

%% (A block in a list item is indented: so may its mark and fences be.)
marked([{_, Mark}, {N, Fence} | Rest], File, Acc) ->
    case {string:trim(Mark), string:trim(Fence, leading)} of
        {?MARK, "```" ++ Lang} ->
            {Body, Rest1} = lists:splitwith(fun({_, L}) -> string:trim(L) =/= "```" end, Rest),
            Block = {File, N, string:trim(Lang), [string:trim(L, leading) || {_, L} <- Body]},
            marked(Rest1, File, [Block | Acc]);
        _ ->
            marked([{N, Fence} | Rest], File, Acc)
    end;
marked(_, _File, Acc) ->
    lists:reverse(Acc).

relative(Path) ->
    case filename:basename(filename:dirname(Path)) of
        "doc" -> filename:join("doc", filename:basename(Path));
        _ -> filename:basename(Path)
    end.

child_label(#{start := {pg, start_link, [Scope]}}) ->
    "pg (scope " ++ atom_to_list(Scope) ++ ")";
child_label(#{id := Id}) ->
    atom_to_list(Id).

%% The top level of the first tree under "toroco_sup (" in a guide: each
%% "├── name" or "└── name" line's name, "pg (scope S)" kept whole.
drawn_tree(Path) ->
    {ok, Bin} = file:read_file(Path),
    Lines = string:split(unicode:characters_to_list(Bin), "\n", all),
    [_ | After] = lists:dropwhile(fun(L) -> not lists:prefix("toroco_sup (", L) end, Lines),
    Tree = lists:takewhile(fun(L) -> L =/= "```" andalso L =/= "" end, After),
    [label(string:trim(Rest)) || L <- Tree, Rest <- [top_level(L)], Rest =/= none].

top_level("├── " ++ Rest) -> Rest;
top_level("└── " ++ Rest) -> Rest;
top_level(_) -> none.

label("pg " ++ Rest) ->
    "pg " ++ lists:takewhile(fun(C) -> C =/= $) end, Rest) ++ ")";
label(Rest) ->
    hd(string:lexemes(Rest, " ")).

%% A session's commands, each with the output lines shown after it.
commands(Lines) ->
    commands(Lines, []).

commands([], Acc) ->
    lists:reverse(Acc);
commands([L | Rest], Acc) ->
    case prompt(L) of
        {ok, Cmd} ->
            {Shown, Rest1} = lists:splitwith(fun(X) -> prompt(X) =:= none end, Rest),
            commands(Rest1, [{Cmd, [S || S <- Shown, S =/= ""]} | Acc]);
        none ->
            commands(Rest, Acc)
    end.

prompt(L) ->
    case re:run(L, "^[0-9]+> (.*)$", [{capture, all_but_first, list}, unicode]) of
        {match, [Cmd]} -> {ok, Cmd};
        nomatch -> none
    end.

%%====================================================================
%% Running them
%%====================================================================

run_shell(Root, File, Line, Lines) ->
    Script = lists:join("\n", Lines),
    ct:log("~ts:~p:~n~ts", [File, Line, Script]),
    Port = open_port({spawn_executable, os:find_executable("bash")},
                     [{args, ["-euc", Script]}, {cd, Root}, exit_status, stderr_to_stdout,
                      binary, {line, 4096}]),
    case collect(Port, [], erlang:monotonic_time(millisecond) + ?SHELL_TIMEOUT) of
        {0, Out} -> ct:log("~ts", [Out]);
        {Status, Out} -> ct:fail({File, Line, {exit_status, Status}, Out})
    end.

collect(Port, Acc, Deadline) ->
    Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
    receive
        {Port, {data, {_, Bin}}} -> collect(Port, [[Bin, $\n] | Acc], Deadline);
        {Port, {exit_status, S}} -> {S, iolist_to_binary(lists:reverse(Acc))}
    after Left ->
        catch port_close(Port),
        ct:fail({timeout, ?SHELL_TIMEOUT, iolist_to_binary(lists:reverse(Acc))})
    end.

run_session(Root, File, Line, Lines) ->
    Commands = commands(Lines),
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    Port = open_port({spawn_executable, os:find_executable("erl")},
                     [{args, lists:append([["-pa", P] || P <- Paths])}, {cd, Root},
                      exit_status, stderr_to_stdout, binary, stream]),
    [port_command(Port, [Cmd, $\n]) || {Cmd, _} <- Commands],
    Expected = [strip(S) || {_, Shown} <- Commands, S <- Shown],
    Deadline = erlang:monotonic_time(millisecond) + ?SESSION_TIMEOUT,
    Last = integer_to_list(length(Commands) + 1) ++ "> ",
    Out = await_output(Port, {Expected, Last}, <<>>, Deadline),
    port_command(Port, "halt().\n"),
    ct:log("~ts:~p:~n~ts", [File, Line, Out]),
    %% an exception, a syntax error, the shell terminating
    case re:run(Out, "\\*\\* exception|\\*\\*\\* |\\* [0-9]+:[0-9]+: ", [unicode]) of
        nomatch -> ok;
        _ -> ct:fail({File, Line, raised, Out})
    end,
    drain(Port).

%% Reads the session's output until every shown line has appeared in order
%% and the shell has prompted after the last command, or the deadline.
await_output(Port, {Expected, Last}, Out, Deadline) ->
    case in_order(Expected, strip(Out)) andalso binary:match(Out, list_to_binary(Last)) =/= nomatch of
        true -> Out;
        false ->
            Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
            receive
                {Port, {data, Bin}} -> await_output(Port, {Expected, Last}, <<Out/binary, Bin/binary>>, Deadline);
                {Port, {exit_status, S}} -> ct:fail({session_ended, S, Out, {expected, Expected}})
            after Left ->
                catch port_close(Port),
                ct:fail({timeout, ?SESSION_TIMEOUT, {expected, Expected}, Out})
            end
    end.

drain(Port) ->
    receive
        {Port, {data, _}} -> drain(Port);
        {Port, {exit_status, _}} -> ok
    after 30000 ->
        catch port_close(Port),
        ok
    end.

in_order([], _Out) -> true;
in_order([E | Rest], Out) ->
    case binary:match(Out, E) of
        {At, Len} -> in_order(Rest, binary:part(Out, At + Len, byte_size(Out) - At - Len));
        nomatch -> false
    end.

strip(S) ->
    unicode:characters_to_binary(re:replace(S, "\\s+", "", [global, unicode])).

%%====================================================================
%% Tables of figures
%%====================================================================

%% The rows of a guide's tables (fenced code left out) that hold measured
%% figures.
figure_rows(File) ->
    {ok, Bin} = file:read_file(File),
    Text = re:replace(Bin, "(?ms)^```.*?^```", "", [global, unicode, {return, binary}]),
    figure_rows(string:split(unicode:characters_to_list(Text), "\n", all), []).

figure_rows([], Acc) ->
    lists:reverse(Acc);
figure_rows(Lines, Acc) ->
    {_, Rest} = lists:splitwith(fun(L) -> not is_row(L) end, Lines),
    {Table, Rest1} = lists:splitwith(fun is_row/1, Rest),
    figure_rows(Rest1, lists:reverse(measured(Table), Acc)).

is_row(Line) ->
    string:prefix(string:trim(Line, leading), "|") =/= nomatch.

%% A row measured: a cell with a number and its unit, or (under a header
%% that names a unit) two cells that are bare numbers.
measured([]) ->
    [];
measured([Header | Body]) ->
    UnitHeader = re:run(Header, ?UNIT, [unicode]) =/= nomatch,
    [string:trim(Row) || Row <- Body,
                         Cells <- [cells(Row)],
                         lists:any(fun with_unit/1, Cells)
                             orelse (UnitHeader andalso length(lists:filter(fun bare/1, Cells)) >= 2)].

cells(Row) ->
    [string:trim(C) || C <- string:split(string:trim(Row), "|", all)].

with_unit(Cell) ->
    re:run(Cell, "^[0-9][0-9,.]*\\s*" ++ ?UNIT ++ "(\\s|\\(|$)", [unicode]) =/= nomatch.

bare(Cell) ->
    re:run(Cell, "^[0-9][0-9,.]*$", [unicode]) =/= nomatch.

%%====================================================================
%% Links and citations
%%====================================================================

guides(Root) ->
    [filename:join(Root, "README.md") | filelib:wildcard(filename:join([Root, "doc", "*.md"]))].

%% The project's own text files: code, tests, scripts, configuration and
%% guides (not what a build or npm put there).
sources(Root) ->
    Patterns = ["README.md", "Makefile", "rebar.config", "doc/*.md", "scripts/*",
                "apps/*/src/*.[eh]rl", "apps/*/test/*.erl", "apps/*/README.md",
                "test/*.erl", "bench/*", "c_src/*/*.[ch]", "c_src/*/src/*.[ch]",
                "c_src/*/*.md", "detector/*.[ch]pp", "detector/src/*.[ch]pp",
                "config/*.wiring", "config/*/*", "apps/*/priv/*.js", "apps/*/web/*.js",
                "apps/*/web/src/*.js"],
    lists:usort([F || P <- Patterns, F <- filelib:wildcard(filename:join(Root, P)),
                      filelib:is_regular(F)]).

%% The targets of [text](target) and ![alt](target), fenced code left out.
links(File) ->
    {ok, Bin} = file:read_file(File),
    Text = re:replace(Bin, "(?ms)^```.*?^```", "", [global, {return, binary}]),
    [T || [T] <- match_all(Text, "\\]\\(([^)\\s]+)\\)"),
          not is_external(T)].

is_external(T) ->
    lists:any(fun(P) -> string:prefix(T, P) =/= nomatch end,
              ["http://", "https://", "mailto:", "#"]).

resolves(Root, File, Target) ->
    [Path | _] = string:split(Target, "#"),
    Abs = filename:absname(filename:join(filename:dirname(File), Path)),
    Norm = normalize(filename:split(Abs), []),
    lists:prefix(filename:split(Root), Norm) andalso filelib:is_file(filename:join(Norm)).

normalize([], Acc) -> lists:reverse(Acc);
normalize([".." | Rest], [_ | Acc]) -> normalize(Rest, Acc);
normalize(["." | Rest], Acc) -> normalize(Rest, Acc);
normalize([P | Rest], Acc) -> normalize(Rest, [P | Acc]).

match_all(Bin, Re) ->
    case re:run(Bin, Re, [global, unicode, {capture, all_but_first, list}]) of
        {match, Ms} -> Ms;
        nomatch -> []
    end.

rel(Root, File) ->
    string:prefix(File, Root ++ "/").
