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

-export([run/2, simulate/2, summary_json/1, batch/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([opts/0, status/0, world_spec/0, summary/0]).

-type status() :: boolean() | tty | fun((iodata()) -> any()).
-type opts() :: #{svg => file:name_all(), wiring => file:name_all(), status => status(),
                  speed => number(), nodes => local | peer, time => realtime | lockstep,
                  trace => file:name_all(), lua => file:name_all()}.
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
              motors = none :: none | {{number(), number()}, atom()}}).

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
              published = 0 :: integer()}).

-define(OPTIONS, [svg, wiring, status, speed, nodes, time, trace, lua]).

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
    WiringFile = maps:get(wiring, Opts,
                          case Opts of
                              #{lua := _} -> "config/torobot_lua.wiring";
                              #{} -> application:get_env(torobot, wiring, "config/torobot.wiring")
                          end),
    Speed = maps:get(speed, Opts, 1),
    Time = maps:get(time, Opts, realtime),
    Trace = maps:get(trace, Opts, undefined),
    Unknown = lists:sort(maps:keys(Opts) -- ?OPTIONS),
    case {load(WorldSpec), file:consult(WiringFile)} of
        _ when Unknown =/= [] ->
            {error, {bad_option, hd(Unknown)}};
        _ when Time =/= realtime, Time =/= lockstep ->
            {error, {time, Time}};
        _ when Trace =/= undefined, Time =/= lockstep; Trace =/= undefined,
                                                     not (is_list(Trace) orelse is_binary(Trace)) ->
            {error, {trace, Trace}};
        {{error, Reason}, _} ->
            {error, {world, WorldSpec, Reason}};
        {_, {error, Reason}} ->
            {error, {wiring, WiringFile, Reason}};
        {_, _} when not is_number(Speed); Speed =< 0 ->
            {error, {speed, Speed}};
        {{ok, Worlds}, {ok, _}} ->
            Named = torobot_world:name(hd(Worlds)) =/= undefined,
            Nodes = maps:get(nodes, Opts, case Named of
                                              true -> peer;
                                              false -> local
                                          end),
            case with_robots(Worlds, Nodes, Opts#{wiring => WiringFile, speed => Speed,
                                                  time => Time}) of
                {ok, [Final]} when not Named -> {ok, Final};
                {ok, Finals} -> {ok, Finals};
                {error, _} = Error -> Error
            end
    end.

