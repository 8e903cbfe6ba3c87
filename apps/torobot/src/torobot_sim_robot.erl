%% @doc One simulated Torobot's side of a run: the runtime, the devices the
%% wiring expects and the wiring itself, on the node the robot runs on.
%%
%% `torobot_sim' (the world) starts one per robot: in its own node for the
%% one-robot form of a world, else on a node of its own (an OTP `peer' over
%% its standard I/O, so robots never form a cluster). The robot's devices
%% are those of the board, on their simulated backends (SPEC §8):
%% <ul>
%% <li>`ir' a `toroco_pru_sensors' on the `pru_port' sim backend, with the
%%     world's thresholds; raw readings come in with {@link sense/2}, so near
%%     and far come out of the C program's own hysteresis;</li>
%% <li>`motors' a `toroco_servo_motors' on the sim backend; what the servos
%%     really apply reaches this process through `wheels'
%%     (`torobot_sim_wheels', wired to `{motors, applied}');</li>
%% <li>`camera' a `toroco_udp_camera' on a free loopback port, to which the
%%     world sends the detector's datagrams;</li>
%% <li>`push' a `toroco_gpio_button' on the sim backend, pressed once by
%%     {@link go/1} as one would on the board;</li>
%% <li>the library's sensors (`sensors' option: `torobot_sim_sensor'
%%     devices and their outputs, from `torobot_sensors:devices/0'), fed
%%     with {@link sense/3}.</li>
%% </ul>
%% The world reads {@link wheels/1} at each tick: the velocities applied
%% now and the behavior that wins the motors' `setvel' input, read with
%% `toroco:inspect(motors)' (some 65 us, one call per tick).
%%
%% Speed: the world's time runs `speed' times faster than real time; the
%% runtime's clock (`toroco_clock': holds, gate timers, behaviors' and
%% devices' timeouts) is set to the same speed for the run and set back
%% after it. What belongs to real
%% hardware stays in real time: the servos' watchdog, and the button's
%% debounce, so the press lasts 60 real ms and {@link go/1} answers once
%% the motors are on: the world starts when the robot is switched on.
%%
%% Lockstep (`time => lockstep', SPEC §14): the node's clock is the world's
%% (`toroco_clock:lockstep/1'). The world calls {@link step/5} each tick
%% with the simulated time and the readings; they reach the devices as
%% steps (`toroco_pru_sensors:stimulus/3' runs the IR hysteresis in the VM,
%% `toroco_udp_camera:stimulus/2' takes the detector's datagrams without
%% UDP, `torobot_sim_sensor:stimulus/2'), in a fixed order, and the answer
%% comes once the robot's event path is quiescent: the wheels then, the
%% winner and the trace lines. {@link go/1} hands the button's press and
%% release in as steps at time 0. The servos' watchdog is off: it guards
%% real hardware against a stalled VM, and the world is the clock.
%%
%% Messages, all within this module: the world calls `wheels' (answer
%% `{Wheels, Winner}'), `go' (answer `ok') and, in lockstep, `{step, T,
%% Ir, Readings, Datagrams}' (answer `{Wheels, Winner, TraceLines}'), and
%% casts `{sense, Ir}'; `torobot_sim_wheels' sends `{torobot_sim_wheels,
%% Wheels}'.
-module(torobot_sim_robot).
-behaviour(gen_server).

