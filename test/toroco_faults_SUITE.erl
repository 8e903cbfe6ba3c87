%% Fault injection (issue: reliability): a layered network under 1 kHz sensor
%% input takes random faults — a behavior killed, a router killed, a device
%% killed, a behavior suspended and resumed, a behavior removed and added back,
%% the pru_port program killed with SIGKILL — and after each one the robot must
%% be whole again quickly. A second case puts a Lua behavior on top of the
%% same network (SPEC §16) and gives it the Lua faults: a Lua error, an
%% endless loop, an endless allocation, its process killed, and the lua_port
%% program killed with SIGKILL (it starts again in the new program):
%%
%%   * every router answers `inspect' within 100 ms;
%%   * within 50 ms (250 in the Lua case: bound/0) the motors' last command
%%     is what SPEC §4 predicts for the
%%     live sources (the highest wired source with a latch);
%%   * no live emitter has lost its latch;
%%   * no process of the network has more than ?MAILBOX_BOUND messages queued
%%     (1 kHz input for a 50 ms recovery is ~50 events; the bound leaves room
%%     for control messages and scheduling jitter on 2 cores, and is far below
%%     what an unbounded backlog would reach);
%%   * while the port program is down and once it is back, the servos are at
%%     neutral.
%%
%% A check that does not hold is a violation: it is counted and logged with
%% the fault that caused it, the run goes on with the next fault (up to
%% ?MAX_VIOLATIONS, past which the robot is too broken for more faults to say
%% anything), and the case fails if any was counted.
%%
%% The run is seeded; the seed is printed on every run (in the case's log and
%% on the console, so CI output has it) and can be given with env
%% TOROCO_FAULT_SEED. The fault count is TOROCO_FAULTS (default 1000; CI runs
%% the default too, it takes well under a minute).
-module(toroco_faults_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-define(MAILBOX_BOUND, 500).
-define(MAX_VIOLATIONS, 20).
-define(PRIORITY, [top, mid2, mid1, forward, noisy]).
-define(LATCH(B), {latched, B}).

suite() -> [{timetrap, {minutes, 10}}].

all() -> [random_faults_leave_the_robot_whole, lua_faults_leave_the_robot_whole].

%% Faults come faster here than any restart intensity meant for a robot
%% allows (that taking-out is tested in toroco_lifecycle_SUITE), so the
%% intensities are raised for this run.
init_per_testcase(lua_faults_leave_the_robot_whole, Config) ->
    Config1 = init_common(Config),
    {ok, _} = application:ensure_all_started(toroco_lua),
    put(lua, true),                           % the priority list has it on top
    Config1;
init_per_testcase(_, Config) ->
    init_common(Config).

init_common(Config) ->
    _ = application:load(toroco),
    [application:set_env(toroco, K, {100000, 1})
     || K <- [layer_restart_intensity, device_restart_intensity, router_restart_intensity]],
    {ok, _} = application:ensure_all_started(toroco_hw),
    logger:set_primary_config(level, error),
    Config.


end_per_testcase(_, _Config) ->
    logger:set_primary_config(level, warning),
    ok = toroco_test_lib:stop(),
    _ = application:stop(toroco_lua),
    [application:unset_env(toroco, K)
     || K <- [layer_restart_intensity, device_restart_intensity, router_restart_intensity]],
    ok.

random_faults_leave_the_robot_whole() ->
    [{doc, "1,000 seeded random faults under 1 kHz input: the network recovers within bounds every time."}].
random_faults_leave_the_robot_whole(Config) ->
    Seed = case os:getenv("TOROCO_FAULT_SEED") of
               false -> erlang:phash2(erlang:monotonic_time());
               S -> list_to_integer(S)
           end,
    Faults = list_to_integer(os:getenv("TOROCO_FAULTS", "1000")),
    say("fault injection: seed ~p, ~p faults (TOROCO_FAULT_SEED=~p to replay)",
        [Seed, Faults, Seed]),
    _ = rand:seed(exsss, Seed),
    build(),
    Port = start_port(?config(priv_dir, Config)),
    Driver = drive(),
    {Stats, Violations} = faults(1, Faults, Port, [], []),
    ok = toroco_test_lib:stop_paced(Driver),
    report(Seed, Stats, Violations).

lua_faults_leave_the_robot_whole() ->
    [{doc, "200 seeded random Lua faults (error, endless loop, endless allocation, process "
      "killed, lua_port killed) to a Lua behavior on top of the network, under 1 kHz input: "
      "the network recovers within the same bounds every time."}].
lua_faults_leave_the_robot_whole(Config) ->
    Seed = case os:getenv("TOROCO_FAULT_SEED") of
               false -> erlang:phash2(erlang:monotonic_time());
               S -> list_to_integer(S)
           end,
    Faults = list_to_integer(os:getenv("TOROCO_LUA_FAULTS", "200")),
    say("Lua fault injection: seed ~p, ~p faults (TOROCO_FAULT_SEED=~p to replay)",
        [Seed, Faults, Seed]),
    _ = rand:seed(exsss, Seed),
    build(),
    ok = toroco:add_device(luak, toroco_fake_sensor, #{outputs => [kind]}),
    ok = toroco_lua:add_behavior(lua, #{file => filename:join(?config(data_dir, Config),
                                                              "latched.lua"),
                                        layer => 4}),
    ok = toroco:set_inputs(lua, #{kind => [{luak, kind}]}),
    wire_motors(),
    [] = check(0),
    Driver = drive(),
    {Stats, Violations} = faults(1, Faults, lua, [], []),
    ok = toroco_test_lib:stop_paced(Driver),
    report(Seed, Stats, Violations).

report(Seed, Stats, Violations) ->
    Recovery = [R || {_, R} <- Stats],
    Kinds = lists:foldl(fun({K, _}, Acc) -> maps:update_with(K, fun(N) -> N + 1 end, 1, Acc) end,
                        #{}, Stats),
    Summary = io_lib:format("seed ~p: ~p faults, max recovery ~p ms, mean ~.1f ms, ~p violations",
                            [Seed, length(Stats), lists:max(Recovery),
                             lists:sum(Recovery) / length(Recovery), length(Violations)]),
    say("~ts~nfaults by kind ~p", [Summary, Kinds]),
    case Violations of
        [] -> {comment, Summary};
        _ -> ct:fail({violations, #{seed => Seed, count => length(Violations),
                                    faults_run => length(Stats),
                                    first => lists:sublist(lists:reverse(Violations), 5)}})
    end.

%% In the case's log and on the console. rebar3 ct shows a passing case's
%% console output only with --verbose, so the line also goes to standard
%% error, where CI's log has it on every run.
say(Format, Args) ->
    ct:log(Format, Args),
    ct:pal(Format, Args),
    io:format(standard_error, "toroco_faults_SUITE: " ++ Format ++ "~n", Args).

%% Runs faults From..To, or fewer once ?MAX_VIOLATIONS are counted.
faults(I, To, _Port, Stats, Vs) when I > To; length(Vs) >= ?MAX_VIOLATIONS ->
    {lists:reverse(Stats), Vs};
faults(I, To, Port, Stats, Vs) ->
    {Kind, Ms, New} = fault(I, Port),
    [say("violation after fault ~p (~p): ~p", [I, Kind, V]) || V <- New],
    faults(I + 1, To, Port, [{Kind, Ms} | Stats], lists:reverse(New) ++ Vs).

%%--------------------------------------------------------------------
%% The network: four latched layers and a momentary noise path over one motor input
%%--------------------------------------------------------------------

build() ->
    ok = toroco:add_device(ir, toroco_fake_sensor, #{outputs => [v]}),
    ok = toroco:add_device(motors, toroco_fake_actuator, #{inputs => [in], max_history => 50}),
    ok = toroco:add_behavior(noisy, tb_relay, #{layer => 0}),
    [add(B) || B <- [forward, mid1, mid2, top]],
    ok = toroco:set_inputs(noisy, #{in => [{ir, v}]}),
    wire_motors(),
    [] = check(0).

layer(forward) -> 0; layer(mid1) -> 1; layer(mid2) -> 2; layer(top) -> 3; layer(noisy) -> 0.

add(B) ->
    ok = toroco:add_behavior(B, tb_relay, #{layer => layer(B), params => #{latch => ?LATCH(B)}}).

%% How soon (ms) the motors and the latches must be right again: 50, as the
%% issue asks; 250 in the Lua case, whose restarts wait for the lua_port
%% program to build a new Lua state (the prelude and the file compiled
%% anew), an OS process that shares the two cores with the VM and whatever
%% else runs.
bound() ->
    case get(lua) of
        true -> 250;
        _ -> 50
    end.

%% Highest first; the Lua case has its Lua behavior on top.
priority() ->
    case get(lua) of
        true -> [lua | ?PRIORITY];
        _ -> ?PRIORITY
    end.

%% What each latched behavior latches at start: a Lua string is a binary.
latch(lua) -> {<<"latched">>, <<"lua">>};
latch(B) -> ?LATCH(B).

wire_motors() ->
    Live = [B || B <- priority(), lists:member(B, maps:get(behaviors, toroco:inspect()))],
    ok = toroco:set_inputs(motors, #{in => [{B, out} || B <- Live]}).

%% 1 kHz momentary events into the noise path (load, not assertions).
drive() ->
    toroco_test_lib:paced(fun(I) -> catch toroco:inject({ir, v}, I) end, infinity, 1).

%%--------------------------------------------------------------------
%% Faults
%%--------------------------------------------------------------------

fault(I, lua) ->
    Kind = pick([lua_error, lua_loop, lua_memory, kill_lua_behavior, kill_lua_port]),
    T0 = erlang:monotonic_time(millisecond),
    Vs = lua_fault(Kind) ++ check(I),
    {Kind, erlang:monotonic_time(millisecond) - T0, Vs};
fault(I, Port) ->
    Kind = lists:nth(rand:uniform(6), [kill_behavior, kill_router, kill_device, suspend_resume,
                                       remove_readd, kill_port]),
    T0 = erlang:monotonic_time(millisecond),
    Vs = inject_fault(Kind, Port) ++ check(I),
    {Kind, erlang:monotonic_time(millisecond) - T0, Vs}.

%% The fault, and the violations seen while it is under way.
inject_fault(kill_behavior, _) ->
    kill(toroco_names:process(pick(priority())));
inject_fault(kill_router, _) ->
    kill(pick([toroco_names:router(motors, in), toroco_names:router(noisy, in)]));
inject_fault(kill_device, _) ->
    kill(toroco_names:process(pick([ir, motors])));
inject_fault(suspend_resume, _) ->
    B = pick([forward, mid1, mid2, top]),
    ok = toroco:suspend_behavior(B),
    ok = toroco:resume_behavior(B),
    [];
inject_fault(remove_readd, _) ->
    B = pick([mid1, mid2, top]),
    ok = toroco:remove_behavior(B),
    Vs = check(removed),
    add(B),
    wire_motors(),
    Vs;
inject_fault(kill_port, Port) ->
    kill_port(Port).

pick(L) -> lists:nth(rand:uniform(length(L)), L).

%% A Lua fault; it is under way until the Lua behavior has stopped (an error,
%% a limit, a kill), or until a new program runs with the behavior's state in
%% it (the program killed: the behavior stays and starts again in it).
lua_fault(kill_lua_port) ->
    OsPid = toroco_lua_port:os_pid(),
    _ = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    until(fun() -> toroco_lua_port:os_pid() =/= OsPid andalso
                       element(1, toroco_lua:waits(lua)) =:= ok end,
          1000 + slack(), {lua_port_restarted, OsPid});
lua_fault(Kind) ->
    Pid = whereis(toroco_names:process(lua)),
    Ref = erlang:monitor(process, Pid),
    case Kind of
        kill_lua_behavior -> exit(Pid, kill);
        lua_error -> ok = toroco:inject({luak, kind}, <<"error">>);
        lua_loop -> ok = toroco:inject({luak, kind}, <<"loop">>);
        lua_memory -> ok = toroco:inject({luak, kind}, <<"memory">>)
    end,
    receive {'DOWN', Ref, process, Pid, _} -> []
    after 5000 -> [{lua_not_stopped, Kind}]
    end.

kill(Reg) ->
    case whereis(Reg) of
        undefined -> [];
        Pid -> exit(Pid, kill), []
    end.

%%--------------------------------------------------------------------
%% Checks
%%--------------------------------------------------------------------

%% Expected: the highest wired source's latch (all latched layers latch at init).
expected() ->
    #{inputs := #{in := #{sources := Srcs}}} = toroco:inspect(motors),
    case [B || {B, out} <- Srcs, B =/= noisy] of
        [Top | _] -> latch(Top);
        [] -> none
    end.

%% The violations of the robot's bounds after fault Label: [] when whole.
check(Label) ->
    Routers = routers_answer(Label),
    Expected = expected(),
    Routers
        ++ until(fun() -> last_command() =:= Expected end, bound() + slack(), {motors, Label, Expected})
        ++ until(fun() -> latches_intact() end, bound() + slack(), {latches, Label})
        ++ mailboxes_bounded(Label).

%% Every router answers `inspect' within 100 ms of the fault (one killed by
%% the fault is restarted by its supervisor within that time).
routers_answer(Label) ->
    lists:append([until(fun() -> is_map(catch gen_statem:call(R, info, 100)) end, 100 + slack(),
                        {router_stuck, R, Label})
                  || R <- [toroco_names:router(motors, in), toroco_names:router(noisy, in)]]).

