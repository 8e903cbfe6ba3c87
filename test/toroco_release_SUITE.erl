%% The releases of SPEC §9, built once per run with the project's own
%% rebar.config: `prod' is unpacked from its tarball and run as a daemon in a
%% test world (cookie, ping, eval, top, stop); `board' is checked for what
%% the BeagleBone needs (no ERTS, no OTP libraries, the armhf pru_port and
%% lua_port, the systemd unit), booted on this machine's Erlang without its
%% hardware, and its pru_port and lua_port are run under qemu.
-module(toroco_release_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("kernel/include/file.hrl").
-compile([export_all, nowarn_export_all]).

-define(REL, "torobot").

suite() -> [{timetrap, {minutes, 5}}].

all() -> [{group, prod}, {group, board}].

groups() ->
    [{prod, [sequence], [daemon_starts_with_a_fresh_cookie, eval_inspects_the_running_torobot,
                         top_through_eval_and_top_command, wiring_command_loads_a_file,
                         metrics_with_the_allocators_off, openssl_stays_out_of_the_node,
                         stop_stops_the_node]},
     {board, [sequence], [board_tarball_is_minimal, board_release_boots_on_system_erlang,
                          board_port_runs_under_qemu, board_port_unit_tests_under_qemu,
                          board_lua_port_runs_under_qemu,
                          deploy_dry_run_shows_the_install]}].

init_per_suite(Config) ->
    case os:find_executable("rebar3") of
        false -> {skip, "rebar3 is not on PATH"};
        _ -> [{root, root()}, {build, build_dir()} | Config]
    end.

end_per_suite(_Config) ->
    ok.

init_per_group(prod, Config) ->
    Tar = build(Config, prod),
    Dir = unpack(Config, Tar, "prod"),
    Node = "torobot_ct" ++ os:getpid(),
    rename_node(Dir, Node),
    Home = filename:join(?config(priv_dir, Config), "prod_home"),
    ok = filelib:ensure_path(Home),
    World = filename:join(?config(priv_dir, Config), "long.world"),
    %% Long enough to inspect at leisure; nothing to touch, so it goes on.
    ok = file:write_file(World, "{arena, {6.0, 4.0}}.\n{robot, {3.0, 2.0, 0.0}}.\n"
                                "{duration_s, 600}.\n"),
    [{rel, Dir}, {node, Node}, {env, [{"HOME", Home}, {"TOROBOT_WORLD", World}]} | Config];
init_per_group(board, Config) ->
    case os:find_executable("arm-linux-gnueabihf-gcc") of
        false ->
            {skip, "no armhf cross compiler: apt-get install gcc-arm-linux-gnueabihf "
                   "libc6-dev-armhf-cross"};
        _ ->
            Tar = build(Config, board),
            [{rel, unpack(Config, Tar, "board")}, {tar, Tar} | Config]
    end.

end_per_group(_Group, Config) ->
    %% Whatever a failed case left running: the node of this run only.
    case ?config(rel, Config) of
        undefined -> ok;
        Dir -> _ = cmd(Config, Dir, "bin/" ++ ?REL ++ " stop", 60), ok
    end.

%%====================================================================
%% prod
%%====================================================================

daemon_starts_with_a_fresh_cookie() ->
    [{doc, "bin/torobot daemon creates the node's cookie on the first start from /dev/urandom, "
           "owner-readable, and the node answers ping; no cookie is in the release."}].
daemon_starts_with_a_fresh_cookie(Config) ->
    Dir = ?config(rel, Config),
    {0, Out} = cmd(Config, Dir, "bin/" ++ ?REL ++ " daemon", 120),
    ct:pal("~ts", [Out]),
    match(Out, "created the node cookie"),
    Cookie = filename:join(proplists:get_value("HOME", ?config(env, Config)), ".erlang.cookie"),
    {ok, C} = file:read_file(Cookie),
    {match, _} = re:run(C, "^[0-9a-f]{64}$"),
    {ok, #file_info{mode = Mode}} = file:read_file_info(Cookie),
    8#400 = Mode band 8#777,
    {0, "pong\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++ " ping", 30),
    {1, _} = cmd(Config, Dir, "grep -rlF " ++ binary_to_list(C) ++ " .", 30),
    {1, _} = cmd(Config, Dir, "grep -l -- -setcookie releases/*/vm.args", 30).

eval_inspects_the_running_torobot() ->
    [{doc, "bin/torobot eval 'toroco:inspect().' shows the Torobot's behaviors and devices, "
           "which the daemon's start put in its simulated world."}].
eval_inspects_the_running_torobot(Config) ->
    Dir = ?config(rel, Config),
    Inspect = fun() ->
                      {0, Out} = cmd(Config, Dir, "bin/" ++ ?REL ++ " eval 'toroco:inspect().'", 30),
                      term(Out)
              end,
    wait(fun() -> lists:member(red_follower, maps:get(behaviors, Inspect(), [])) end, 30000),
    #{behaviors := Bs, devices := Ds, layers := #{4 := [red_follower]}, removed_layers := []} =
        Inspect(),
    [] = [forward, avoid_left, avoid_right, trq_ignore, red_follower] -- Bs,
    [] = [ir, camera, motors] -- Ds,
    {0, "running\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++
                               " eval 'maps:get(status, toroco:inspect(forward)).'", 30).

top_through_eval_and_top_command() ->
    [{doc, "toroco:top() runs through eval (its table goes to the node's console, as eval's "
           "output does), through eval with nodetool and through bin/torobot top (printed "
           "where it is called)."}].
top_through_eval_and_top_command(Config) ->
    Dir = ?config(rel, Config),
    {0, "ok\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++ " eval 'toroco:top().'", 30),
    wait(fun() -> {0, Log} = cmd(Config, Dir, "cat log/erlang.log.*", 10),
                  nomatch =/= string:find(Log, "motors.setvel")
         end, 10000),
    {0, Nodetool} = cmd(Config, Dir, "USE_NODETOOL=1 bin/" ++ ?REL ++ " eval 'toroco:top().'", 30),
    match(Nodetool, "^toroco top  " ++ ?config(node, Config) ++ "@localhost"),
    {0, Top} = cmd(Config, Dir, "bin/" ++ ?REL ++ " top", 30),
    ct:pal("~ts", [Top]),
    ok = file:write_file(filename:join(?config(priv_dir, Config), "top.txt"), Top),
    match(Top, "^layers     4: red_follower  3: hold_left hold_right  2: trq_ignore  "
               "1: avoid_left avoid_right  0: button forward$"),
    match(Top, "^forward +behavior +0 +running "),
    match(Top, "^motors +device +0 +running "),
    match(Top, "^motors\\.setvel +[a-z_]+\\.motors "),
    nomatch = re:run(Top, "^ok$", [multiline]).

wiring_command_loads_a_file() ->
    [{doc, "bin/torobot wiring FILE (what the board's service runs after the start) loads a "
           "wiring file into the running node and exits 0; a refused file exits 1 with the "
           "reason."}].
wiring_command_loads_a_file(Config) ->
    Dir = ?config(rel, Config),
    Priv = ?config(priv_dir, Config),
    Good = filename:join(Priv, "extra.wiring"),
    ok = file:write_file(Good, "{behavior, ct_forward, torobot_forward, #{params => #{speed => 10}}}.\n"),
    {0, "ok\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++ " wiring " ++ Good, 60),
    {0, "running\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++
                               " eval 'maps:get(status, toroco:inspect(ct_forward)).'", 30),
    Bad = filename:join(Priv, "bad.wiring"),
    ok = file:write_file(Bad, "{inputs, ct_forward, #{nowhere => [{motors, setvel}]}}.\n"),
    {1, Out} = cmd(Config, Dir, "bin/" ++ ?REL ++ " wiring " ++ Bad, 60),
    match(Out, "^\\{error, .*nowhere"),
    {0, "ok\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++ " eval 'toroco:remove_behavior(ct_forward).'", 30).

metrics_with_the_allocators_off() ->
    [{doc, "In the prod release (+Mea min: erlang:memory/0 is notsup) the dashboard's "
           "/metrics still has toroco_vm_memory_bytes, its total the node's resident size."}].
metrics_with_the_allocators_off(Config) ->
    Dir = ?config(rel, Config),
    Eval = fun(Expr) -> cmd(Config, Dir, "bin/" ++ ?REL ++ " eval '" ++ Expr ++ "'", 30) end,
    {0, "'EXIT'\n"} = Eval("element(1, catch erlang:memory())."),
    {0, Total} = Eval("T = iolist_to_binary(toroco_live_metrics:text()), "
                      "{match, [N]} = re:run(T, \"^toroco_vm_memory_bytes.kind=.total.. ([0-9]+)$\", "
                      "[multiline, {capture, all_but_first, list}]), list_to_integer(N)."),
    true = list_to_integer(string:trim(Total)) > 10000000.

openssl_stays_out_of_the_node() ->
    [{doc, "After the daemon's start, ping, eval and top (erl_call reaching it under a name of "
           "its own making), with the dashboard up and its token drawn, the node has not "
           "loaded crypto and has not mapped OpenSSL's libcrypto (3.8 MiB)."}].
openssl_stays_out_of_the_node(Config) ->
    Dir = ?config(rel, Config),
    Eval = fun(Expr) -> cmd(Config, Dir, "bin/" ++ ?REL ++ " eval '" ++ Expr ++ "'", 30) end,
    {0, Url} = Eval("binary_to_list(toroco_live:url())."),
    match(Url, "token="),
    {0, "false\n"} = Eval("code:is_loaded(crypto)."),
    {0, Pid} = cmd(Config, Dir, "bin/" ++ ?REL ++ " pid", 30),
    {0, Maps} = cmd(Config, Dir, "cat /proc/" ++ string:trim(Pid) ++ "/maps", 10),
    nomatch = string:find(Maps, "libcrypto").

stop_stops_the_node() ->
    [{doc, "bin/torobot stop returns once the node is gone; ping then says so."}].
stop_stops_the_node(Config) ->
    Dir = ?config(rel, Config),
    {0, Pid} = cmd(Config, Dir, "bin/" ++ ?REL ++ " pid", 30),
    {0, _} = cmd(Config, Dir, "bin/" ++ ?REL ++ " stop", 60),
    {1, "Node is not running!\n"} = cmd(Config, Dir, "bin/" ++ ?REL ++ " ping", 30),
    {1, _} = cmd(Config, Dir, "kill -0 " ++ string:trim(Pid), 10).

%%====================================================================
%% board
%%====================================================================

board_tarball_is_minimal() ->
    [{doc, "The board tarball has no ERTS and no OTP libraries, only the project's apps; its "
           "pru_port is the armhf build, in the toroco_hw that the release runs; the board's "
           "vm.args, sys.config and the systemd unit are in it."}].
board_tarball_is_minimal(Config) ->
    Dir = ?config(rel, Config),
    {ok, Top} = file:list_dir(Dir),
    [] = [F || F <- Top, lists:prefix("erts-", F)],
    {ok, Libs} = file:list_dir(filename:join(Dir, "lib")),
    Apps = lists:sort([hd(string:split(L, "-")) || L <- Libs]),
    %% the behavior library comes along: a robot of wiring files needs it
    ["torobot", "toroco", "toroco_hw", "toroco_lib", "toroco_lua"] = Apps,
    [HwDir] = [L || L <- Libs, lists:prefix("toroco_hw-", L)],
    {ok, [{application, toroco_hw, Props}]} =
        file:consult(filename:join([Dir, "lib", HwDir, "ebin", "toroco_hw.app"])),
    HwDir = "toroco_hw-" ++ proplists:get_value(vsn, Props),
    {ok, <<16#7f, "ELF", 1, 1, _:10/binary, _Type:16/little, Machine:16/little, _/binary>>} =
        file:read_file(filename:join([Dir, "lib", HwDir, "priv", "pru_port"])),
    40 = Machine,                                    % EM_ARM, 32-bit little-endian
    [LuaPort] = filelib:wildcard(filename:join(Dir, "lib/toroco_lua-*/priv/lua_port")),
    {ok, <<16#7f, "ELF", 1, 1, _:10/binary, _:16/little, 40:16/little, _/binary>>} =
        file:read_file(LuaPort),
    {ok, Unit} = file:read_file(filename:join(Dir, "torobot.service")),
    match(Unit, "^ExecStart=/opt/torobot/bin/torobot foreground$"),
    [Vsn] = [V || V <- element(2, file:list_dir(filename:join(Dir, "releases"))),
                  filelib:is_dir(filename:join([Dir, "releases", V]))],
    {ok, VmArgs} = file:read_file(filename:join([Dir, "releases", Vsn, "vm.args"])),
    match(VmArgs, "^\\+sbwt none$"),
    {ok, [Sys]} = file:consult(filename:join([Dir, "releases", Vsn, "sys.config"])),
    Devices = proplists:get_value(devices, proplists:get_value(toroco_hw, Sys)),
    [ir, motors, push, camera] = [N || {N, _, _} <- Devices],
    [true = filelib:is_regular(filename:join([Dir, "lib", HwDir, "ebin", atom_to_list(M) ++ ".beam"]))
     || {_, M, _} <- Devices].

board_release_boots_on_system_erlang() ->
    [{doc, "The board release starts on the Erlang it finds on PATH (as on the board) with its "
           "own vm.args; the devices are left out, this machine has no PRU."}].
board_release_boots_on_system_erlang(Config) ->
    Dir = ?config(rel, Config),
    Node = "torobot_board_ct" ++ os:getpid(),
    rename_node(Dir, Node),
    Priv = ?config(priv_dir, Config),
    Sys = filename:join(Priv, "board_nodevices.config"),
    ok = file:write_file(Sys, "[{toroco_hw, [{devices, []}]}].\n"),
    Home = filename:join(Priv, "board_home"),
    ok = filelib:ensure_path(Home),
    Env = [{"HOME", Home}, {"RELX_CONFIG_PATH", Sys}],
    C1 = [{env, Env} | Config],
    {0, _} = cmd(C1, Dir, "sed -i 's|-env ERL_CRASH_DUMP .*|-env ERL_CRASH_DUMP " ++ Priv ++
                     "/erl_crash.dump|' releases/*/vm.args", 10),
    {0, _} = cmd(C1, Dir, "bin/" ++ ?REL ++ " daemon", 120),
    try
        {0, "pong\n"} = cmd(C1, Dir, "bin/" ++ ?REL ++ " ping", 30),
        %% Its OTP libraries are this machine's, as they will be the board's.
        {0, Kernel} = cmd(C1, Dir, "bin/" ++ ?REL ++ " eval 'code:lib_dir(kernel).'", 30),
        true = string:trim(Kernel, both, "\"\n") =:= code:lib_dir(kernel),
        {0, Out} = cmd(C1, Dir, "bin/" ++ ?REL ++ " eval 'toroco:inspect().'", 30),
        #{behaviors := [], devices := []} = term(Out)
    after
        {0, _} = cmd(C1, Dir, "bin/" ++ ?REL ++ " stop", 60)
    end.

board_port_runs_under_qemu() ->
    [{doc, "The tarball's armhf pru_port, run under qemu by toroco_pru_port on the sim backend, "
           "answers and turns ADC samples into threshold events."}].
board_port_runs_under_qemu(Config) ->
    case {os:find_executable("qemu-arm-static"), filelib:is_dir("/usr/arm-linux-gnueabihf")} of
        {false, _} -> {skip, "qemu-arm-static not found: apt-get install qemu-user-static"};
        {_, false} -> {skip, "no armhf libc: apt-get install libc6-dev-armhf-cross"};
        {Qemu, true} ->
            Dir = ?config(rel, Config),
            [Exe] = filelib:wildcard(filename:join(Dir, "lib/toroco_hw-*/priv/pru_port")),
            Wrapper = filename:join(?config(priv_dir, Config), "pru_port_qemu"),
            ok = file:write_file(Wrapper, ["#!/bin/sh\nexec ", Qemu,
                                           " -L /usr/arm-linux-gnueabihf ", Exe, " \"$@\"\n"]),
            ok = file:change_mode(Wrapper, 8#755),
            {ok, P} = toroco_pru_port:start_link(
                        #{executable => Wrapper, backend => sim,
                          sysfs_root => ?config(priv_dir, Config),
                          adc => [#{channel => 0, mode => analog_threshold,
                                    threshold_high => 2000, threshold_low => 1500}]}),
            pong = toroco_pru_port:ping(P),
            ok = toroco_pru_port:subscribe(P),
            [ok = toroco_pru_port:sim_adc(P, 0, V) || V <- [1000, 2500, 1800, 1400]],
            [0, 1, 0] = [receive {toroco_pru_port, {adc, 0, V, _}} -> V
                         after 5000 -> ct:fail(no_adc_event)
                         end || _ <- [1, 2, 3]],
            unlink(P),
            ok = toroco_pru_port:stop(P)
    end.

board_lua_port_runs_under_qemu() ->
    [{doc, "The tarball's armhf lua_port, run under qemu as toroco_lua's program, runs the "
           "thesis' signaller written for the original: a press reaches the actuator."}].
board_lua_port_runs_under_qemu(Config) ->
    case {os:find_executable("qemu-arm-static"), filelib:is_dir("/usr/arm-linux-gnueabihf")} of
        {false, _} -> {skip, "qemu-arm-static not found: apt-get install qemu-user-static"};
        {_, false} -> {skip, "no armhf libc: apt-get install libc6-dev-armhf-cross"};
        {Qemu, true} ->
            Dir = ?config(rel, Config),
            [Exe] = filelib:wildcard(filename:join(Dir, "lib/toroco_lua-*/priv/lua_port")),
            [Main] = filelib:wildcard(filename:join(
                                        Dir, "lib/toroco_lua-*/priv/examples/sensor_signalling/main.lua")),
            Wrapper = filename:join(?config(priv_dir, Config), "lua_port_qemu"),
            ok = file:write_file(Wrapper, ["#!/bin/sh\nexec ", Qemu,
                                           " -L /usr/arm-linux-gnueabihf ", Exe, " \"$@\"\n"]),
            ok = file:change_mode(Wrapper, 8#755),
            _ = application:load(toroco_lua),
            ok = application:set_env(toroco_lua, executable, Wrapper),
            try
                {ok, _} = application:ensure_all_started(toroco_lua),
                {pong, 1} = toroco_lua_port:ping(),
                ok = toroco:add_device(mouse, toroco_fake_sensor, #{outputs => [left, right]}),
                ok = toroco:add_device(actuator, toroco_fake_actuator, #{inputs => [signal]}),
                {ok, #{behaviors := [signaller]}} = toroco_lua:load_main(Main, #{}),
                ok = toroco:inject({mouse, left}, pressed),
                ok = toroco_fake_actuator:await(
                       actuator, fun(H) -> [V || {signal, V, _} <- H] =:= [{<<"left">>, <<"pressed">>}] end,
                       20000)
            after
                %% the behaviors first, so none sees its program go
                _ = application:stop(toroco),
                _ = application:stop(toroco_lua),
                application:unset_env(toroco_lua, executable)
            end
    end.

board_port_unit_tests_under_qemu() ->
    [{doc, "pru_port's C unit tests, built for armhf, pass under qemu (make test-armhf)."}].
board_port_unit_tests_under_qemu(Config) ->
    {Status, Out} = cmd(Config, ?config(root, Config), "make -C c_src/pru_port test-armhf", 600),
    ct:pal("~ts", [Out]),
    case re:run(Out, "^skipped armhf: (.*)$", [multiline, {capture, all_but_first, list}]) of
        {match, [Why]} ->
            {skip, Why};
        nomatch ->
            0 = Status,
            match(Out, "^[0-9]+ passed, 0 failed$")
    end.

deploy_dry_run_shows_the_install() ->
    [{doc, "scripts/deploy --dry-run prints what it would run on the board, and the install "
           "script it would send is valid shell."}].
deploy_dry_run_shows_the_install(Config) ->
    Root = ?config(root, Config),
    {0, _} = cmd(Config, Root, "bash -n scripts/deploy", 10),
    {0, Out} = cmd(Config, Root, "scripts/deploy --dry-run board.example " ++ ?config(tar, Config), 30),
    ct:pal("~ts", [Out]),
    match(Out, "^scp .*torobot-[0-9.]+\\.tar\\.gz board\\.example:"),
    match(Out, "^ssh board\\.example sudo sh -s"),
    match(Out, "/opt/torobot"),
    match(Out, "systemctl enable torobot"),
    match(Out, "od -An -N32 -tx1 /dev/urandom"),
    Script = filename:join(?config(priv_dir, Config), "install.sh"),
    {0, _} = cmd(Config, Root, "scripts/deploy --print-install > " ++ Script, 10),
    {0, _} = cmd(Config, Root, "sh -n " ++ Script, 10).

%%====================================================================
%% Helpers
%%====================================================================

%% rebar3 runs this suite from a copy in the build dir; the project is
%% where the runtime's sources are (its build dir links to them).
root() ->
    Src = filename:join(code:lib_dir(toroco), "src"),
    Real = case file:read_link_all(Src) of
               {ok, Link} -> normalize(filename:absname(Link, filename:dirname(Src)));
               {error, _} -> Src
           end,
    Root = filename:dirname(filename:dirname(filename:dirname(Real))),
    true = filelib:is_regular(filename:join(Root, "rebar.config")),
    Root.

normalize(Path) ->
    filename:join(lists:reverse(lists:foldl(fun("..", [_ | Acc]) -> Acc;
                                               (".", Acc) -> Acc;
                                               (C, Acc) -> [C | Acc]
                                            end, [], filename:split(Path)))).

%% Nested builds go beside the outer one's, so that private build dirs stay
%% private and a second run is incremental.
build_dir() ->
    Base = case os:getenv("REBAR_BASE_DIR") of
               false -> filename:join(root(), "_build");
               B -> B
           end,
    filename:join(Base, "release_ct").

build(Config, Profile) ->
    P = atom_to_list(Profile),
    {Status, Out} = cmd([{env, [{"REBAR_BASE_DIR", ?config(build, Config)}]} | Config],
                        ?config(root, Config), "rebar3 as " ++ P ++ " tar", 600),
    case Status of
        0 -> ok;
        _ -> ct:fail({rebar3, P, Status, Out})
    end,
    [Tar] = filelib:wildcard(filename:join([?config(build, Config), P, "rel", ?REL,
                                             ?REL ++ "-*.tar.gz"])),
    Tar.

unpack(Config, Tar, Name) ->
    Dir = filename:join(?config(priv_dir, Config), Name),
    ok = erl_tar:extract(Tar, [compressed, {cwd, Dir}]),
    Dir.

%% A node name of this run's own, so that runs and a robot on this machine
%% do not meet.
rename_node(Dir, Node) ->
    [VmArgs] = filelib:wildcard(filename:join(Dir, "releases/*/vm.args")),
    {ok, Bin} = file:read_file(VmArgs),
    ok = file:write_file(VmArgs, re:replace(Bin, "^-sname .*$", "-sname " ++ Node ++ "@localhost",
                                            [multiline])).

%% Runs a shell command in Dir with the group's environment; returns its
%% exit status and output (stderr included).
cmd(Config, Dir, Cmd, TimeoutS) ->
    Env = [{V, false} || V <- ["ERL_LIBS", "ERL_FLAGS", "ERL_AFLAGS", "ERL_ZFLAGS",
                               "RELX_COOKIE"]]
        ++ proplists:get_value(env, Config, []),
    Port = open_port({spawn_executable, "/bin/sh"},
                     [{args, ["-c", Cmd]}, {cd, Dir}, {env, Env}, exit_status,
                      stderr_to_stdout, binary, hide]),
    collect(Port, [], erlang:monotonic_time(millisecond) + TimeoutS * 1000, Cmd).

collect(Port, Acc, Deadline, Cmd) ->
    receive
        {Port, {data, D}} -> collect(Port, [Acc, D], Deadline, Cmd);
        {Port, {exit_status, S}} -> {S, unicode:characters_to_list(iolist_to_binary(Acc))}
    after max(0, Deadline - erlang:monotonic_time(millisecond)) ->
            catch port_close(Port),
            ct:fail({timeout, Cmd, iolist_to_binary(Acc)})
    end.

term(Out) ->
    {ok, Tokens, _} = erl_scan:string(string:trim(Out) ++ "."),
    {ok, Term} = erl_parse:parse_term(Tokens),
    Term.

match(Text, Re) ->
    case re:run(Text, Re, [multiline, {capture, none}, unicode]) of
        match -> ok;
        nomatch -> ct:fail({no_match, Re, Text})
    end.

%% The release's answers come from another OS process: a check that raises
%% (the node not up yet) is one that does not hold yet; after `Ms' the check
%% runs once more uncaught, so the case fails with what is wrong.
wait(Fun, Ms) ->
    case toroco_test_lib:poll(fun() -> catch Fun() end, Ms, 250) of
        ok -> ok;
        timeout -> true = Fun()
    end.
