%% @doc The owner of the `pru_port' C program: one gen_server per program.
%%
%% It spawns `priv/pru_port' as an Erlang port (`{packet, 2}', terms in the
%% external format on both sides; the frames are in
%% `c_src/pru_port/PROTOCOL.md'), matches replies to requests by reference,
%% and forwards the program's unsolicited events to subscribers as
%% `{toroco_pru_port, Event}'. It keeps the configuration it was given (ADC
%% channels, servo calibrations, watchdog, button, the enable state), so
%% when the program dies it starts a new one and applies that configuration
%% again: the servos come back at neutral, and velocities are never
%% replayed. On terminate it puts the servos at neutral and closes the port,
%% which the program also takes as the signal to go neutral.
%%
%% The device modules (`toroco_pru_sensors', `toroco_servo_motors',
%% `toroco_gpio_button') sit on top of this process; it knows nothing of the
%% runtime's wiring.
%%
%% Functions, by purpose:
%% <ul>
%% <li>life: `start_link/1', `stop/1', `os_pid/1'</li>
%% <li>configuration (remembered, re-applied after a restart):
%%     `configure_adc/2', `configure_servos/2', `enable_servos/2',
%%     `configure_watchdog/2', `configure_button/2'</li>
%% <li>commands: `set_servos/2', `neutral/1', `ping/1', `call/2,3'</li>
%% <li>simulation (sim backend): `sim_adc/3', `sim_button/2'</li>
%% <li>events: `subscribe/1,2', `unsubscribe/1,2'</li>
%% </ul>
-module(toroco_pru_port).
-behaviour(gen_server).

-export([start_link/1, stop/1, os_pid/1,
         configure_adc/2, configure_servos/2, enable_servos/2,
         configure_watchdog/2, configure_button/2,
         set_servos/2, neutral/1, ping/1, call/2, call/3,
         sim_adc/3, sim_button/2,
         subscribe/1, subscribe/2, unsubscribe/1, unsubscribe/2]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2, terminate/2]).

-export_type([server/0, opts/0, adc_channel/0, servo_id/0, servo/0, button/0,
              event/0, request/0]).

-type server() :: pid() | atom() | {global, term()} | {via, module(), term()}.
-type adc_channel() ::
        #{channel := 0..7,
          mode := analog | analog_threshold | off,
          threshold_high => 0..4095,
          threshold_low => 0..4095}.
-type servo_id() :: atom().
%% Pulse widths in ns. neutral_ns is the pulse that stops the servo;
%% span_ns is how far from neutral full speed (velocity +-100) is.
-type servo() :: #{pwmchip := non_neg_integer(),
                   channel := non_neg_integer(),
                   period_ns => pos_integer(),
                   neutral_ns => non_neg_integer(),
                   span_ns => non_neg_integer(),
                   reversed => boolean()}.
%% active_low defaults to true (a button to ground, line pulled up),
%% debounce_ms to 20.
-type button() :: none | #{line := non_neg_integer(),
                           active_low => boolean(),
                           debounce_ms => non_neg_integer()}.
-type opts() :: #{name => atom() | {local, atom()} | {global, term()} | {via, module(), term()},
                  backend => sim | pru,
                  executable => file:filename_all(),
                  sysfs_root => file:filename_all(),
                  gpiochip => file:filename_all(),
                  sim_script => file:filename_all(),
                  remoteproc => file:filename_all(),
                  firmware => string() | binary(),
                  rpmsg_dev => file:filename_all(),
                  watchdog_ms => non_neg_integer(),
                  adc => [adc_channel()],
                  servos => #{servo_id() => servo()},
                  enabled => boolean(),
                  button => button(),
                  max_restarts => {non_neg_integer(), pos_integer()}}.
%% What subscribers receive, as {toroco_pru_port, event()}. Times are the
%% port program's monotonic clock in ms.
-type event() :: {adc, 0..7, non_neg_integer(), integer()}
               | {button, pressed | released, integer()}
               | {watchdog, integer()}
               | {fault, term()}
               | {port_restarted, term()}.
%% A request in the protocol's own terms (see PROTOCOL.md), for call/2.
-type request() :: ping | neutral | tuple().

-define(DEFAULT_PERIOD_NS, 20000000).
-define(DEFAULT_NEUTRAL_NS, 1500000).
-define(DEFAULT_SPAN_NS, 500000).
-define(START_TIMEOUT, 10000).