last_command() ->
    case catch toroco_fake_actuator:history(motors) of
        [_ | _] = H -> element(2, lists:last(H));
        _ -> undefined
    end.

latches_intact() ->
    Live = maps:get(behaviors, toroco:inspect()),
    lists:all(fun(B) ->
                      Latch = {value, latch(B)},
                      case toroco:inspect(B) of
                          #{status := running, outputs := #{out := #{latch := Latch}}} -> true;
                          #{status := suspended, outputs := #{out := #{latch := Latch}}} -> true;
                          _ -> false
                      end
              end, [B || B <- Live, B =/= noisy]).

mailboxes_bounded(Label) ->
    Names = [toroco_names:process(N) || N <- [ir, motors | priority()]]
        ++ [toroco_names:router(motors, in), toroco_names:router(noisy, in)],
    Max = lists:max([case whereis(N) of
                         undefined -> 0;
                         P -> case erlang:process_info(P, message_queue_len) of
                                  {_, Q} -> Q;
                                  undefined -> 0
                              end
                     end || N <- Names]),
    [{mailbox_over_bound, Max, Label} || Max > ?MAILBOX_BOUND].

%% Polls every millisecond up to Timeout ms: [] once Fun is true, else the
%% violation [{not_recovered_in_time, What}].
until(Fun, Timeout, What) ->
    case toroco_test_lib:poll(fun() -> catch Fun() end, Timeout, 1) of
        ok -> [];
        timeout -> [{not_recovered_in_time, What}]
    end.

