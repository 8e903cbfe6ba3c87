%% @doc The Torobot in a simulated world: the real runtime, the real devices
%% and the Torobot's wiring, with `torobot_world' standing in for the board
%% and the arena.
%%
%% {@link run/2} starts the applications, adds the devices the wiring file
%% expects (SPEC §8), loads the wiring, and ticks the world in real time on
%% a process of its own (this module's gen_server) until the world is done:
%% <ul>
%% <li>`ir' is a `toroco_pru_sensors' on the `pru_port' sim backend; each
%%     tick's raw IR readings go in through `toroco_pru_sensors:sim_adc/3',
%%     so near and far come out of the C program's own hysteresis, with the
%%     world's thresholds;</li>
%% <li>`motors' is a `toroco_servo_motors' on the sim backend (a fake sysfs
%%     PWM tree in a temporary directory); the world moves with the
%%     velocities the servos really apply, which the `wheels' device
%%     (`torobot_sim_wheels', wired to `{motors, applied}') hands to the
%%     simulator;</li>
%% <li>`camera' is a `toroco_udp_camera' on a free local port; each tick the
%%     simulator sends it the detector's datagrams for the frame
%%     (`torobot_world:camera/1') over real UDP;</li>
%% <li>`push' is a `toroco_gpio_button' on the sim backend; the simulator
%%     presses it once at the start, as one would on the board, and the
%%     `button' behavior switches the motors on.</li>
%% </ul>
%% Each step is tagged with the behavior that wins the motors' `setvel'
%% input at that tick, read with `toroco:inspect(motors)': one call per tick
%% to the wiring server, the motors device and its routers, about 65 us,
%% so some 0.1% of a core at the default 20 ticks a second; it names the
%% winner as the runtime sees it, which no cheaper reading of the velocities
%% could (two behaviors may command the same pair).
%%
%% The world runs in real time only: every timer of the runtime (holds,
%% watchdogs, debounce, restarts) runs on the node's clock, so a faster
%% world would change what the robot does. At the end the SVG is written
%% and everything the run started is stopped: the applications if it
%% started them, else the nodes it added.
%%
%% Options of {@link run/2}: `svg' (a path; no picture without it),
%% `wiring' (default: app env `wiring' of `torobot', else
%% `config/torobot.wiring'), `status' (`false', the default; `true' prints a
%% status line each world second; `tty' rewrites one line in place; or a fun
%% called with each line). {@link simulate/2} is {@link run/2} returning the
%% final world, trajectory included; {@link summary_json/1} is the summary
%% as the run command prints it.
-module(torobot_sim).
-behaviour(gen_server).