-export([start/1, stop/0, go/1, wheels/1, sense/3, step/5, fault/3]).
-export([start_peer/1, stop_peer/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([opts/0, handle/0]).

-type opts() :: #{wiring := file:name_all(),
                  thresholds := #{threshold_high := 0..1023, threshold_low := 0..1023},
                  speed := number(),
                  time => realtime | lockstep,
                  trace => boolean(),
                  sensors => [{atom(), [atom()]}],
                  lua => file:name_all()}.
%% Where a robot runs: this node, or a peer node.
-type handle() :: local | {peer, pid()}.

-define(DEVICES, [ir, motors, camera, push]).
%% The press is a person's, in real time: the button's debounce (in the
%% C program) is a real-hardware filter and stays real at any speed.
-define(PRESS_MS, 60).
-define(ENABLE_POLL_MS, 5).
-define(ENABLE_WAIT_MS, 3000).
-define(PEER_BOOT_MS, 30000).
-define(CALL_MS, 10000).

-record(robot, {wheels = {0, 0} :: {number(), number()},
                started :: [atom()],
                behaviors :: [{behavior | device, atom()}],
                sensors :: [atom()],
                clock :: {previous, number()} | lockstep,
                %% the wiring's behaviors on other nodes (SPEC §13)
                remote = [] :: [atom()],
                going :: {gen_server:from(), integer()} | undefined}).

%%====================================================================
%% API: the robot's node
%%====================================================================

%% @doc Starts the applications where they are not running, then the
%% robot: its devices, its wiring, and this module's process (registered
%% as `torobot_sim_robot'). Returns the camera's UDP port.
-spec start(opts()) -> {ok, inet:port_number()} | {error, term()}.
start(#{wiring := Wiring} = Opts) ->
    case toroco:read_wiring(Wiring) of
        {ok, Added} ->
            case application:ensure_all_started(torobot) of
                {ok, Started} ->
                    Init = Opts#{started => Started, added => Added},
                    case gen_server:start({local, ?MODULE}, ?MODULE, Init, []) of
                        {ok, _} -> {ok, camera_port()};
                        {error, Reason} -> {error, Reason}
                    end;
                {error, Reason} ->
                    {error, {applications, Reason}}
            end;
        {error, Reason} ->
            {error, {wiring, Wiring, Reason}}
    end.

%% @doc Stops the robot: the applications if {@link start/1} started them,
%% else the behaviors and devices it added; the runtime's clock goes back to
%% its speed before the run.
-spec stop() -> ok.
stop() ->
    try gen_server:stop(?MODULE)
    catch exit:noproc -> ok
    end.

%%====================================================================
%% API: the world's side
%%====================================================================

%% @doc Presses the robot's button (the `button' behavior enables the
%% motors) for 60 ms and answers once the motors are enabled, so the world
%% starts when the robot is switched on, whatever the speed.
-spec go(handle()) -> ok | {error, term()}.
go(Robot) ->
    call(Robot, go).

