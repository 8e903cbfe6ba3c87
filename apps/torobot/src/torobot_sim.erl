%% @doc The Torobot in a simulated world: the real runtime, the real devices
%% and the Torobot's wiring, with `torobot_world' standing in for the board
%% and the arena (SPEC §8, §14).
%%
%% {@link run/2} loads the world, starts each robot's side
%% (`torobot_sim_robot': the runtime, the devices the wiring file expects
%% on their simulated backends, the wiring) and ticks the world on a
%% process of its own (this module's gen_server) until the world is done.
%% Each tick the world reads every robot's applied wheel velocities and the
%% behavior winning its motors, steps the robots one after another (each
%% sees the others where they are: they block moves, IR rays and the
%% camera's line of sight), then hands each robot its IR readings (to the
%% `pru_port' sim backend, only when they change) and its camera frame (the
%% detector's datagrams, over real UDP).
%% The sensors of the library's robots (`torobot_sensors': `range',
%% `bumper', `odometry', `light', `beacon') are `torobot_sim_sensor'
%% devices on each robot's node, fed each tick with the rest; a wiring that
%% does not use them (the Torobot's) leaves them unwired.
%%
%% Where robots run: the one-robot form of a world (`{robot, Pose}') runs
%% in this node; a world of named robots (`{robot, Name, Pose}') runs each
%% robot on a node of its own, an OTP `peer' over its standard I/O (not
%% distributed: robots form no cluster, and no cookie is needed), while the
%% world stays here. Option `nodes => peer' puts a one-robot world on a
%% peer too (as {@link batch/1} does, to run worlds side by side).
%%
%% Speed: `speed => S' (default 1) runs the world S times faster than real
%% time: a tick of `tick_ms' world milliseconds takes `tick_ms / S' real
%% ones, and the robot's timers follow: the runtime's clock
%% (`toroco_clock') runs at the same speed, so holds, gate timers and
%% behaviors' timeouts count world milliseconds. What belongs to real
%% hardware stays in real time: the servos' watchdog and its keepalive,
%% the button's debounce. What limits the
%% speed is the event path's real latency: a reaction that takes L real ms
%% lands L * S world ms later, so it is on time while L * S stays under a
%% tick (`make bench' finds the highest speed that keeps the outcome).
%%
%% Lockstep (`time => lockstep', SPEC §14): the world is the robots'
%% clock. Each tick, robot after robot in file order, the world hands a
%% robot the time and its readings (`torobot_sim_robot:step/5': steps of
%% the robot's event path, not UDP nor the port's timing), waits until its
%% event path is quiescent, and takes the velocities its servos apply then;
%% then it moves every robot. No tick waits on a real clock, so the run
%% goes as fast as the CPU allows and its outcome depends only on the
%% world, the wiring and the seed. `trace => Path' writes every step of
%% every robot's event path (emissions, deliveries, acks, timers, stimuli)
%% and every change of the wheels, one line each with its simulated time
%% in ms (a robot's name first in a world of named robots): two runs of
%% the same world give byte-identical files. `speed' means nothing there.
%%
%% At the end the SVG is written (one picture, every robot) and everything
%% the run started is stopped: the peers, the applications if it started
%% them in this node, else the behaviors and devices it added.
%%
%% Options of {@link run/2}: `svg' (a path; no picture without it),
%% `wiring' (default: app env `wiring' of `torobot', else
%% `config/torobot.wiring'), `lua' (a program written for the original
%% Torocó, its main.lua, run with `toroco_lua:load_main/2' after the wiring,
%% whose default is then `config/torobot_lua.wiring': SPEC §16), `time'
%% (`realtime', the default, or
%% `lockstep'), `trace' (a path, lockstep only), `speed' (a number > 0,
%% default 1, real time only), `nodes'
%% (`local' or `peer'; see above), `status' (`false', the default; `true'
%% prints a status line each world second; `tty' rewrites one line in
%% place; or a fun called with each line). {@link simulate/2} is {@link
%% run/2} returning the final world (a list of them for named robots),
%% trajectory included; {@link summary_json/1} is the summary as the run
%% command prints it; {@link batch/1} runs many worlds and scores them
%% (`torobot_batch').
-module(torobot_sim).
-behaviour(gen_server).

-export([run/2, simulate/2, observe/2, summary_json/1, batch/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([opts/0, status/0, world_spec/0, summary/0]).

-type status() :: boolean() | tty | fun((iodata()) -> any()).
-type opts() :: #{svg => file:name_all(), wiring => file:name_all(), status => status(),
                  speed => number(), nodes => local | peer, time => realtime | lockstep,
                  trace => file:name_all(), faults => torobot_faults:concrete(),
                  seed => integer(), stop => fun(([map()]) -> boolean()),
                  marks => [#{t_ms := non_neg_integer(), kind := atom(), text := iodata()}],
                  lua => file:name_all()}.
%% A world file, or the terms of one (as `torobot_worlds:generate/2' makes).
-type world_spec() :: file:name_all() | [tuple()].
%% One robot's summary, or one per robot for a world of named robots.
-type summary() :: torobot_world:summary() | #{atom() => torobot_world:summary()}.

%% How long past the world's duration (in real time) the caller waits
%% before giving up.
-define(GRACE_MS, 30000).

-record(bot, {world :: torobot_world:world(),
              handle :: torobot_sim_robot:handle(),
              port :: inet:port_number(),
              ir = #{} :: map(),
              sensors :: torobot_sensors:state(),
              readings = #{} :: map(),
              winner = none :: atom(),
              motors = none :: none | {{number(), number()}, atom()},
              %% the faults' state: stuck readings, delayed datagrams
              stuck = #{} :: map(),
              delayed = [] :: [{integer(), binary()}],
              lines = [] :: [iodata()]}).

-record(sim, {bots = [] :: [#bot{}],
              caller :: pid(),
              status :: status(),
              speed :: number(),
              tick :: pos_integer(),
              t0 :: integer() | undefined,
              ticks = 0 :: non_neg_integer(),
              sock :: gen_udp:socket() | undefined,
              next_status = 1000 :: non_neg_integer(),
              time = realtime :: realtime | lockstep,
              trace :: file:io_device() | undefined,
              %% the fault schedule (SPEC §17): the world's faults, the
              %% robot's events not applied yet, the seed; observations
              faults = [] :: torobot_faults:concrete(),
              stop = none :: none | fun(([torobot_props:observation()]) -> boolean()),
              %% what the dashboard marks on the run's timeline: the faults,
              %% and what the caller adds (a replay's violation)
              marks = [] :: [map()],
              robot_events = [] :: [{non_neg_integer(), term()}],
              seed = 0 :: integer(),
              %% whether each tick's observation is kept (observe/2)
              observing = true :: boolean(),
              obs = [] :: [torobot_props:observation()]}).

-define(OPTIONS, [svg, wiring, status, speed, nodes, time, trace, faults, seed, stop, marks, lua]).

%%====================================================================
%% API
%%====================================================================

%% @doc Runs the Torobot in a world to the world's end and returns the
%% summary (`torobot_world:summary/1'; for a world of named robots, a map
%% of robot name to summary). Fails with `{error, {bad_option, Key}}' for
%% an option it does not know, `{error, {world, World, Reason}}' for a bad
%% world, `{error, {wiring, File, Reason}}' for a bad wiring file, `{error,
%% {speed, S}}', `{error, {time, T}}' or `{error, {trace, P}}' for a bad
%% value, or `{error, {Step, Reason}}' when the applications, a device, a
%% node or the run fail.
-spec run(world_spec(), opts()) -> {ok, summary()} | {error, term()}.
run(WorldSpec, Opts) ->
    case simulate(WorldSpec, Opts) of
        {ok, Worlds} when is_list(Worlds) ->
            {ok, maps:from_list([{torobot_world:name(W), torobot_world:summary(W)}
                                 || W <- Worlds])};
        {ok, World} ->
            {ok, torobot_world:summary(World)};
        {error, _} = Error ->
            Error
    end.

%% @doc As {@link run/2}, returning the final world (with its trajectory)
%% instead of its summary: one world for the one-robot form, a list of
%% worlds (one per robot, in file order) for named robots.
-spec simulate(world_spec(), opts()) ->
          {ok, torobot_world:world() | [torobot_world:world()]} | {error, term()}.
simulate(WorldSpec, Opts) when is_map(Opts) ->
    %% nothing judges this run: no observation is made of each tick
    case observe(WorldSpec, Opts, false) of
        {ok, Final, _Obs} -> {ok, Final};
        {error, _} = Error -> Error
    end.

%% @doc As {@link simulate/2}, with the observations of each tick (one
%% robot: `torobot_props:observation()', in time order), which the
%% properties of the robustness lab judge (SPEC §17). Options `faults' (a
%% concrete schedule, `torobot_faults:concrete()', lockstep only), `seed'
%% (of the faults' noise and losses, default 0) and `stop' (a fun of the
%% observations so far, asked each simulated second: `true' ends the run
%% there).
-spec observe(world_spec(), opts()) ->
          {ok, torobot_world:world() | [torobot_world:world()], [torobot_props:observation()]}
          | {error, term()}.
observe(WorldSpec, Opts) when is_map(Opts) ->
    observe(WorldSpec, Opts, true).

observe(WorldSpec, Opts, Observing) ->
    WiringFile = maps:get(wiring, Opts,
                          case Opts of
                              #{lua := _} -> "config/torobot_lua.wiring";
                              #{} -> application:get_env(torobot, wiring, "config/torobot.wiring")
                          end),
    Speed = maps:get(speed, Opts, 1),
    Time = maps:get(time, Opts, realtime),
    Trace = maps:get(trace, Opts, undefined),
    Unknown = lists:sort(maps:keys(Opts) -- ?OPTIONS),
    case {load(WorldSpec), toroco:read_wiring(WiringFile)} of
        _ when Unknown =/= [] ->
            {error, {bad_option, hd(Unknown)}};
        _ when Time =/= realtime, Time =/= lockstep ->
            {error, {time, Time}};
        _ when Time =/= lockstep, is_map_key(faults, Opts) ->
            {error, {faults, lockstep_only}};
        _ when Trace =/= undefined, Time =/= lockstep; Trace =/= undefined,
                                                     not (is_list(Trace) orelse is_binary(Trace)) ->
            {error, {trace, Trace}};
        {{error, Reason}, _} ->
            {error, {world, WorldSpec, Reason}};
        {_, {error, {wiring_file, {_, Reason}}}} ->
            {error, {wiring, WiringFile, Reason}};
        {_, _} when not is_number(Speed); Speed =< 0 ->
            {error, {speed, Speed}};
        {{ok, Worlds}, {ok, #{nodes := WiringNodes}}} ->
            Run = Opts#{observing => Observing, wiring_nodes => WiringNodes},
            case [N || N <- WiringNodes, Time =:= lockstep, not lists:member(N, nodes())] of
                [] -> run_worlds(Worlds, WiringFile, Speed, Time, Run);
                [Node | _] -> {error, {node_not_connected, Node}}
            end
    end.

%% The checked worlds run (a robot placed on several nodes, SPEC §13, runs
%% from this node, whose clock the other nodes join in lockstep).
run_worlds(Worlds, WiringFile, Speed, Time, Opts) ->
    Named = torobot_world:name(hd(Worlds)) =/= undefined,
    Nodes = maps:get(nodes, Opts, case Named of
                                      true -> peer;
                                      false -> local
                                  end),
    case with_robots(Worlds, Nodes, Opts#{wiring => WiringFile, speed => Speed,
                                          time => Time}) of
        {ok, [Final], Obs} when not Named -> {ok, Final, Obs};
        {ok, Finals, Obs} -> {ok, Finals, Obs};
        {error, _} = Error -> Error
    end.

%% @doc The summary as one JSON object (`none' as `null'); a world's own
%% figures (`torobot_sensors', and `robot_contacts' for a named robot)
%% follow the Torobot's keys. A world of named robots gives one object
%% with a member per robot.
-spec summary_json(summary()) -> binary().
summary_json(Summary) ->
    torobot_sim_view:summary_json(Summary).

%% @doc Runs many worlds, several at once, and scores them: see
%% `torobot_batch:run/1'.
-spec batch(torobot_batch:opts()) -> {ok, torobot_batch:report()} | {error, term()}.
batch(Opts) ->
    torobot_batch:run(Opts).

%%====================================================================
%% Setting up and tearing down
%%====================================================================

load(Terms) when is_list(Terms), Terms =/= [], is_tuple(hd(Terms)) ->
    torobot_world:from_terms_all(Terms);
load(File) ->
    torobot_world:load_all(File).

with_robots(Worlds, Nodes, Opts) ->
    #{wiring := WiringFile, speed := Speed, time := Time} = Opts,
    Trace = maps:get(trace, Opts, undefined),
    {ok, Sim} = gen_server:start(?MODULE, {self(), maps:get(status, Opts, false), Speed,
                                           torobot_world:tick_ms(hd(Worlds)), Time, Trace,
                                           maps:get(faults, Opts, []), maps:get(seed, Opts, 0),
                                           {maps:get(stop, Opts, none),
                                            maps:get(observing, Opts, true)},
                                           maps:get(marks, Opts, [])},
                                 []),
    MRef = monitor(process, Sim),
    RobotOpts0 = #{wiring => WiringFile, speed => Speed, time => Time,
                  trace => Trace =/= undefined,
                  thresholds => torobot_world:ir_thresholds(hd(Worlds)),
                  %% a sensor the world has not (no outputs) gets no device
                  sensors => [{Name, Os} || {Name, Outputs} <- torobot_sensors:devices(),
                                            Os <- [Outputs(hd(Worlds))], Os =/= []]},
    RobotOpts = maps:merge(RobotOpts0, maps:with([lua], Opts)),
    Started = start_robots(Worlds, Nodes, RobotOpts),
    try
        Bots = [case Result of
                    {ok, Handle, Port} -> #bot{world = W, handle = Handle, port = Port,
                                               sensors = torobot_sensors:new(W)};
                    {error, Reason} -> throw({failed, Reason})
                end || {W, Result} <- lists:zip(Worlds, Started)],
        ok = case gen_server:call(Sim, {go, Bots}, infinity) of
                 ok -> ok;
                 {error, GoFailed} -> throw({failed, {go, GoFailed}})
             end,
        %% a run in lockstep goes as fast as the CPU allows: given as long
        %% as real time would take, it is stuck; a robot over several nodes
        %% pays round trips between them for its steps, and gets more
        Others = length(maps:get(wiring_nodes, Opts, [])),
        Timeout = case Time of
                      realtime -> round(torobot_world:duration_ms(hd(Worlds)) / Speed);
                      lockstep -> torobot_world:duration_ms(hd(Worlds)) * (1 + 4 * Others)
                  end + ?GRACE_MS,
        receive
            {?MODULE, Sim, {done, Finals, Obs}} ->
                demonitor(MRef, [flush]),
                case svg(Finals, Opts) of
                    ok -> {ok, Finals, Obs};
                    {error, SvgFailed} -> {error, {svg, SvgFailed}}
                end;
            {'DOWN', MRef, process, Sim, Why} ->
                {error, {simulator, Why}}
        after Timeout ->
                {error, {simulator, timeout}}
        end
    catch
        throw:{failed, Failure} -> {error, Failure}
    after
        demonitor(MRef, [flush]),
        exit(Sim, shutdown),
        _ = [torobot_sim_robot:stop_peer(Handle) || {ok, Handle, _} <- Started]
    end.

%% Peers boot side by side, each linked to the caller once up; the robot
%% in this node starts in it.
start_robots([_], local, RobotOpts) ->
    case torobot_sim_robot:start(RobotOpts) of
        {ok, Port} -> [{ok, local, Port}];
        {error, _} = Error -> [Error]
    end;
start_robots(Worlds, _Peer, RobotOpts) ->
    Self = self(),
    Pids = [spawn_link(fun() -> Self ! {self(), torobot_sim_robot:start_peer(RobotOpts)} end)
            || _ <- Worlds],
    [receive
         {Pid, {ok, {peer, Peer}, _} = Result} -> link(Peer), Result;
         {Pid, Result} -> Result
     end || Pid <- Pids].

svg(Worlds, #{svg := Path}) ->
    ok = filelib:ensure_dir(Path),
    case Worlds of
        [World] -> torobot_svg:write(World, Path);
        _ -> torobot_svg:write_all(Worlds, Path)
    end;
svg(_Worlds, #{}) ->
    ok.

%%====================================================================
%% The world's process
%%====================================================================

-spec init({pid(), status(), number(), pos_integer(), realtime | lockstep,
            file:name_all() | undefined, torobot_faults:concrete(), integer(),
            {none | fun(), boolean()}, [map()]}) ->
          {ok, #sim{}} | {stop, term()}.
init({Caller, Status, Speed, Tick, Time, TracePath, Faults, Seed, {Stop, Observing}, Marks}) ->
    monitor(process, Caller),
    S = #sim{caller = Caller, status = Status, speed = Speed, tick = Tick, time = Time,
             faults = Faults, seed = Seed, robot_events = torobot_faults:robot_events(Faults), stop = Stop,
             observing = Observing,
             marks = [#{t_ms => Ms, kind => fault,
                        text => iolist_to_binary(torobot_faults:describe(F))}
                      || {at, Ms, F} <- Faults]
                 ++ [M#{text := iolist_to_binary(T)} || M = #{text := T} <- Marks]},
    case TracePath of
        undefined ->
            {ok, S};
        _ ->
            ok = filelib:ensure_dir(TracePath),
            case file:open(TracePath, [write, raw, binary, {delayed_write, 65536, 200}]) of
                {ok, Fd} -> {ok, S#sim{trace = Fd}};
                {error, Reason} -> {stop, {trace, TracePath, Reason}}
            end
    end.

-spec handle_call(term(), gen_server:from(), #sim{}) -> {reply, term(), #sim{}}.
handle_call({go, Bots}, _From, S = #sim{time = lockstep}) ->
    case lists:filter(fun(R) -> R =/= ok end,
                      [torobot_sim_robot:go(B#bot.handle) || B <- Bots]) of
        [] ->
            self() ! lockstep,
            {reply, ok, S#sim{bots = Bots, t0 = erlang:monotonic_time(microsecond)}};
        [Error | _] ->
            {reply, Error, S}
    end;
handle_call({go, Bots}, _From, S) ->
    {ok, Sock} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    case lists:filter(fun(R) -> R =/= ok end,
                      [torobot_sim_robot:go(B#bot.handle) || B <- Bots]) of
        [] ->
            S1 = sense(S#sim{sock = Sock, bots = Bots}),
            T0 = erlang:monotonic_time(microsecond),
            {reply, ok, schedule(S1#sim{t0 = T0})};
        [Error | _] ->
            gen_udp:close(Sock),
            {reply, Error, S}
    end;
handle_call(_Request, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), #sim{}) -> {noreply, #sim{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #sim{}) -> {noreply, #sim{}} | {stop, term(), #sim{}}.
handle_info({timeout, _Ref, tick}, S = #sim{bots = Bots, tick = Tick}) ->
    Commands = [case torobot_world:done(W) of
                    true -> done;
                    false -> torobot_sim_robot:wheels(H)
                end || #bot{world = W, handle = H} <- Bots],
    S1 = status(sense(S#sim{bots = move(Bots, Commands, Tick)})),
    publish(S1),
    next(S1, fun schedule/1);
handle_info(lockstep, S = #sim{bots = Bots, tick = Tick}) ->
    %% robot after robot: readings, quiescence, wheels; then they all move
    {Stepped, S0} = lists:mapfoldl(fun(B, Acc) -> lockstep(B, [O || O <- Bots, O =/= B], Acc) end,
                                   S, Bots),
    Commands = [case Motors of
                    done -> done;
                    {Wheels, Winner} ->
                        Active = torobot_faults:world_faults(S#sim.faults,
                                                             torobot_world:time_ms(B#bot.world)),
                        {torobot_faults:wheels(Wheels, Active, B), Winner}
                end || {B, Motors} <- Stepped],
    Moved = move([B || {B, _} <- Stepped], Commands, Tick),
    S1 = status(observed(Moved, S0#sim{bots = Moved})),
    %% every tick: a recording of a lockstep run has the pose at each
    publish(S1),
    next(S1, fun(S2) -> self() ! lockstep, S2 end);
handle_info({'DOWN', _, process, Caller, _}, S = #sim{caller = Caller}) ->
    {stop, normal, S};
handle_info(_Info, S) ->
    {noreply, S}.

-spec terminate(term(), #sim{}) -> ok.
terminate(_Reason, S = #sim{sock = Sock, status = Status}) ->
    case Sock of
        undefined -> ok;
        _ -> gen_udp:close(Sock)
    end,
    _ = close_trace(S),
    case Status of
        tty -> io:put_chars("\n");
        _ -> ok
    end.

close_trace(S = #sim{trace = undefined}) ->
    S;
close_trace(S = #sim{trace = Fd}) ->
    ok = file:close(Fd),
    S#sim{trace = undefined}.

%% After a tick: the caller has the final worlds once every robot is done,
%% else the next tick is asked for.
next(S = #sim{bots = Bots, caller = Caller, obs = Obs, stop = Stop}, Again) ->
    Worlds = [W || #bot{world = W} <- Bots],
    case lists:all(fun torobot_world:done/1, Worlds) orelse stop(Stop, Obs) of
        true ->
            %% the trace is whole on disk before the caller hears of the end
            %% (it reads it back at once: the lab hashes it)
            S1 = close_trace(S),
            Caller ! {?MODULE, self(), {done, Worlds, lists:reverse(Obs)}},
            {stop, normal, S1};
        false ->
            {noreply, Again(S)}
    end.

%% A run may end as soon as its observations say so (the robustness lab's
%% shrinking stops a candidate once its property is violated for sure);
%% asked each simulated second.
stop(none, _Obs) -> false;
stop(Stop, [#{t := T} | _] = Obs) when T rem 1000 =:= 0 -> Stop(lists:reverse(Obs));
stop(_Stop, _Obs) -> false.

%% Ticks are scheduled on the absolute clock from the start, so a late tick
%% does not delay the ones after it.
schedule(S = #sim{t0 = T0, ticks = N, tick = Tick, speed = Speed}) ->
    Due = (T0 + round((N + 1) * Tick * 1000 / Speed)) div 1000,
    erlang:start_timer(Due, self(), tick, [{abs, true}]),
    S#sim{ticks = N + 1}.

%% The robots move one after another, each among the others where they
%% are at that moment, so no two ever overlap. A robot that is done (it
%% touched red) stays where it is.
move(Bots, Commands, Tick) ->
    move_each(lists:zip(Bots, Commands), Tick, []).

move_each([], _Tick, Moved) ->
    lists:reverse(Moved);
move_each([{Bot, done} | Rest], Tick, Moved) ->
    move_each(Rest, Tick, [Bot | Moved]);
move_each([{Bot = #bot{world = W}, {Wheels, Winner}} | Rest], Tick, Moved) ->
    Others = [B#bot.world || B <- Moved] ++ [B#bot.world || {B, _} <- Rest],
    Among = torobot_world:set_others(W, [torobot_world:body(O) || O <- Others]),
    Stepped = torobot_world:step(Among, Tick, Wheels, Winner),
    move_each(Rest, Tick, [Bot#bot{world = Stepped, winner = Winner} | Moved]).

%% The sensors read the world as it is now: IR samples go to the PRU sim
%% and the library's sensors to their devices only when they change,
%% camera frames are sent every tick, as the detector sends every frame.
sense(S = #sim{bots = Bots, sock = Sock}) ->
    S#sim{bots = [sense(B, [O || O <- Bots, O =/= B], Sock) || B <- Bots]}.

sense(B = #bot{world = W0, handle = H, ir = Last, port = Port, readings = LastReadings},
      Others, Sock) ->
    W = torobot_world:set_others(W0, [torobot_world:body(O#bot.world) || O <- Others]),
    case torobot_world:done(W) of
        true ->
            B#bot{world = W};
        false ->
            Ir = torobot_world:ir(W),
            {Readings, Sensors} = torobot_sensors:read(W, B#bot.sensors),
            _ = torobot_sim_robot:sense(H, changed(Ir, Last), changed(Readings, LastReadings)),
            _ = [gen_udp:send(Sock, {127, 0, 0, 1}, Port, Datagram)
                 || Datagram <- torobot_world:camera(W)],
            B#bot{world = W, ir = Ir, sensors = Sensors, readings = Readings}
    end.

%% Lockstep: each robot in turn gets its readings of the world as it is
%% now (the others where they are), as the world's faults leave them, and
%% the robot's faults due by now, and answers once quiescent.
lockstep(B = #bot{world = W0, handle = H, ir = Last, readings = LastReadings}, Others,
         S = #sim{trace = Trace, faults = Faults, seed = Seed}) ->
    W = torobot_world:set_others(W0, [torobot_world:body(O#bot.world) || O <- Others]),
    case torobot_world:done(W) of
        true ->
            {{B#bot{world = W}, done}, S};
        false ->
            T = torobot_world:time_ms(W),
            Active = torobot_faults:world_faults(Faults, T),
            {Ir, St1} = torobot_faults:readings(ir, torobot_world:ir(W), Active, B#bot.stuck,
                                                {Seed, T}),
            {Readings0, Sensors} = torobot_sensors:read(W, B#bot.sensors),
            {Readings, St2} = torobot_faults:sensor_readings(Readings0, Active, St1, {Seed, T}),
            {Datagrams, Delayed, St4} = torobot_faults:datagrams(torobot_world:camera(W), Active,
                                                                 B#bot.delayed, St2, {Seed, T}),
            {FaultLines, S1} = robot_faults(H, T, S),
            {Wheels, Winner, Lines} =
                torobot_sim_robot:step(H, T, changed(Ir, Last), changed(Readings, LastReadings),
                                       Datagrams),
            Motors = {Wheels, Winner},
            AllLines = FaultLines ++ Lines,
            trace(Trace, torobot_world:name(W), T, AllLines, Motors, B#bot.motors),
            {{B#bot{world = W, ir = maps:merge(Last, Ir), sensors = Sensors,
                    readings = maps:merge(LastReadings, Readings), motors = Motors,
                    stuck = St4, delayed = Delayed, lines = AllLines},
              Motors}, S1}
    end.

%% The robot's faults (kills, suspends and their resumes) due by `T',
%% each at its own simulated instant, with a trace line saying what it is.
robot_faults(H, T, S = #sim{robot_events = Events}) ->
    {Due, Later} = lists:splitwith(fun({Ms, _}) -> Ms =< T end, Events),
    Lines = lists:append([torobot_sim_robot:fault(H, Ms, Event) || {Ms, Event} <- Due]),
    {Lines, S#sim{robot_events = Later}}.

%% What the properties judge (SPEC §17): each robot's tick, after it moved.
observed(_Bots, S = #sim{observing = false}) ->
    S;
observed([#bot{world = W, motors = Motors, lines = Lines}], S = #sim{obs = Obs})
  when Motors =/= none ->
    Last = case Obs of
               [O | _] -> O;
               [] -> none
           end,
    S#sim{obs = [torobot_sim_observation:observation(W, Motors, Lines, Last) | Obs]};
observed(_Bots, S) ->
    S.

%% The readings that changed since the last tick: all a robot is handed,
%% in either clock.
changed(Now, Before) ->
    maps:filter(fun(K, V) -> maps:get(K, Before, undefined) =/= V end, Now).

trace(undefined, _Name, _T, _Lines, _Motors, _Before) ->
    ok;
trace(Fd, Name, T, Lines, Motors, Before) ->
    Prefix = case Name of
                 undefined -> [];
                 _ -> [atom_to_binary(Name), $\s]
             end,
    Wheels = case Motors of
                 Before -> [];
                 {{L, R}, Winner} -> [io_lib:format("~b wheels ~0p ~0p ~0p~n", [T, L, R, Winner])]
             end,
    ok = file:write(Fd, [[Prefix, Line] || Line <- Lines ++ Wheels]).


%% The dashboard's view of the world, through the runtime
%% (toroco:publish_world/1): the snapshot is made only when someone
%% subscribed in this node.
publish(#sim{bots = Bots, t0 = T0, time = Time, marks = Marks}) ->
    toroco:publish_world(fun() ->
                                 torobot_sim_view:snapshot(
                                   {self(), T0}, Time =:= lockstep, Marks,
                                   [{W, Winner} || #bot{world = W, winner = Winner} <- Bots])
                         end).

status(S = #sim{status = false}) ->
    S;
status(S = #sim{bots = Bots, next_status = Next, status = How}) ->
    case lists:max([torobot_world:time_ms(B#bot.world) || B <- Bots]) >= Next of
        true ->
            _ = [torobot_sim_view:status_line(How, W, Winner)
                 || #bot{world = W, winner = Winner} <- Bots],
            S#sim{next_status = Next + 1000};
        false ->
            S
    end.
