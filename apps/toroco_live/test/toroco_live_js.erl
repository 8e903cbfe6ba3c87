%% The Node side of the toroco_live suites: the reference clients installed
%% (web/build's `npm ci', only when the lockfile changed, so the test path
%% installs them itself), and a line-by-line JSON conversation with a
%% script of test/js.
-module(toroco_live_js).
-export([ensure_installed/0, start/1, start/2, send/2, await/3, stop/1, run/2, transcript/1]).

%% Common Test runs in a log directory; the app is found from this
%% module's source, which the compiler records.
app_dir() ->
    Src = proplists:get_value(source, ?MODULE:module_info(compile)),
    filename:dirname(filename:dirname(Src)).

%% The clients are pinned in web/package.json with the dashboard's page;
%% web/build installs them (npm ci, only when the lockfile changed).
ensure_installed() ->
    Out = os:cmd("sh '" ++ filename:join([app_dir(), "web", "build"]) ++ "' 2>&1; echo \"exit=$?\""),
    case string:find(Out, "exit=0") of
        nomatch -> {error, {web_build, Out}};
        _ -> ok
    end.

script(Name) -> filename:join([app_dir(), "test", "js", Name]).

env() -> [{"NODE_PATH", filename:join([app_dir(), "web", "node_modules"])}].

%% A driver script: JSON commands in, JSON events out.
start(Name) ->
    start(Name, []).

%% ... with more environment (`NODE_EXTRA_CA_CERTS' for a test CA).
start(Name, Env) ->
    Port = open_port({spawn_executable, os:find_executable("node")},
                     [{args, [script(Name)]}, {line, 1 bsl 20}, binary, exit_status,
                      {env, env() ++ Env}]),
    {Port, []}.

send({Port, _}, Map) ->
    port_command(Port, [jiffy:encode(Map), $\n]),
    ok.

%% Events until one for which Pred is true: {ok, Event, Seen} (Seen oldest
%% first, the matching one last) or {error, {timeout, Seen}}.
await(P, Pred, TimeoutMs) ->
    Until = erlang:monotonic_time(millisecond) + TimeoutMs,
    await(P, Pred, Until, []).

await(P = {Port, _}, Pred, Until, Acc) ->
    Left = max(0, Until - erlang:monotonic_time(millisecond)),
    receive
        {Port, {data, {eol, Line}}} ->
            Ev = jiffy:decode(Line, [return_maps]),
            log(Line),
            case Pred(Ev) of
                true -> {ok, Ev, lists:reverse([Ev | Acc])};
                false -> await(P, Pred, Until, [Ev | Acc])
            end;
        {Port, {exit_status, S}} -> {error, {exited, S, lists:reverse(Acc)}}
    after Left -> {error, {timeout, lists:reverse(Acc)}}
    end.

stop({Port, _}) ->
    catch port_close(Port),
    ok.

%% A one-shot script: its single JSON line.
run(Name, Args) ->
    Port = open_port({spawn_executable, os:find_executable("node")},
                     [{args, [script(Name) | Args]}, {line, 1 bsl 24}, binary, exit_status, {env, env()}]),
    collect(Port, []).

collect(Port, Acc) ->
    receive
        {Port, {data, {eol, Line}}} -> collect(Port, [Line | Acc]);
        {Port, {data, {noeol, Line}}} -> collect(Port, [Line | Acc]);
        {Port, {exit_status, 0}} -> jiffy:decode(iolist_to_binary(lists:reverse(Acc)), [return_maps]);
        {Port, {exit_status, S}} -> {error, {exited, S, lists:reverse(Acc)}}
    after 60000 -> {error, timeout}
    end.

%% The conversation is kept (the issue note quotes it) in the file named by
%% the process dictionary of the test case's process, if any.
log(Line) ->
    case get(transcript) of
        undefined -> ok;
        File -> file:write_file(File, [Line, $\n], [append])
    end.

transcript(File) ->
    put(transcript, File).
