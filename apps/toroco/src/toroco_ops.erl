%% @doc Shell commands for operating a running robot, beside the API's
%% `toroco:top/0', `toroco:watch/2' and `toroco:reload/1'.
%%
%% <ul>
%% <li>{@link wiring_svg/1}: the wiring picture of `toroco:wiring_dot/0',
%%     rendered by Graphviz (`dot', Debian package `graphviz') into an SVG
%%     file, e.g. from `bin/torobot remote_console':
%%     `toroco_ops:wiring_svg("/tmp/wiring.svg")'.</li>
%% <li>{@link render/3}: the same for any `dot' text and output format.</li>
%% </ul>
-module(toroco_ops).

-export([wiring_svg/1, render/3]).

%% @doc Writes the running network's wiring to `Path' as SVG.
-spec wiring_svg(file:name_all()) -> ok | {error, term()}.
wiring_svg(Path) ->
    render(toroco:wiring_dot(), svg, Path).

%% @doc Renders Graphviz `dot' text into `Path' in `Format' (`svg', `png',
%% `pdf', ...). Errors: `{no_graphviz, dot}' when `dot' is not installed,
%% `{dot_failed, ExitStatus, Output}' when it refuses the graph, and file
%% errors as `{file, Path, Reason}'.
-spec render(iodata(), atom(), file:name_all()) -> ok | {error, term()}.
render(Dot, Format, Path) when is_atom(Format) ->
    case os:find_executable("dot") of
        false ->
            {error, {no_graphviz, dot}};
        Exe ->
            Tmp = unicode:characters_to_list(Path) ++ ".dot.tmp",
            case file:write_file(Tmp, Dot) of
                ok ->
                    try run(Exe, ["-T" ++ atom_to_list(Format), "-o", Path, Tmp])
                    after _ = file:delete(Tmp)
                    end;
                {error, Reason} ->
                    {error, {file, Path, Reason}}
            end
    end.

run(Exe, Args) ->
    Port = open_port({spawn_executable, Exe},
                     [{args, Args}, exit_status, stderr_to_stdout, binary, hide]),
    collect(Port, []).

collect(Port, Acc) ->
    receive
        {Port, {data, Data}} -> collect(Port, [Acc, Data]);
        {Port, {exit_status, 0}} -> ok;
        {Port, {exit_status, Status}} ->
            {error, {dot_failed, Status, iolist_to_binary(Acc)}}
    end.