-record(state, {
          opts :: opts(),
          port :: port() | undefined,
          os_pid :: integer() | undefined,
          next_ref = 1 :: pos_integer(),
          %% Ref => {From, Request}; Request decides what is remembered on ok
          pending = #{} :: #{pos_integer() => {gen_server:from(), request()}},
          subscribers = #{} :: #{pid() => reference()},
          %% the configuration as applied, in wire form
          config :: #{atom() => term()},
          restarts = [] :: [integer()]
         }).
-type state() :: #state{}.

%%% ---------------------------------------------------------------------
%%% API
%%% ---------------------------------------------------------------------

%% @doc Starts the program and applies the configuration in `Opts'. Fails
%% with `{error, {Section, Reason}}' (Section = adc | servos | ...) when the
%% program refuses a part of it, `{error, {port_program, Reason}}' when the
%% program cannot start.
-spec start_link(opts()) -> {ok, pid()} | {error, term()}.
start_link(Opts) when is_map(Opts) ->
    case maps:get(name, Opts, undefined) of
        undefined -> gen_server:start_link(?MODULE, Opts, []);
        Name when is_atom(Name) -> gen_server:start_link({local, Name}, ?MODULE, Opts, []);
        Name -> gen_server:start_link(Name, ?MODULE, Opts, [])
    end.

-spec stop(server()) -> ok.
stop(Server) ->
    gen_server:stop(Server).

%% @doc The OS pid of the running program.
-spec os_pid(server()) -> integer().
os_pid(Server) ->
    gen_server:call(Server, os_pid).

%% @doc Replaces the ADC channel set; remembered when accepted.
-spec configure_adc(server(), [adc_channel()]) -> ok | {error, term()}.
configure_adc(Server, Channels) ->
    case wire_adc(Channels) of
        {ok, Wire} -> call(Server, {configure_adc, Wire});
        Error -> Error
    end.

%% @doc Replaces the servo set (calibrations); each starts at neutral.
-spec configure_servos(server(), #{servo_id() => servo()}) -> ok | {error, term()}.
configure_servos(Server, Servos) ->
    case wire_servos(Servos) of
        {ok, Wire} -> call(Server, {configure_servos, Wire});
        Error -> Error
    end.

%% @doc Velocities in -100..100 by servo; a servo command (kicks the watchdog).
-spec set_servos(server(), #{servo_id() => -100..100}) -> ok | {error, term()}.
set_servos(Server, Velocities) when is_map(Velocities) ->
    call(Server, {set_servos, maps:to_list(Velocities)}).

%% @doc Turns the PWM outputs on or off; remembered, a servo command.
-spec enable_servos(server(), boolean()) -> ok | {error, term()}.
enable_servos(Server, Enable) when is_boolean(Enable) ->
    call(Server, {enable_servos, Enable}).

%% @doc Every servo to its neutral pulse.
-spec neutral(server()) -> ok | {error, term()}.
neutral(Server) ->
    call(Server, neutral).

%% @doc Servos go neutral after `Ms' without a servo command; 0 disables.
-spec configure_watchdog(server(), non_neg_integer()) -> ok | {error, term()}.
configure_watchdog(Server, Ms) ->
    call(Server, {configure_watchdog, Ms}).

-spec configure_button(server(), button()) -> ok | {error, term()}.
configure_button(Server, Button) ->
    case wire_button(Button) of
        {ok, Wire} -> call(Server, Wire);
        Error -> Error
    end.

%% @doc Sim backend: one raw ADC sample (0..4095) on a channel.
-spec sim_adc(server(), 0..7, 0..4095) -> ok | {error, term()}.
sim_adc(Server, Channel, Raw) ->
    call(Server, {sim_adc, Channel, Raw}).

%% @doc Sim backend: the button line's physical level.
-spec sim_button(server(), 0 | 1) -> ok | {error, term()}.
sim_button(Server, Level) ->
    call(Server, {sim_button, Level}).

-spec ping(server()) -> pong | {error, term()}.
ping(Server) ->
    call(Server, ping).

%% @doc One request in protocol terms, answered by the program's result
%% (5 s timeout).
-spec call(server(), request()) -> term().
call(Server, Request) ->
    gen_server:call(Server, {request, Request}, 5000).