-export([run/2, simulate/2, summary_json/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([opts/0, status/0]).

-type status() :: boolean() | tty | fun((iodata()) -> any()).
-type opts() :: #{svg => file:name_all(), wiring => file:name_all(), status => status()}.

-define(DEVICES, [ir, motors, camera, push]).
-define(PRESS_MS, 60).
%% How long past the world's duration the caller waits before giving up.
-define(GRACE_MS, 30000).

-record(sim, {world :: torobot_world:world(),
              caller :: pid(),
              status :: status(),
              tick :: pos_integer(),
              t0 :: integer() | undefined,
              ticks = 0 :: non_neg_integer(),
              wheels = {0, 0} :: {number(), number()},
              sock :: gen_udp:socket() | undefined,
              camera :: inet:port_number() | undefined,
              ir = #{} :: map(),
              next_status = 1000 :: non_neg_integer()}).

%%====================================================================
%% API
%%====================================================================

%% @doc Runs the Torobot in the world of `WorldFile' to the world's end and
%% returns the summary (`torobot_world:summary/1'). Fails with
%% `{error, {world, File, Reason}}' for a bad world file, `{error, {wiring,
%% File, Reason}}' for a bad wiring file, or `{error, {Step, Reason}}' when
%% the applications, a device or the run itself fail.
-spec run(file:name_all(), opts()) -> {ok, torobot_world:summary()} | {error, term()}.
run(WorldFile, Opts) ->
    case simulate(WorldFile, Opts) of
        {ok, World} -> {ok, torobot_world:summary(World)};
        {error, _} = Error -> Error
    end.

%% @doc As {@link run/2}, returning the final world (with its trajectory)
%% instead of its summary.
-spec simulate(file:name_all(), opts()) -> {ok, torobot_world:world()} | {error, term()}.
simulate(WorldFile, Opts) when is_map(Opts) ->
    WiringFile = maps:get(wiring, Opts,
                          application:get_env(torobot, wiring, "config/torobot.wiring")),
    case {torobot_world:load(WorldFile), file:consult(WiringFile)} of
        {{error, Reason}, _} ->
            {error, {world, WorldFile, Reason}};
        {_, {error, Reason}} ->
            {error, {wiring, WiringFile, Reason}};
        {{ok, World}, {ok, Terms}} ->
            Behaviors = [Name || {behavior, Name, _, _} <- Terms],
            case application:ensure_all_started(torobot) of
                {ok, Started} ->
                    try
                        with_network(World, WiringFile, Opts)
                    after
                        stop(Started, Behaviors)
                    end;
                {error, Reason} ->
                    {error, {applications, Reason}}
            end
    end.

%% @doc The summary as one JSON object (`none' as `null').
-spec summary_json(torobot_world:summary()) -> binary().
summary_json(#{red_touched_ms := Red, wall_contacts := Walls, blue_contacts := Blue,
               distance_m := Distance}) ->
    iolist_to_binary(
      ["{\"red_touched_ms\":", case Red of
                                   none -> "null";
                                   _ -> integer_to_list(Red)
                               end,
       ",\"wall_contacts\":", integer_to_list(Walls),
       ",\"blue_contacts\":", integer_to_list(Blue),
       ",\"distance_m\":", float_to_list(float(Distance), [{decimals, 3}, compact]),
       "}"]).

%%====================================================================
%% Setting up and tearing down
%%====================================================================

with_network(World, WiringFile, Opts) ->
    {ok, Sim} = gen_server:start(?MODULE, {World, self(), maps:get(status, Opts, false)}, []),
    MRef = monitor(process, Sim),
    try
        ok = step(devices, add_devices(World)),
        ok = step(wheels, toroco:add_device(wheels, torobot_sim_wheels, #{sim => Sim})),
        ok = step({wiring, WiringFile}, toroco:load_wiring(WiringFile)),
        ok = step(wheels, toroco:set_inputs(wheels, #{applied => [{motors, applied}]})),
        ok = step(camera, gen_server:call(Sim, {go, camera_port()})),
        Timeout = torobot_world:duration_ms(World) + ?GRACE_MS,
        receive
            {?MODULE, Sim, {done, Final}} ->
                demonitor(MRef, [flush]),
                warn_safety_stops(),
                ok = step(svg, svg(Final, Opts)),
                {ok, Final};
            {'DOWN', MRef, process, Sim, Why} ->
                {error, {simulator, Why}}
        after Timeout ->
                {error, {simulator, timeout}}
        end
    catch
        throw:{step, Step, Failure} -> {error, {Step, Failure}}
    after
        demonitor(MRef, [flush]),
        exit(Sim, shutdown)
    end.

step(_Step, ok) -> ok;
step(Step, {error, Reason}) -> throw({step, Step, Reason});
step(Step, Other) -> throw({step, Step, Other}).

add_devices(World) ->
    #{threshold_high := High, threshold_low := Low} = torobot_world:ir_thresholds(World),
    Ir = fun(Channel) -> #{channel => Channel, mode => analog_threshold,
                           threshold_high => High, threshold_low => Low} end,
    Devices = [{ir, toroco_pru_sensors, #{sensors => [{left, Ir(0)}, {right, Ir(1)}],
                                          backend => sim}},
               {motors, toroco_servo_motors, #{backend => sim}},
               {camera, toroco_udp_camera, #{port => 0, ip => {127, 0, 0, 1}}},
               {push, toroco_gpio_button, #{line => 0, backend => sim}}],
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
        Other -> {error, {no_camera_port, Other}}
    end.

%% A servo watchdog or a restart of the servos' program stops the robot
%% until a behavior commands a new velocity, which a latched command never
%% does: the run is not what the behaviors made of the world, so say so.
warn_safety_stops() ->
    case toroco:inspect(motors) of
        #{device := #{watchdogs := W, port_restarts := R}} when W > 0; R > 0 ->
            logger:warning("torobot_sim: the servos stopped for safety during the run "
                           "(~b watchdog stops, ~b program restarts); the robot stood "
                           "still until its next new velocity", [W, R]);
        _ ->
            ok
    end.

svg(World, #{svg := Path}) ->
    ok = filelib:ensure_dir(Path),
    torobot_svg:write(World, Path);
svg(_World, #{}) ->
    ok.

%% The applications this run started are stopped whole; in a node where
%% they were already running, only the nodes it added are removed.
stop([], Behaviors) ->
    _ = [toroco:remove_behavior(B) || B <- Behaviors],
    _ = [toroco:remove_device(D) || D <- [wheels | lists:reverse(?DEVICES)]],
    ok;
stop(Started, _Behaviors) ->
    _ = [application:stop(App) || App <- lists:reverse(Started)],
    ok.

%%====================================================================
%% The world's process
%%====================================================================

-spec init({torobot_world:world(), pid(), status()}) -> {ok, #sim{}}.
init({World, Caller, Status}) ->
    monitor(process, Caller),
    {ok, #sim{world = World, caller = Caller, status = Status,
              tick = torobot_world:tick_ms(World)}}.

-spec handle_call(term(), gen_server:from(), #sim{}) -> {reply, term(), #sim{}}.
handle_call({go, Port}, _From, S) when is_integer(Port) ->
    {ok, Sock} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    case toroco_gpio_button:sim_button(push, 0) of
        ok ->
            erlang:send_after(?PRESS_MS, self(), release),
            S1 = sense(S#sim{sock = Sock, camera = Port}),
            T0 = erlang:monotonic_time(millisecond),
            {reply, ok, schedule(S1#sim{t0 = T0})};
        {error, _} = Error ->
            {reply, Error, S}
    end;
handle_call({go, Error}, _From, S) ->
    {reply, Error, S};
handle_call(_Request, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), #sim{}) -> {noreply, #sim{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #sim{}) -> {noreply, #sim{}} | {stop, term(), #sim{}}.
handle_info({timeout, _Ref, tick}, S = #sim{world = W, wheels = Wheels, tick = Tick}) ->
    Winner = winner(),
    S1 = status(sense(S#sim{world = torobot_world:step(W, Tick, Wheels, Winner)}), Winner),
    publish(S1, Winner),
    case torobot_world:done(S1#sim.world) of
        true ->
            S1#sim.caller ! {?MODULE, self(), {done, S1#sim.world}},
            {stop, normal, S1};
        false ->
            {noreply, schedule(S1)}
    end;
handle_info({torobot_sim_wheels, Wheels}, S) ->
    {noreply, S#sim{wheels = Wheels}};
handle_info(release, S) ->
    _ = toroco_gpio_button:sim_button(push, 1),
    {noreply, S};
handle_info({'DOWN', _, process, Caller, _}, S = #sim{caller = Caller}) ->
    {stop, normal, S};
handle_info(_Info, S) ->
    {noreply, S}.

-spec terminate(term(), #sim{}) -> ok.
terminate(_Reason, #sim{sock = Sock, status = Status}) ->
    case Sock of
        undefined -> ok;
        _ -> gen_udp:close(Sock)
    end,
    case Status of
        tty -> io:put_chars("\n");
        _ -> ok
    end.

%% Ticks are scheduled on the absolute clock from the start, so a late tick
%% does not delay the ones after it.
schedule(S = #sim{t0 = T0, ticks = N, tick = Tick}) ->
    erlang:start_timer(T0 + (N + 1) * Tick, self(), tick, [{abs, true}]),
    S#sim{ticks = N + 1}.

%% The sensors read the world as it is now: IR samples go to the PRU sim
%% only when they change, camera frames are sent every tick, as the
%% detector sends every frame.
sense(S = #sim{world = W, ir = Last, sock = Sock, camera = Port}) ->
    Ir = torobot_world:ir(W),
    _ = [ok = toroco_pru_sensors:sim_adc(ir, Side, Raw)
         || {Side, Raw} <- maps:to_list(Ir), maps:get(Side, Last, undefined) =/= Raw],
    _ = [gen_udp:send(Sock, {127, 0, 0, 1}, Port, Datagram)
         || Datagram <- torobot_world:camera(W)],
    S#sim{ir = Ir}.

%% The dashboard's view of the world (toroco_live_world's message, written
%% down there): a plain send, and only when toroco_live runs in this node.
publish(#sim{world = W, t0 = T0}, Winner) ->
    case whereis(toroco_live_world) of
        undefined ->
            ok;
        Viewer ->
            #{ir := Ir, camera := Camera} = torobot_world:view(W),
            Robot = #{name => torobot, pose => torobot_world:pose(W),
                      radius => torobot_world:robot_radius(W), winner => Winner,
                      ir => Ir, camera => Camera},
            Viewer ! {toroco_live_world, snapshot,
                      #{run => {self(), T0}, t_ms => torobot_world:time_ms(W),
                        arena => torobot_world:arena(W), walls => torobot_world:walls(W),
                        objects => torobot_world:objects(W), robots => [Robot]}},
            ok
    end.

winner() ->
    try toroco:inspect(motors) of
        #{inputs := #{setvel := #{winner := {Emitter, _}}}} -> Emitter;
        _ -> none
    catch
        _:_ -> none
    end.

status(S = #sim{status = false}, _Winner) ->
    S;
status(S = #sim{world = W, next_status = Next, status = How}, Winner) ->
    case torobot_world:time_ms(W) >= Next of
        true ->
            {X, Y, H} = torobot_world:pose(W),
            Line = io_lib:format("t ~5.1f s  ~-13s x ~4.2f  y ~4.2f  heading ~4b",
                                 [torobot_world:time_ms(W) / 1000, Winner, X, Y, round(H)]),
            case How of
                true -> io:put_chars([Line, "\n"]);
                tty -> io:put_chars(["\r", Line]);
                Fun when is_function(Fun, 1) -> Fun(Line)
            end,
            S#sim{next_status = Next + 1000};
        false ->
            S
    end.
