%% The browser of the dashboard's tests and screenshots: the system's
%% chromium, headless, driven by puppeteer-core through
%% `apps/toroco_live/web/test/driver.js' (one JSON command a line).
-module(toroco_live_browser).

-export([available/0, start/0, start/1, cmd/2, cmd/3, stop/1, root/0]).

%% The repository's root, from where this module's source is.
root() ->
    toroco_test_lib:root().

web() -> filename:join([root(), "apps", "toroco_live", "web"]).

%% ok, or why the browser cannot run here.
available() ->
    Chromium = os:getenv("TOROCO_CHROMIUM", "/usr/bin/chromium"),
    Puppeteer = filename:join([web(), "node_modules", "puppeteer-core", "package.json"]),
    case {filelib:is_regular(Chromium), os:find_executable("node"), filelib:is_regular(Puppeteer)} of
        {false, _, _} -> {no, "no chromium at " ++ Chromium};
        {_, false, _} -> {no, "no node"};
        {_, _, false} -> {no, "puppeteer-core not installed (apps/toroco_live/web/build)"};
        _ -> ok
    end.

%% A process owning the driver (Common Test runs init_per_suite and each
%% case in processes of their own, so the driver outlives them all).
start() ->
    start([]).

%% With more chromium switches (`Args', strings).
start(Args) ->
    Caller = self(),
    Switches = binary_to_list(jiffy:encode([list_to_binary(A) || A <- Args])),
    Pid = spawn(fun() ->
                        Port = open_port({spawn_executable, os:find_executable("node")},
                                         [{args, [filename:join([web(), "test", "driver.js"])]},
                                          {cd, web()}, {line, 1 bsl 20}, binary, exit_status,
                                          use_stdio, {env, [{"PUPPETEER_SKIP_DOWNLOAD", "1"},
                                                  {"TOROCO_CHROMIUM_ARGS", Switches}]}]),
                        Caller ! {self(), started},
                        owner(Port)
                end),
    receive {Pid, started} -> Pid end.

owner(Port) ->
    receive
        {cmd, From, Cmd, Timeout} ->
            true = port_command(Port, [jiffy:encode(Cmd), "\n"]),
            Answer = receive
                         {Port, {data, {eol, Line}}} ->
                             case jiffy:decode(Line, [return_maps]) of
                                 #{<<"ok">> := true} = A -> {ok, maps:get(<<"value">>, A, null)};
                                 #{<<"error">> := Why} -> {error, Why}
                             end;
                         {Port, {exit_status, S}} -> {error, {driver_exited, S}}
                     after Timeout -> {error, driver_timeout}
                     end,
            From ! {self(), Answer},
            owner(Port);
        stop ->
            catch port_close(Port)
    end.

cmd(Pid, Cmd) -> cmd(Pid, Cmd, 30000).

%% {ok, Value} or {error, Why}.
cmd(Pid, Cmd, Timeout) ->
    Pid ! {cmd, self(), Cmd, Timeout},
    receive {Pid, Answer} -> Answer
    after Timeout + 1000 -> {error, driver_timeout}
    end.

stop(Pid) ->
    _ = cmd(Pid, #{quit => true}, 10000),
    Pid ! stop,
    ok.