-spec call(server(), request(), timeout()) -> term().
call(Server, Request, Timeout) ->
    gen_server:call(Server, {request, Request}, Timeout).

%% @doc Sends `{toroco_pru_port, event()}' to the caller (or Pid) from now on.
-spec subscribe(server()) -> ok.
subscribe(Server) ->
    subscribe(Server, self()).

-spec subscribe(server(), pid()) -> ok.
subscribe(Server, Pid) ->
    gen_server:call(Server, {subscribe, Pid}).

-spec unsubscribe(server()) -> ok.
unsubscribe(Server) ->
    unsubscribe(Server, self()).

-spec unsubscribe(server(), pid()) -> ok.
unsubscribe(Server, Pid) ->
    gen_server:call(Server, {unsubscribe, Pid}).

%%% ---------------------------------------------------------------------
%%% gen_server
%%% ---------------------------------------------------------------------

-spec init(opts()) -> {ok, state()} | {stop, term()}.
init(Opts) ->
    %% so that terminate/2 runs on shutdown and leaves the servos at neutral
    process_flag(trap_exit, true),
    case initial_config(Opts) of
        {ok, Config} ->
            State0 = #state{opts = Opts, config = Config},
            case start_program(State0) of
                {ok, State} -> {ok, State};
                {error, Reason, _} -> {stop, Reason}
            end;
        {error, Reason} ->
            {stop, Reason}
    end.

-spec handle_call(term(), gen_server:from(), state()) ->
          {reply, term(), state()} | {noreply, state()}.
handle_call({request, Request}, From, #state{port = Port, next_ref = Ref} = State) ->
    case send_frame(Port, {Ref, Request}) of
        ok ->
            Pending = maps:put(Ref, {From, Request}, State#state.pending),
            {noreply, State#state{next_ref = Ref + 1, pending = Pending}};
        closed ->
            %% the program just died; its exit_status, queued, restarts it
            {reply, {error, {port_exit, closed}}, State}
    end;
handle_call(os_pid, _From, State) ->
    {reply, State#state.os_pid, State};
handle_call({subscribe, Pid}, _From, #state{subscribers = Subs} = State) ->
    case maps:is_key(Pid, Subs) of
        true -> {reply, ok, State};
        false -> {reply, ok, State#state{subscribers = Subs#{Pid => monitor(process, Pid)}}}
    end;
handle_call({unsubscribe, Pid}, _From, #state{subscribers = Subs} = State) ->
    case maps:take(Pid, Subs) of
        {MRef, Rest} ->
            demonitor(MRef, [flush]),
            {reply, ok, State#state{subscribers = Rest}};
        error ->
            {reply, ok, State}
    end;
handle_call(Other, _From, State) ->
    {reply, {error, {unknown_call, Other}}, State}.

-spec handle_cast(term(), state()) -> {noreply, state()}.
handle_cast(_Msg, State) ->
    {noreply, State}.

-spec handle_info(term(), state()) -> {noreply, state()} | {stop, term(), state()}.
handle_info({Port, {data, Bin}}, #state{port = Port} = State) ->
    {noreply, from_program(binary_to_term(Bin), State)};
handle_info({Port, {exit_status, Status}}, #state{port = Port} = State) ->
    restart({exit_status, Status}, State);
handle_info({'EXIT', Port, Reason}, #state{port = Port} = State) ->
    %% the port closed without an exit status (e.g. its pipe broke)
    restart({port_exit, Reason}, State);
handle_info({'EXIT', _OldPort, _}, State) ->
    {noreply, State};
handle_info({'DOWN', MRef, process, Pid, _}, #state{subscribers = Subs} = State) ->
    case maps:get(Pid, Subs, undefined) of
        MRef -> {noreply, State#state{subscribers = maps:remove(Pid, Subs)}};
        _ -> {noreply, State}
    end;
handle_info(_Other, State) ->
    {noreply, State}.

-spec terminate(term(), state()) -> ok.
terminate(_Reason, #state{port = undefined}) ->
    ok;
terminate(_Reason, #state{port = Port} = State) ->
    %% Neutral first, explicitly; closing the port (stdin EOF) makes the
    %% program do it again on its way out, should this reply never come.
    _ = sync_request(neutral, 1000, State),
    catch port_close(Port),
    ok.

%%% ---------------------------------------------------------------------
%%% The program: start, configure, restart
%%% ---------------------------------------------------------------------

-spec start_program(state()) -> {ok, state()} | {error, term(), state()}.
start_program(#state{opts = Opts} = State) ->
    case executable(Opts) of
        {ok, Exe} ->
            Port = open_port({spawn_executable, Exe},
                             [{packet, 2}, binary, exit_status, use_stdio,
                              {args, program_args(Opts)}]),
            {os_pid, OsPid} = erlang:port_info(Port, os_pid),
            State1 = State#state{port = Port, os_pid = OsPid},
            case await_hello(Port) of
                ok -> apply_config(State1);
                {error, Reason} -> {error, {port_program, Reason}, State1#state{port = undefined}}
            end;
        {error, Reason} ->
            {error, Reason, State}
    end.

-spec await_hello(port()) -> ok | {error, term()}.
await_hello(Port) ->
    receive
        {Port, {data, Bin}} ->
            case binary_to_term(Bin) of
                {hello, 1, _Backend} -> ok;
                {fatal, Reason} -> await_exit(Port, Reason);
                Other -> {error, {unexpected, Other}}
            end;
        {Port, {exit_status, Status}} ->
            {error, {exit_status, Status}}
    after ?START_TIMEOUT ->
            catch port_close(Port),
            {error, start_timeout}
    end.

-spec await_exit(port(), term()) -> {error, term()}.
await_exit(Port, Reason) ->
    receive
        {Port, {exit_status, _}} -> {error, Reason}
    after 1000 ->
            catch port_close(Port),
            {error, Reason}
    end.

%% Each section in a fixed order: the watchdog and servos first so that
%% outputs are safe before any input starts reporting.
-spec apply_config(state()) -> {ok, state()} | {error, term(), state()}.
apply_config(#state{config = Config} = State) ->
    Steps = [{watchdog, {configure_watchdog, maps:get(watchdog, Config)}},
             {servos, {configure_servos, maps:get(servos, Config)}},
             {enabled, {enable_servos, maps:get(enabled, Config)}},
             {adc, {configure_adc, maps:get(adc, Config)}},
             {button, maps:get(button, Config)}],
    apply_steps(Steps, State).

-spec apply_steps([{atom(), request()}], state()) -> {ok, state()} | {error, term(), state()}.
apply_steps([], State) ->
    {ok, State};
apply_steps([{enabled, {enable_servos, false}} | Rest], State) ->
    %% servos start disabled; saying so again would only arm the watchdog
    apply_steps(Rest, State);
apply_steps([{button, {configure_button, none}} | Rest], State) ->
    apply_steps(Rest, State);
apply_steps([{Section, Request} | Rest], State) ->
    case sync_request(Request, ?START_TIMEOUT, State) of
        {ok, State1} -> apply_steps(Rest, State1);
        {{error, Reason}, State1} -> {error, {Section, Reason}, State1};
        {Other, State1} -> {error, {Section, Other}, State1}
    end.

%% A request answered before anything else is handled; events that arrive
%% meanwhile are dispatched as usual.
-spec sync_request(request(), timeout(), state()) -> {term(), state()}.
sync_request(Request, Timeout, #state{port = Port, next_ref = Ref} = State0) ->
    State = State0#state{next_ref = Ref + 1},
    case send_frame(Port, {Ref, Request}) of
        ok ->
            Deadline = erlang:monotonic_time(millisecond) + Timeout,
            await_reply(Ref, Deadline, State);
        closed ->
            {{error, {port_exit, closed}}, State}
    end.

%% A port whose program has died is closed before its exit_status is
%% handled: writing to it then is not an error of this process.
-spec send_frame(port(), {pos_integer(), request()}) -> ok | closed.
send_frame(Port, Frame) ->
    try port_command(Port, term_to_binary(Frame)) of
        true -> ok
    catch
        error:badarg -> closed
    end.

-spec await_reply(pos_integer(), integer(), state()) -> {term(), state()}.
await_reply(Ref, Deadline, #state{port = Port} = State) ->
    Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
    receive
        {Port, {data, Bin}} ->
            case binary_to_term(Bin) of
                {reply, Ref, Result} -> {Result, State};
                Other -> await_reply(Ref, Deadline, from_program(Other, State))
            end;
        {Port, {exit_status, Status}} ->
            %% put back for handle_info, which owns restarting
            self() ! {Port, {exit_status, Status}},
            {{error, {exit_status, Status}}, State}
    after Left ->
            {{error, timeout}, State}
    end.

-spec restart(term(), state()) -> {noreply, state()} | {stop, term(), state()}.
restart(Why, #state{opts = Opts, pending = Pending, restarts = Restarts} = State0) ->
    logger:warning("pru_port program ended (~0p); restarting it", [Why],
                   #{domain => [toroco, hw, pru_port]}),
    maps:foreach(fun(_Ref, {From, _}) -> gen_server:reply(From, {error, {port_exit, Why}}) end,
                 Pending),
    catch port_close(State0#state.port),
    {MaxR, WindowMs} = maps:get(max_restarts, Opts, {5, 10000}),
    Now = erlang:monotonic_time(millisecond),
    Recent = [T || T <- Restarts, Now - T < WindowMs],
    State = State0#state{port = undefined, os_pid = undefined, pending = #{},
                         restarts = [Now | Recent]},
    case length(Recent) >= MaxR of
        true ->
            logger:error("pru_port program failed ~b times within ~b ms; giving up",
                         [length(Recent) + 1, WindowMs], #{domain => [toroco, hw, pru_port]}),
            {stop, {port_program_failed, Why}, State};
        false ->
            case start_program(State) of
                {ok, State1} ->
                    notify({port_restarted, Why}, State1),
                    {noreply, State1};
                {error, Reason, State1} ->
                    {stop, {port_restart_failed, Reason}, State1}
            end
    end.

%%% ---------------------------------------------------------------------
%%% What the program sends
%%% ---------------------------------------------------------------------

-spec from_program(term(), state()) -> state().
from_program({reply, Ref, Result}, #state{pending = Pending} = State) ->
    case maps:take(Ref, Pending) of
        {{From, Request}, Rest} ->
            gen_server:reply(From, Result),
            remember(Request, Result, State#state{pending = Rest});
        error ->
            State
    end;
from_program({adc, _, _, _} = Event, State) ->
    notify(Event, State),
    State;
from_program({button, _, _} = Event, State) ->
    notify(Event, State),
    State;
from_program({watchdog, _} = Event, State) ->
    logger:notice("pru_port watchdog: no servo command in time, servos at neutral", [],
                  #{domain => [toroco, hw, pru_port]}),
    notify(Event, State),
    State;
from_program({fault, Reason} = Event, State) ->
    logger:warning("pru_port fault: ~0p", [Reason], #{domain => [toroco, hw, pru_port]}),
    notify(Event, State),
    State;
from_program({error, {bad_frame, Why}}, State) ->
    logger:error("pru_port refused a frame from this process (~0p)", [Why],
                 #{domain => [toroco, hw, pru_port]}),
    State;
from_program(Other, State) ->
    logger:warning("pru_port sent an unexpected term: ~0p", [Other],
                   #{domain => [toroco, hw, pru_port]}),
    State.

-spec notify(event(), state()) -> ok.
notify(Event, #state{subscribers = Subs}) ->
    maps:foreach(fun(Pid, _) -> Pid ! {toroco_pru_port, Event} end, Subs).

%% Accepted configuration requests become the configuration re-applied
%% after a restart.
-spec remember(request(), term(), state()) -> state().
remember(Request, ok, #state{config = Config} = State) ->
    case Request of
        {configure_adc, Wire} -> State#state{config = Config#{adc := Wire}};
        {configure_servos, Wire} -> State#state{config = Config#{servos := Wire}};
        {enable_servos, On} -> State#state{config = Config#{enabled := On}};
        {configure_watchdog, Ms} -> State#state{config = Config#{watchdog := Ms}};
        {configure_button, _} = B -> State#state{config = Config#{button := B}};
        {configure_button, _, _, _} = B -> State#state{config = Config#{button := B}};
        _ -> State
    end;
remember(_Request, _Result, State) ->
    State.

%%% ---------------------------------------------------------------------
%%% Options to command line and wire terms
%%% ---------------------------------------------------------------------

-spec executable(opts()) -> {ok, file:filename_all()} | {error, term()}.
executable(#{executable := Exe}) ->
    {ok, Exe};
executable(_) ->
    case code:priv_dir(toroco_hw) of
        {error, _} -> {error, {no_priv_dir, toroco_hw}};
        Dir -> {ok, filename:join(Dir, "pru_port")}
    end.

-spec program_args(opts()) -> [string() | binary()].
program_args(Opts) ->
    Flags = [{backend, "--backend"}, {sysfs_root, "--sysfs-root"}, {gpiochip, "--gpiochip"},
             {sim_script, "--sim-script"}, {remoteproc, "--remoteproc"},
             {firmware, "--firmware"}, {rpmsg_dev, "--rpmsg-dev"}],
    lists:append([[Flag, arg(V)] || {Key, Flag} <- Flags, {ok, V} <- [maps:find(Key, Opts)]]).

-spec arg(atom() | string() | binary()) -> string() | binary().
arg(A) when is_atom(A) -> atom_to_list(A);
arg(S) -> S.

-spec initial_config(opts()) -> {ok, #{atom() => term()}} | {error, term()}.
initial_config(Opts) ->
    maybe_all([{adc, fun() -> wire_adc(maps:get(adc, Opts, [])) end},
               {servos, fun() -> wire_servos(maps:get(servos, Opts, #{})) end},
               {button, fun() -> wire_button(maps:get(button, Opts, none)) end}],
              #{watchdog => maps:get(watchdog_ms, Opts, 0),
                enabled => maps:get(enabled, Opts, false)}).

-spec maybe_all([{atom(), fun(() -> {ok, term()} | {error, term()})}], map()) ->
          {ok, map()} | {error, term()}.
maybe_all([], Acc) ->
    {ok, Acc};
maybe_all([{Key, F} | Rest], Acc) ->
    case F() of
        {ok, V} -> maybe_all(Rest, Acc#{Key => V});
        {error, Reason} -> {error, {Key, Reason}}
    end.

-spec wire_adc([adc_channel()]) -> {ok, [tuple()]} | {error, term()}.
wire_adc(Channels) when is_list(Channels) ->
    map_ok(fun wire_channel/1, Channels);
wire_adc(Other) ->
    {error, {bad_adc_channels, Other}}.

-spec wire_channel(adc_channel()) -> {ok, tuple()} | {error, term()}.
wire_channel(#{channel := Ch, mode := analog_threshold,
               threshold_high := High, threshold_low := Low}) ->
    {ok, {Ch, analog_threshold, High, Low}};
wire_channel(#{channel := Ch, mode := Mode}) when Mode =:= analog; Mode =:= off ->
    {ok, {Ch, Mode}};
wire_channel(Other) ->
    {error, {bad_adc_channel, Other}}.

-spec wire_servos(#{servo_id() => servo()}) -> {ok, [tuple()]} | {error, term()}.
wire_servos(Servos) when is_map(Servos) ->
    map_ok(fun wire_servo/1, lists:sort(maps:to_list(Servos)));
wire_servos(Other) ->
    {error, {bad_servos, Other}}.

-spec wire_servo({servo_id(), servo()}) -> {ok, tuple()} | {error, term()}.
wire_servo({Id, #{pwmchip := Chip, channel := Ch} = S}) when is_atom(Id) ->
    {ok, {Id, Chip, Ch,
          maps:get(period_ns, S, ?DEFAULT_PERIOD_NS),
          maps:get(neutral_ns, S, ?DEFAULT_NEUTRAL_NS),
          maps:get(span_ns, S, ?DEFAULT_SPAN_NS),
          maps:get(reversed, S, false)}};
wire_servo({Id, Other}) ->
    {error, {bad_servo, Id, Other}}.

-spec wire_button(button()) -> {ok, tuple()} | {error, term()}.
wire_button(none) ->
    {ok, {configure_button, none}};
wire_button(#{line := Line} = B) ->
    {ok, {configure_button, Line, maps:get(active_low, B, true), maps:get(debounce_ms, B, 20)}};
wire_button(Other) ->
    {error, {bad_button, Other}}.

-spec map_ok(fun((A) -> {ok, B} | {error, term()}), [A]) -> {ok, [B]} | {error, term()}.
map_ok(F, List) ->
    lists:foldr(fun(_, {error, _} = E) -> E;
                   (X, {ok, Acc}) ->
                        case F(X) of
                            {ok, Y} -> {ok, [Y | Acc]};
                            {error, _} = E -> E
                        end
                end, {ok, []}, List).