%% @doc The summary as one JSON object (`none' as `null'); a world's own
%% figures (`torobot_sensors', and `robot_contacts' for a named robot)
%% follow the Torobot's keys. A world of named robots gives one object
%% with a member per robot.
-spec summary_json(summary()) -> binary().
summary_json(Summary) ->
    iolist_to_binary(jiffy:encode(summary_value(Summary))).

-define(TOROBOT_KEYS, [red_touched_ms, wall_contacts, blue_contacts, distance_m]).

%% The summary for `jiffy', its keys in order; floats with three decimals.
-spec summary_value(summary()) -> jiffy:json_value().
summary_value(#{red_touched_ms := _, wall_contacts := _, blue_contacts := _,
                distance_m := Distance} = Summary) ->
    {[{K, figure_value(maps:get(K, Summary))} || K <- ?TOROBOT_KEYS, K =/= distance_m]
     ++ [{distance_m, figure_value(float(Distance))}
         | [{K, figure_value(V)}
            || {K, V} <- lists:sort(maps:to_list(maps:without(?TOROBOT_KEYS, Summary)))]]};
summary_value(PerRobot) when is_map(PerRobot) ->
    {[{Name, summary_value(S)} || {Name, S} <- lists:sort(maps:to_list(PerRobot))]}.

-spec figure_value(term()) -> jiffy:json_value().
figure_value(none) -> null;
figure_value(V) when is_integer(V) -> V;
figure_value(V) when is_float(V) -> binary_to_float(float_to_binary(V, [{decimals, 3}]));
figure_value(V) -> iolist_to_binary(io_lib:format("~0p", [V])).

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
                                           torobot_world:tick_ms(hd(Worlds)), Time, Trace}, []),
    MRef = monitor(process, Sim),
    RobotOpts0 = #{wiring => WiringFile, speed => Speed, time => Time,
                  trace => Trace =/= undefined,
                  thresholds => torobot_world:ir_thresholds(hd(Worlds)),
                  sensors => [{Name, Outputs(hd(Worlds))}
                              || {Name, Outputs} <- torobot_sensors:devices()]},
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
        %% as real time would take, it is stuck
        Timeout = case Time of
                      realtime -> round(torobot_world:duration_ms(hd(Worlds)) / Speed);
                      lockstep -> torobot_world:duration_ms(hd(Worlds))
                  end + ?GRACE_MS,
        receive
            {?MODULE, Sim, {done, Finals}} ->
                demonitor(MRef, [flush]),
                case svg(Finals, Opts) of
                    ok -> {ok, Finals};
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
            file:name_all() | undefined}) -> {ok, #sim{}} | {stop, term()}.
init({Caller, Status, Speed, Tick, Time, TracePath}) ->
    monitor(process, Caller),
    S = #sim{caller = Caller, status = Status, speed = Speed, tick = Tick, time = Time},
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
    Stepped = lockstep(Bots, S),
    Commands = [case Motors of
                    done -> done;
                    _ -> Motors
                end || {_, Motors} <- Stepped],
    S1 = status(S#sim{bots = move([B || {B, _} <- Stepped], Commands, Tick)}),
    next(publish_paced(S1), fun(S2) -> self() ! lockstep, S2 end);
handle_info({'DOWN', _, process, Caller, _}, S = #sim{caller = Caller}) ->
    {stop, normal, S};
handle_info(_Info, S) ->
    {noreply, S}.

-spec terminate(term(), #sim{}) -> ok.
terminate(_Reason, #sim{sock = Sock, status = Status, trace = Trace}) ->
    case Sock of
        undefined -> ok;
        _ -> gen_udp:close(Sock)
    end,
    case Trace of
        undefined -> ok;
        _ -> ok = file:close(Trace)
    end,
    case Status of
        tty -> io:put_chars("\n");
        _ -> ok
    end.

%% After a tick: the caller has the final worlds once every robot is done,
%% else the next tick is asked for.
next(S = #sim{bots = Bots, caller = Caller}, Again) ->
    Worlds = [W || #bot{world = W} <- Bots],
    case lists:all(fun torobot_world:done/1, Worlds) of
        true ->
            Caller ! {?MODULE, self(), {done, Worlds}},
            {stop, normal, S};
        false ->
            {noreply, Again(S)}
    end.

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
%% now (the others where they are) and answers once quiescent.
lockstep(Bots, S) ->
    [lockstep(B, [O || O <- Bots, O =/= B], S) || B <- Bots].

lockstep(B = #bot{world = W0, handle = H, ir = Last, readings = LastReadings}, Others,
         #sim{trace = Trace}) ->
    W = torobot_world:set_others(W0, [torobot_world:body(O#bot.world) || O <- Others]),
    case torobot_world:done(W) of
        true ->
            {B#bot{world = W}, done};
        false ->
            T = torobot_world:time_ms(W),
            Ir = torobot_world:ir(W),
            {Readings, Sensors} = torobot_sensors:read(W, B#bot.sensors),
            {Wheels, Winner, Lines} =
                torobot_sim_robot:step(H, T, changed(Ir, Last), changed(Readings, LastReadings),
                                       torobot_world:camera(W)),
            Motors = {Wheels, Winner},
            trace(Trace, torobot_world:name(W), T, Lines, Motors, B#bot.motors),
            {B#bot{world = W, ir = Ir, sensors = Sensors, readings = Readings, motors = Motors},
             Motors}
    end.

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

%% The dashboard's view, at most 20 times a second of real time however
%% fast the world goes.
publish_paced(S = #sim{published = Last}) ->
    Now = erlang:monotonic_time(millisecond),
    case Now - Last >= 50 of
        true -> publish(S), S#sim{published = Now};
        false -> S
    end.

%% The dashboard's view of the world (toroco_live_world's message, written
%% down there): a plain send, and only when toroco_live runs in this node.
%% A robot of the one-robot form is named `torobot'.
publish(#sim{bots = Bots, t0 = T0}) ->
    case whereis(toroco_live_world) of
        undefined ->
            ok;
        Viewer ->
            [#bot{world = W} | _] = Bots,
            Robots = [begin
                          #{ir := Ir, camera := Camera} = torobot_world:view(R),
                          #{name => case torobot_world:name(R) of
                                        undefined -> torobot;
                                        Name -> Name
                                    end,
                            pose => torobot_world:pose(R),
                            radius => torobot_world:robot_radius(R), winner => Winner,
                            ir => Ir, camera => Camera}
                      end || #bot{world = R, winner = Winner} <- Bots],
            Viewer ! {toroco_live_world, snapshot,
                      #{run => {self(), T0},
                        t_ms => lists:max([torobot_world:time_ms(B#bot.world) || B <- Bots]),
                        arena => torobot_world:arena(W), walls => torobot_world:walls(W),
                        objects => torobot_world:objects(W), robots => Robots}},
            ok
    end.

status(S = #sim{status = false}) ->
    S;
status(S = #sim{bots = Bots, next_status = Next, status = How}) ->
    case lists:max([torobot_world:time_ms(B#bot.world) || B <- Bots]) >= Next of
        true ->
            _ = [line(How, Bot) || Bot <- Bots],
            S#sim{next_status = Next + 1000};
        false ->
            S
    end.

line(How, #bot{world = W, winner = Winner}) ->
    {X, Y, H} = torobot_world:pose(W),
    Name = case torobot_world:name(W) of
               undefined -> "";
               N -> io_lib:format("~s  ", [N])
           end,
    Line = io_lib:format("~st ~5.1f s  ~-13s x ~4.2f  y ~4.2f  heading ~4b",
                         [Name, torobot_world:time_ms(W) / 1000, Winner, X, Y, round(H)]),
    case How of
        true -> io:put_chars([Line, "\n"]);
        tty -> io:put_chars(["\r", Line]);
        Fun when is_function(Fun, 1) -> Fun(Line)
    end.