%% @doc The velocities the servos apply now, and the behavior winning the
%% motors (`none' when no source holds).
-spec wheels(handle()) -> {{number(), number()}, atom() | none}.
wheels(Robot) ->
    call(Robot, wheels).

%% @doc Hands the robot's IR sensors new raw readings and the library's
%% sensor devices (`torobot_sim_sensor') new readings; only what changed
%% need be given, and nothing is sent when nothing did.
-spec sense(handle(), #{left | right => 0..1023}, #{atom() => #{atom() => term()}}) -> ok.
sense(_Robot, Ir, Readings) when map_size(Ir) =:= 0, map_size(Readings) =:= 0 ->
    ok;
sense(local, Ir, Readings) ->
    gen_server:cast(?MODULE, {sense, Ir, Readings});
sense({peer, Peer}, Ir, Readings) ->
    peer:cast(Peer, gen_server, cast, [?MODULE, {sense, Ir, Readings}]).

%% @doc Lockstep: moves the robot's clock to `T' (world ms), hands it the
%% readings that changed and the camera's datagrams, and answers once its
%% event path is quiescent with the velocities the servos apply, the
%% behavior winning the motors and the trace lines of the step.
-spec step(handle(), integer(), #{left | right => 0..1023}, #{atom() => #{atom() => term()}},
           [binary()]) -> {{number(), number()}, atom() | none, [iodata()]}.
step(Robot, T, Ir, Readings, Datagrams) ->
    call(Robot, {step, T, Ir, Readings, Datagrams}).

%% @doc Lockstep: moves the robot's clock to `Ms' (timers due on the way
%% fire) and applies a fault of the robustness lab there (SPEC §17):
%% `{kill, Name}', `{kill, router, {Receiver, Input}}' (the exit is a step
%% and settles: restart, handover), `{suspend, Name}' or `{resume, Name}'.
%% Answers the trace lines, the fault's own first.
-spec fault(handle(), non_neg_integer(), term()) -> [iodata()].
fault(Robot, Ms, Fault) ->
    call(Robot, {fault, Ms, Fault}).

%% @doc Starts a node for one robot (an OTP `peer' on this machine, over
%% its standard I/O: not distributed, so robots never form a cluster) with
%% this node's code path and application environment, and the robot on it.
%% The peer is not linked to the caller: link to it, or stop it with
%% {@link stop_peer/1}.
-spec start_peer(opts()) -> {ok, handle(), inet:port_number()} | {error, term()}.
start_peer(Opts) ->
    Root = code:root_dir(),
    Paths = [P || P <- code:get_path(), not lists:prefix(Root, P)],
    case peer:start(#{connection => standard_io, args => ["-pa" | Paths],
                      wait_boot => ?PEER_BOOT_MS}) of
        {ok, Peer} -> on_peer(Peer, Opts);
        {ok, Peer, _Node} -> on_peer(Peer, Opts);
        {error, Reason} -> {error, {peer, Reason}}
    end.

%% @doc Stops a robot's node started by {@link start_peer/1}.
-spec stop_peer(handle()) -> ok.
stop_peer({peer, Peer}) ->
    try peer:stop(Peer)
    catch exit:_ -> ok
    end;
stop_peer(local) ->
    stop().

on_peer(Peer, Opts) ->
    Env = [{App, application:get_all_env(App)} || App <- [kernel, toroco, toroco_hw, torobot]],
    #{level := Level} = logger:get_primary_config(),
    try
        ok = peer:call(Peer, logger, set_primary_config, [level, Level], ?CALL_MS),
        _ = [peer:call(Peer, application, set_env, [App, K, V], ?CALL_MS)
             || {App, Pairs} <- Env, App =/= kernel, {K, V} <- Pairs],
        case peer:call(Peer, ?MODULE, start, [Opts], ?PEER_BOOT_MS) of
            {ok, Port} -> {ok, {peer, Peer}, Port};
            {error, _} = Error -> stop_peer({peer, Peer}), Error
        end
    catch
        Class:Reason ->
            stop_peer({peer, Peer}),
            {error, {peer, {Class, Reason}}}
    end.

call(local, Request) ->
    gen_server:call(?MODULE, Request, ?CALL_MS);
call({peer, Peer}, Request) ->
    peer:call(Peer, gen_server, call, [?MODULE, Request, ?CALL_MS], ?CALL_MS).

%%====================================================================
%% The robot's process
%%====================================================================

-spec init(map()) -> {ok, #robot{}} | {stop, term()}.
init(#{wiring := Wiring, thresholds := Thresholds, speed := Speed, started := Started,
       added := #{behaviors := Bs, devices := Ds, placement := Placed, nodes := Nodes}} = Opts) ->
    Sensors = maps:get(sensors, Opts, []),
    Lockstep = maps:get(time, Opts, realtime) =:= lockstep,
    process_flag(trap_exit, true),
    %% what the wiring adds, taken away again by teardown/1
    S = #robot{started = Started,
               behaviors = [{behavior, B} || B <- Bs] ++ [{device, D} || D <- Ds],
               remote = [B || B <- Bs, is_map_key(B, Placed)],
               sensors = [Name || {Name, _} <- Sensors],
               clock = set_clock(Speed, Lockstep, maps:get(trace, Opts, false), Nodes)},
    try
        ok = step(devices, add_devices(Thresholds, Sensors, Lockstep)),
        ok = step(wheels, toroco:add_device(wheels, torobot_sim_wheels, #{sim => self()})),
        ok = step({wiring, Wiring}, toroco:load_wiring(Wiring)),
        ok = step(wheels, toroco:set_inputs(wheels, #{applied => [{motors, applied}]})),
        {ok, lua(Opts, S)}
    catch
        throw:{step, Step, Failure} ->
            teardown(S),
            {stop, {Step, Failure}}
    end.

%% A program written for the original Torocó, after the wiring (SPEC §16):
%% its behaviors are removed with the rest.
lua(#{lua := Main}, S = #robot{behaviors = Bs}) ->
    case application:ensure_all_started(toroco_lua) of
        {ok, _} -> ok;
        {error, Why} -> throw({step, {lua, Main}, Why})
    end,
    case toroco_lua:load_main(Main, #{}) of
        {ok, #{behaviors := Names}} -> S#robot{behaviors = Bs ++ [{behavior, N} || N <- Names]};
        {error, Why1} -> throw({step, {lua, Main}, Why1})
    end;
lua(#{}, S) ->
    S.

-spec handle_call(term(), gen_server:from(), #robot{}) ->
          {reply, term(), #robot{}} | {noreply, #robot{}}.
handle_call(wheels, _From, S = #robot{wheels = Wheels}) ->
    {reply, {Wheels, winner()}, S};
handle_call({step, T, Ir, Readings, Datagrams}, _From, S = #robot{wheels = W0}) ->
    Stimuli = [toroco_pru_sensors:stimulus(ir, Side, Raw) || {Side, Raw} <- lists:sort(maps:to_list(Ir))]
        ++ [torobot_sim_sensor:stimulus(N, R) || {N, R} <- lists:sort(maps:to_list(Readings))]
        ++ [toroco_udp_camera:stimulus(camera, D) || D <- Datagrams],
    case toroco_clock:tick(T, Stimuli) of
        {ok, Lines} ->
            Wheels = applied(W0),
            {reply, {Wheels, winner(), Lines}, S#robot{wheels = Wheels}};
        {error, Reason} ->
            {stop, {lockstep, Reason}, {error, Reason}, S}
    end;
handle_call({fault, Ms, Fault}, _From, S = #robot{wheels = W0}) ->
    Lines = [io_lib:format("~b fault ~ts~n", [Ms, torobot_faults:describe(Fault)])
             | apply_fault(Ms, Fault)],
    {reply, Lines, S#robot{wheels = applied(W0)}};
handle_call(go, _From, S = #robot{clock = lockstep, wheels = W0}) ->
    %% the press and the release, at time 0, each to quiescence
    Press = [toroco_clock:tick(0, [toroco_gpio_button:stimulus(push, Edge)])
             || Edge <- [pressed, released]],
    Wheels = applied(W0),
    case {lists:usort([element(1, P) || P <- Press]), motors_enabled()} of
        {[ok], true} -> {reply, ok, S#robot{wheels = Wheels}};
        {[ok], false} -> {reply, {error, motors_not_enabled}, S#robot{wheels = Wheels}};
        _ -> {reply, {error, {lockstep, Press}}, S}
    end;
handle_call(go, From, S) ->
    case toroco_gpio_button:sim_button(push, 0) of
        ok ->
            erlang:send_after(?PRESS_MS, self(), release),
            self() ! enabled,
            Deadline = erlang:monotonic_time(millisecond) + ?ENABLE_WAIT_MS,
            {noreply, S#robot{going = {From, Deadline}}};
        {error, _} = Error ->
            {reply, Error, S}
    end;
handle_call(_Request, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), #robot{}) -> {noreply, #robot{}}.
handle_cast({sense, Ir, Readings}, S) ->
    _ = [ok = toroco_pru_sensors:sim_adc(ir, Side, Raw) || {Side, Raw} <- maps:to_list(Ir)],
    maps:foreach(fun torobot_sim_sensor:feed/2, Readings),
    {noreply, S};
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #robot{}) -> {noreply, #robot{}}.
handle_info({torobot_sim_wheels, Wheels}, S) ->
    {noreply, S#robot{wheels = Wheels}};
handle_info(release, S) ->
    _ = toroco_gpio_button:sim_button(push, 1),
    {noreply, S};
handle_info(enabled, S = #robot{going = {From, Deadline}}) ->
    case {motors_enabled(), erlang:monotonic_time(millisecond) > Deadline} of
        {true, _} ->
            gen_server:reply(From, ok),
            {noreply, S#robot{going = undefined}};
        {false, true} ->
            gen_server:reply(From, {error, motors_not_enabled}),
            {noreply, S#robot{going = undefined}};
        {false, false} ->
            erlang:send_after(?ENABLE_POLL_MS, self(), enabled),
            {noreply, S}
    end;
handle_info(_Info, S) ->
    {noreply, S}.

-spec terminate(term(), #robot{}) -> ok.
terminate(_Reason, S) ->
    warn_safety_stops(),
    teardown(S).

%% A robot's fault at simulated `Ms', each part to quiescence.
apply_fault(Ms, {kill, port, Program}) ->
    {ok, Before} = toroco_clock:tick(Ms, []),
    Before ++ lists:append([kill_program(Ms, Program, Owner) || Owner <- owners(Program)]);
apply_fault(Ms, Fault) ->
    {ok, Before} = toroco_clock:tick(Ms, []),
    Stimuli = case Fault of
                  {kill, router, {R, I}} -> exit_of(toroco:whereis({router, R, I}));
                  {kill, Name} -> exit_of(toroco:whereis(Name));
                  _ -> []
              end,
    _ = case Fault of
            {suspend, N} -> toroco:suspend_behavior(N);
            {resume, N} -> toroco:resume_behavior(N);
            {disconnect, Node, For} -> ok = toroco_clock:cut(Node, round(For));
            {kill_node, Node} -> ok = toroco_clock:cut(Node, forever);
            _ -> ok
        end,
    {ok, After} = toroco_clock:tick(Ms, Stimuli),
    Before ++ After.

exit_of(undefined) -> [];
exit_of(Pid) -> [{exit, Pid, kill}].

%% The owners of the robot's `pru_port' programs (its devices', each its
%% own on the sim backend, in the devices' order), or the node's
%% `lua_port' owner.
owners(pru_port) ->
    lists:foldl(fun(Name, Acc) ->
                        case toroco:inspect(Name) of
                            #{device := #{port := Owner}} when is_pid(Owner) ->
                                [Owner || not lists:member(Owner, Acc)] ++ Acc;
                            _ -> Acc
                        end
                end, [], lists:reverse(?DEVICES));
owners(lua_port) ->
    %% the program's owner runs while toroco_lua does (a Lua run started it)
    [toroco_lua || lists:keymember(toroco_lua, 1, application:which_applications())].

%% Kills one program (its OS process, as a crash of the C program would
%% end it) and waits in real time, the world's clock standing still, for
%% its owner to have started and configured the next one. The owner tells
%% the devices or Lua behaviors as notices (toroco_clock:notify/2), steps
%% at simulated `Ms' that the tick then runs to quiescence, in order.
kill_program(Ms, pru_port, Owner) ->
    ok = toroco_pru_port:subscribe(Owner),
    kill_os(toroco_pru_port:os_pid(Owner)),
    Restarted = receive
                    {toroco_pru_port, {port_restarted, _}} -> ok
                after ?CALL_MS -> {error, {pru_port, not_restarted}}
                end,
    _ = toroco_pru_port:unsubscribe(Owner),
    ok = Restarted,
    {ok, After} = toroco_clock:tick(Ms, []),
    After;
kill_program(Ms, lua_port, _Owner) ->
    OsPid = toroco_lua_port:os_pid(),
    kill_os(OsPid),
    ok = await(fun() -> toroco_lua_port:os_pid() =/= OsPid end,
               erlang:monotonic_time(millisecond) + ?CALL_MS, {lua_port, not_restarted}),
    {ok, After} = toroco_clock:tick(Ms, []),
    After.

kill_os(OsPid) when is_integer(OsPid) ->
    _ = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    ok.

%% A condition of another process met, waited for in real time (a program
%% is being started), at most until `Deadline'.
await(Cond, Deadline, Why) ->
    case Cond() of
        true -> ok;
        false ->
            case erlang:monotonic_time(millisecond) < Deadline of
                true -> receive after 2 -> await(Cond, Deadline, Why) end;
                false -> {error, Why}
            end
    end.

%%====================================================================
%% Setting up and tearing down
%%====================================================================

step(_Step, ok) -> ok;
step(Step, {error, Reason}) -> throw({step, Step, Reason});
step(Step, Other) -> throw({step, Step, Other}).

add_devices(#{threshold_high := High, threshold_low := Low}, Sensors, Lockstep) ->
    Ir = fun(Channel) -> #{channel => Channel, mode => analog_threshold,
                           threshold_high => High, threshold_low => Low} end,
    Devices = [{ir, toroco_pru_sensors, #{sensors => [{left, Ir(0)}, {right, Ir(1)}],
                                          backend => sim}},
               {motors, toroco_servo_motors, case Lockstep of
                                                 true -> #{backend => sim, watchdog_ms => 0};
                                                 false -> #{backend => sim}
                                             end},
               {camera, toroco_udp_camera, #{port => 0, ip => {127, 0, 0, 1}}},
               {push, toroco_gpio_button, #{line => 0, backend => sim}}]
        ++ [{Name, torobot_sim_sensor, #{outputs => Outputs}} || {Name, Outputs} <- Sensors],
    lists:foldl(fun({Name, Module, DevOpts}, ok) ->
                        case toroco:add_device(Name, Module, DevOpts) of
                            ok -> ok;
                            {error, Reason} -> {error, {Name, Reason}}
                        end;
                   (_, Error) -> Error
                end, ok, Devices).

camera_port() ->
    case toroco:inspect(camera) of
        #{device := #{port := Port}} when is_integer(Port) -> Port;
        Other -> error({no_camera_port, Other})
    end.

%% The applications this run started are stopped whole; in a node where
%% they were already running, only what the run added is removed.
%% What the run added goes, unless the run started the runtime itself (a
%% runtime already running, e.g. with toroco_lua, keeps only what it had);
%% what the wiring placed on other nodes goes first, before this node's
%% toroco.
teardown(#robot{started = Started, behaviors = Behaviors, sensors = Sensors, clock = Clock,
                remote = Remote}) ->
    _ = [toroco:remove_behavior(B) || B <- Remote],
    _ = case lists:member(toroco, Started) of
            true ->
                ok;
            false ->
                %% the actuators first, as one switches a robot off: what
                %% the behaviors' removal lets go reaches no motor
                _ = [toroco:remove_device(D) || D <- [wheels | lists:reverse(?DEVICES)]],
                _ = [toroco:remove_device(D) || D <- Sensors],
                _ = [toroco:remove_device(D) || {device, D} <- Behaviors],
                [toroco:remove_behavior(B) || {behavior, B} <- Behaviors]
        end,
    restore_clock(Clock),
    _ = [application:stop(App) || App <- lists:reverse(Started)],
    ok.

%% A servo watchdog or a restart of the servos' program stops the robot
%% until a behavior commands a new velocity, which a latched command never
%% does: the run is not what the behaviors made of the world, so say so.
warn_safety_stops() ->
    case catch toroco:inspect(motors) of
        #{device := #{watchdogs := W, port_restarts := R}} when W > 0; R > 0 ->
            logger:warning("torobot_sim: the servos stopped for safety during the run "
                           "(~b watchdog stops, ~b program restarts); the robot stood "
                           "still until its next new velocity", [W, R],
                           #{domain => [torobot, sim]});
        _ ->
            ok
    end.

motors_enabled() ->
    case catch toroco:inspect(motors) of
        #{device := #{enabled := true}} -> true;
        _ -> false
    end.

winner() ->
    try toroco:inspect(motors) of
        #{inputs := #{setvel := #{winner := {Emitter, _}}}} -> Emitter;
        _ -> none
    catch
        _:_ -> none
    end.

%% The velocities the wheels device reported while the step ran (it sends
%% them before the step is done, so they are here when the tick answers).
applied(W) ->
    receive
        {torobot_sim_wheels, W1} -> applied(W1)
    after 0 -> W
    end.

%% The runtime's clock runs at the world's speed for the run, or is the
%% world's in lockstep.
set_clock(_Speed, true, Trace, Nodes) ->
    %% the other nodes the wiring places things on join the world's clock
    ok = toroco_clock:lockstep(#{trace => Trace, nodes => Nodes}),
    lockstep;
set_clock(Speed, false, _Trace, _Nodes) ->
    Previous = toroco_clock:speed(),
    ok = toroco_clock:set_speed(Speed),
    {previous, Previous}.

restore_clock(lockstep) ->
    toroco_clock:realtime();
restore_clock({previous, Speed}) ->
    _ = toroco_clock:set_speed(Speed),
    ok.