%% Restarting an OS process or a supervisor child is not instantaneous on a
%% loaded 2-core machine; CI may give extra slack through TOROCO_FAULT_SLACK_MS
%% (default 0: the bounds are exactly those of the issue).
slack() -> list_to_integer(os:getenv("TOROCO_FAULT_SLACK_MS", "0")).

%%--------------------------------------------------------------------
%% The port program: servos against a fake sysfs tree
%%--------------------------------------------------------------------

start_port(Dir) ->
    Root = filename:join(Dir, "sysfs"),
    Chan = filename:join([Root, "class", "pwm", "pwmchip0", "pwm0"]),
    ok = filelib:ensure_path(Chan),
    [ok = file:write_file(filename:join(Chan, F), "0\n") || F <- ["period", "duty_cycle", "enable"]],
    ok = file:write_file(filename:join([Root, "class", "pwm", "pwmchip0", "export"]), ""),
    {ok, Pid} = toroco_pru_port:start_link(#{backend => sim, sysfs_root => Root, enabled => true,
                                             max_restarts => {100000, 1},
                                             servos => #{left => #{pwmchip => 0, channel => 0,
                                                                   period_ns => 20000000,
                                                                   neutral_ns => 1500000,
                                                                   span_ns => 500000}}}),
    unlink(Pid),
    #{pid => Pid, duty => filename:join(Chan, "duty_cycle")}.

kill_port(#{pid := Owner, duty := Duty}) ->
    ok = toroco_pru_port:set_servos(Owner, #{left => 80}),
    Driven = [{servo_not_driven, D} || D <- [duty(Duty)], D =/= 1900000],
    OsPid = toroco_pru_port:os_pid(Owner),
    os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    %% While the program is down nothing may drive the servo away from neutral
    %% (the owner does not replay velocities); once it is back, neutral.
    Driven
        ++ until(fun() -> toroco_pru_port:os_pid(Owner) =/= OsPid andalso
                              is_integer(toroco_pru_port:os_pid(Owner)) end,
                 500 + slack(), port_restarted)
        ++ until(fun() -> duty(Duty) =:= 1500000 end, 50 + slack(), servo_neutral).

duty(File) ->
    {ok, B} = file:read_file(File),
    binary_to_integer(string:trim(B)).
