%% @doc The owner of the `pru_port' C program: one gen_statem per program.
%%
%% It spawns `priv/pru_port' as an Erlang port (`{packet, 2}', terms in the
%% external format on both sides; the frames are in
%% `c_src/pru_port/PROTOCOL.md'), matches replies to requests by reference,
%% and forwards the program's unsolicited events to subscribers as
%% `{toroco_pru_port, Event}'. It keeps the configuration it was given (ADC
%% channels, servo calibrations, watchdog, button, the enable state), so
%% when the program dies it starts a new one and applies that configuration
%% again: the servos come back at neutral, and velocities are never
%% replayed. On terminate it commands neutral and closes the port, which the
%% program also takes as the signal to go neutral.
%%
%% This process is the one that must stop the motors, so no callback ever
%% waits for the program: the hello, each configuration step and each reply
%% are states and data, and the process answers every call meanwhile.
%%
%% States:
%% <table>
%% <tr><th>state</th><th>what it waits for</th><th>leaves on</th></tr>
%% <tr><td>`connecting'</td><td>the delay before (re)starting the program
%%   (`restart_backoff'), then the program's `{hello, 1, Backend}' (at most
%%   `hello_timeout_ms')</td><td>hello: `configuring'; no hello in time, an
%%   exit or an unexpected frame: the program is killed and `connecting'
%%   again, later</td></tr>
%% <tr><td>`configuring'</td><td>the reply to each configuration step in
%%   turn: watchdog, servos, `neutral', enable, ADC, button (each at most
%%   `reply_timeout_ms')</td><td>the last reply: `running'; an exit or a
%%   step timeout: `connecting'; a refused step: stop (the first start:
%%   `start_link/1' returns the error)</td></tr>
%% <tr><td>`running'</td><td>requests, replies, events</td><td>an exit:
%%   `connecting'</td></tr>
%% </table>
%% The first restart after a program that was `running' is immediate; each
%% further program that does not reach `running' doubles the delay, from
%% the first to the last of `restart_backoff' (default `{100, 5000}' ms).
%% More than `max_restarts' `{N, WindowMs}' (default `{5, 10000}') restarts
%% stop the process (`{port_program_failed, Why}'). `info/1' counts them.
%%
%% Messages (callers' calls, and what each gets while not `running'):
%% <table>
%% <tr><th>message</th><th>from</th><th>`running'</th><th>`connecting',
%%   `configuring'</th></tr>
%% <tr><td>`{request, R}', R a configuration (`configure_adc',
%%   `configure_servos', `configure_watchdog', `configure_button')</td>
%%   <td>devices attaching</td><td>sent; the reply when it comes; remembered
%%   when `ok'</td><td>postponed until `running' (it changes what a
%%   restart re-applies, so it follows the re-applied configuration)</td></tr>
%% <tr><td>`{request, neutral}'</td><td>devices, terminate</td><td>sent</td>
%%   <td>postponed; the program is commanded neutral anyway as the first
%%   servo command after its servos are configured</td></tr>
%% <tr><td>`{request, R}', any other (`set_servos', `enable_servos',
%%   `ping', `sim_adc', `sim_button', unknown)</td><td>devices, tests</td>
%%   <td>sent</td><td>`{error, {connecting, Phase}}' at once, Phase
%%   `restart_backoff' | `awaiting_hello' | `configuring': a velocity is
%%   not kept for later, and the servo device must not wait</td></tr>
%% <tr><td>`os_pid'</td><td>tests, operators</td><td>the pid</td>
%%   <td>postponed (the pid of a running program)</td></tr>
%% <tr><td>`info', `{subscribe, Pid}', `{unsubscribe, Pid}'</td>
%%   <td>anyone</td><td colspan="2">answered at once</td></tr>
%% <tr><td>`await_start'</td><td>`start_link/1', in the caller</td>
%%   <td>`ok'</td><td>answered when the first program is `running', or
%%   with the error that ended the first start</td></tr>
%% <tr><td>`{toroco_pru_port, event()}'</td><td>this process</td>
%%   <td colspan="2">to each subscriber; `{port_restarted, Why}' once a
%%   restarted program is `running'</td></tr>
%% </table>
%% `start_link/1' waits in the caller (not in this process) until the first
%% program is configured, so a refused configuration is still its error;
%% the first start is not retried.
%%
%% The device modules (`toroco_pru_sensors', `toroco_servo_motors',
%% `toroco_gpio_button') sit on top of this process; it knows nothing of the
%% runtime's wiring. Beside it, `toroco_pru_port_config' holds its pure
%% parts (the options checked and in wire form, the configuration steps,
%% what a restart re-applies, the backoff) and `toroco_pru_port_program'
%% the program's side (open, frame, close, kill; its events passed on).
%%
%% Functions, by purpose:
%% <ul>
%% <li>life: `start_link/1', `stop/1', `os_pid/1', `info/1'</li>
%% <li>configuration (remembered, re-applied after a restart):
%%     `configure_adc/2', `configure_servos/2', `enable_servos/2',
%%     `configure_watchdog/2', `configure_button/2'</li>
%% <li>commands: `set_servos/2', `neutral/1', `ping/1', `call/2,3'</li>
%% <li>simulation (sim backend): `sim_adc/3', `sim_button/2'</li>
%% <li>events: `subscribe/1,2', `unsubscribe/1,2'</li>
%% </ul>
-module(toroco_pru_port).
-behaviour(gen_statem).

-export([start_link/1, stop/1, os_pid/1, info/1,
         configure_adc/2, configure_servos/2, enable_servos/2,
         configure_watchdog/2, configure_button/2,
         set_servos/2, neutral/1, ping/1, call/2, call/3,
         sim_adc/3, sim_button/2,
         subscribe/1, subscribe/2, unsubscribe/1, unsubscribe/2]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).

-export_type([server/0, opts/0, adc_channel/0, servo_id/0, servo/0, button/0,
              event/0, request/0, phase/0]).

-type server() :: pid() | atom() | {global, term()} | {via, module(), term()}.
%% The options and their parts are checked, and turned into the
%% program's terms, by toroco_pru_port_config.
-type opts() :: toroco_pru_port_config:opts().
-type adc_channel() :: toroco_pru_port_config:adc_channel().
-type servo_id() :: toroco_pru_port_config:servo_id().
-type servo() :: toroco_pru_port_config:servo().
-type button() :: toroco_pru_port_config:button().
%% What subscribers receive, as {toroco_pru_port, event()}. Times are the
%% port program's monotonic clock in ms.
-type event() :: {adc, 0..7, non_neg_integer(), integer()}
               | {button, pressed | released, integer()}
               | {watchdog, integer()}
               | {fault, term()}
               | {port_restarted, term()}.
%% A request in the protocol's own terms (see PROTOCOL.md), for call/2.
-type request() :: ping | neutral | tuple().
%% Where a program that is not running yet is: what `{error, {connecting,
%% Phase}}' says.
-type phase() :: restart_backoff | awaiting_hello | configuring | start_failed.
-type state() :: connecting | configuring | running.

-define(HELLO_TIMEOUT, 10000).
-define(REPLY_TIMEOUT, 10000).
-define(BACKOFF, {100, 5000}).
-define(LOG, #{domain => [toroco, hw, pru_port]}).

-record(data, {
          opts :: opts(),
          %% the configuration as applied, in wire form
          config :: toroco_pru_port_config:config(),
          port :: port() | undefined,
          os_pid :: integer() | undefined,
          %% connecting: what the program said before it exited
          fatal :: term() | undefined,
          next_ref = 1 :: pos_integer(),
          %% running: Ref => {From, Request}; Request decides what is
          %% remembered on ok
          pending = #{} :: #{pos_integer() => {gen_statem:from(), request()}},
          %% configuring: the step in flight and those after it
          step :: {pos_integer(), atom()} | undefined,
          steps = [] :: [{atom(), request()}],
          subscribers = #{} :: #{pid() => reference()},
          %% the first start: who waits for it, or why it failed
          start = {awaiting, []} :: {awaiting, [gen_statem:from()]} | {failed, term()} | done,
          %% why the last running program ended (the port_restarted event)
          down_why :: term(),
          %% when restarts were scheduled, for max_restarts
          restart_times = [] :: [integer()],
          %% programs in a row that did not reach running
          failures = 0 :: non_neg_integer(),
          counters = #{restarts => 0, hello_timeouts => 0, failed_starts => 0,
                       backoff_ms => 0} :: #{atom() => non_neg_integer()}
         }).
-type data() :: #data{}.

%%% ---------------------------------------------------------------------
%%% API
%%% ---------------------------------------------------------------------

%% @doc Starts the program and applies the configuration in `Opts'. Fails
%% with `{error, {Section, Reason}}' (Section = adc | servos | ...) when the
%% program refuses a part of it, `{error, {port_program, Reason}}' when the
%% program cannot start (`start_timeout' when it sends no hello within
%% `hello_timeout_ms'). The caller waits for that outcome; the owner itself
%% answers calls meanwhile. A refused start ends the owner with reason
%% `normal'.
-spec start_link(opts()) -> {ok, pid()} | {error, term()}.
start_link(Opts) when is_map(Opts) ->
    Started = case maps:get(name, Opts, undefined) of
                  undefined -> gen_statem:start_link(?MODULE, Opts, []);
                  Name when is_atom(Name) -> gen_statem:start_link({local, Name}, ?MODULE, Opts, []);
                  Name -> gen_statem:start_link(Name, ?MODULE, Opts, [])
              end,
    case Started of
        {ok, Pid} -> await_start(Pid);
        Other -> Other
    end.

%% The first program configured, or the reason it was not; a refused owner
%% is gone (its name free again) when this returns.
-spec await_start(pid()) -> {ok, pid()} | {error, term()}.
await_start(Pid) ->
    MRef = monitor(process, Pid),
    Result = try gen_statem:call(Pid, await_start, infinity)
             catch exit:{Reason, _} -> {error, {port_owner, Reason}}
             end,
    case Result of
        ok ->
            demonitor(MRef, [flush]),
            {ok, Pid};
        {error, _} = Error ->
            receive {'DOWN', MRef, process, Pid, _} -> ok after 5000 -> ok end,
            Error
    end.

-spec stop(server()) -> ok.
stop(Server) ->
    gen_statem:stop(Server).

%% @doc The OS pid of the running program (waits while a program starts).
-spec os_pid(server()) -> integer().
os_pid(Server) ->
    gen_statem:call(Server, os_pid).

%% @doc The state, the current program's OS pid (or `undefined') and the
%% counters: `restarts' (programs started after the first),
%% `hello_timeouts', `failed_starts' (programs that never reached running),
%% `backoff_ms' (the delay before the last restart), `failures' (in a row
%% now), `pending' (requests in flight), `subscribers'.
-spec info(server()) -> #{state := state(), atom() => term()}.
info(Server) ->
    gen_statem:call(Server, info).

%% @doc Replaces the ADC channel set; remembered when accepted.
-spec configure_adc(server(), [adc_channel()]) -> ok | {error, term()}.
configure_adc(Server, Channels) ->
    case toroco_pru_port_config:wire_adc(Channels) of
        {ok, Wire} -> call(Server, {configure_adc, Wire});
        Error -> Error
    end.

%% @doc Replaces the servo set (calibrations); each starts at neutral.
-spec configure_servos(server(), #{servo_id() => servo()}) -> ok | {error, term()}.
configure_servos(Server, Servos) ->
    case toroco_pru_port_config:wire_servos(Servos) of
        {ok, Wire} -> call(Server, {configure_servos, Wire});
        Error -> Error
    end.

%% @doc Velocities in -100..100 by servo; a servo command (kicks the
%% watchdog). While no program runs: `{error, {connecting, Phase}}' at once.
-spec set_servos(server(), #{servo_id() => -100..100}) -> ok | {error, term()}.
set_servos(Server, Velocities) when is_map(Velocities) ->
    call(Server, {set_servos, maps:to_list(Velocities)}).

%% @doc Turns the PWM outputs on or off; remembered, a servo command.
-spec enable_servos(server(), boolean()) -> ok | {error, term()}.
enable_servos(Server, Enable) when is_boolean(Enable) ->
    call(Server, {enable_servos, Enable}).

%% @doc Every servo to its neutral pulse (answered once a program has done
%% it, when one is starting).
-spec neutral(server()) -> ok | {error, term()}.
neutral(Server) ->
    call(Server, neutral).

%% @doc Servos go neutral after `Ms' without a servo command; 0 disables.
-spec configure_watchdog(server(), non_neg_integer()) -> ok | {error, term()}.
configure_watchdog(Server, Ms) ->
    call(Server, {configure_watchdog, Ms}).

-spec configure_button(server(), button()) -> ok | {error, term()}.
configure_button(Server, Button) ->
    case toroco_pru_port_config:wire_button(Button) of
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
    gen_statem:call(Server, {request, Request}, 5000).

-spec call(server(), request(), timeout()) -> term().
call(Server, Request, Timeout) ->
    gen_statem:call(Server, {request, Request}, Timeout).

%% @doc Sends `{toroco_pru_port, event()}' to the caller (or Pid) from now on.
-spec subscribe(server()) -> ok.
subscribe(Server) ->
    subscribe(Server, self()).

-spec subscribe(server(), pid()) -> ok.
subscribe(Server, Pid) ->
    gen_statem:call(Server, {subscribe, Pid}).

-spec unsubscribe(server()) -> ok.
unsubscribe(Server) ->
    unsubscribe(Server, self()).

-spec unsubscribe(server(), pid()) -> ok.
unsubscribe(Server, Pid) ->
    gen_statem:call(Server, {unsubscribe, Pid}).

%%% ---------------------------------------------------------------------
%%% gen_statem
%%% ---------------------------------------------------------------------

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() ->
    handle_event_function.

-spec init(opts()) -> gen_statem:init_result(state()).
init(Opts) ->
    %% so that terminate/3 runs on shutdown and leaves the servos at neutral
    process_flag(trap_exit, true),
    case toroco_pru_port_config:initial_config(Opts) of
        {ok, Config} ->
            {ok, connecting, #data{opts = Opts, config = Config},
             [{next_event, internal, start_program}]};
        {error, Reason} ->
            {stop, Reason}
    end.

-spec handle_event(gen_statem:event_type(), term(), state(), data()) ->
          gen_statem:event_handler_result(state()).
handle_event({call, From}, Call, State, D) ->
    answer(Call, From, State, D);
%% --- starting a program
handle_event(Type, start_program, connecting, D)
  when Type =:= internal; Type =:= state_timeout ->
    case toroco_pru_port_program:open(D#data.opts) of
        {ok, Port, OsPid} ->
            {keep_state, D#data{port = Port, os_pid = OsPid, fatal = undefined},
             [{state_timeout, maps:get(hello_timeout_ms, D#data.opts, ?HELLO_TIMEOUT),
               hello_timeout}]};
        {error, Reason} ->
            program_failed(Reason, connecting, D)
    end;
handle_event(state_timeout, hello_timeout, connecting, #data{counters = C} = D) ->
    logger:warning("pru_port program ~p sent no hello in time; killing it",
                   [D#data.os_pid], ?LOG),
    program_failed(start_timeout, connecting,
                   D#data{counters = C#{hello_timeouts := maps:get(hello_timeouts, C) + 1}});
handle_event(state_timeout, give_up, connecting, _D) ->
    %% a failed first start nobody asked about (start_link's caller is gone)
    {stop, normal};
handle_event({timeout, step}, Section, configuring, D) ->
    logger:warning("pru_port program ~p did not answer its ~p configuration in time",
                   [D#data.os_pid, Section], ?LOG),
    program_failed({Section, timeout}, configuring, D);
%% --- what the program sends
handle_event(info, {Port, {data, Bin}}, State, #data{port = Port} = D) ->
    from_program(binary_to_term(Bin), State, D);
handle_event(info, {Port, {exit_status, Status}}, State, #data{port = Port} = D) ->
    program_ended({exit_status, Status}, State, D);
handle_event(info, {'EXIT', Port, Reason}, State, #data{port = Port} = D) ->
    %% the port closed without an exit status (e.g. its pipe broke)
    program_ended({port_exit, Reason}, State, D);
handle_event(info, {'DOWN', MRef, process, Pid, _}, _State, #data{subscribers = Subs} = D) ->
    case maps:get(Pid, Subs, undefined) of
        MRef -> {keep_state, D#data{subscribers = maps:remove(Pid, Subs)}};
        _ -> keep_state_and_data
    end;
handle_event(info, _Other, _State, _D) ->
    %% frames and exits of programs already given up, the kill helper's exit
    keep_state_and_data;
handle_event({timeout, step}, _Section, _State, _D) ->
    %% a step timeout that fired as its program was given up
    keep_state_and_data;
handle_event(cast, _Msg, _State, _D) ->
    keep_state_and_data.

%% The calls: some answered the same in every state, requests and the
%% OS pid by state (the module doc's table of messages).
-spec answer(term(), gen_statem:from(), state(), data()) ->
          gen_statem:event_handler_result(state()).
answer({subscribe, Pid}, From, _State, #data{subscribers = Subs} = D) ->
    case maps:is_key(Pid, Subs) of
        true -> {keep_state_and_data, [{reply, From, ok}]};
        false -> {keep_state, D#data{subscribers = Subs#{Pid => monitor(process, Pid)}},
                  [{reply, From, ok}]}
    end;
answer({unsubscribe, Pid}, From, _State, #data{subscribers = Subs} = D) ->
    case maps:take(Pid, Subs) of
        {MRef, Rest} ->
            demonitor(MRef, [flush]),
            {keep_state, D#data{subscribers = Rest}, [{reply, From, ok}]};
        error ->
            {keep_state_and_data, [{reply, From, ok}]}
    end;
answer(info, From, State, D) ->
    {keep_state_and_data, [{reply, From, describe(State, D)}]};
answer(await_start, From, _State, #data{start = Start} = D) ->
    case Start of
        done -> {keep_state_and_data, [{reply, From, ok}]};
        {awaiting, Froms} -> {keep_state, D#data{start = {awaiting, [From | Froms]}}};
        {failed, Reason} -> {stop_and_reply, normal, [{reply, From, {error, Reason}}]}
    end;
%% --- requests
answer({request, Request}, From, running,
       #data{port = Port, next_ref = Ref, pending = Pending} = D) ->
    case toroco_pru_port_program:send(Port, {Ref, Request}) of
        ok ->
            {keep_state, D#data{next_ref = Ref + 1,
                                pending = Pending#{Ref => {From, Request}}}};
        closed ->
            %% the program just died; its exit_status, queued, restarts it
            {keep_state_and_data, [{reply, From, {error, {port_exit, closed}}}]}
    end;
answer({request, Request}, From, State, D) ->
    case toroco_pru_port_config:waits_for_program(Request) of
        true -> {keep_state_and_data, [postpone]};
        false -> {keep_state_and_data,
                  [{reply, From, {error, {connecting, phase(State, D)}}}]}
    end;
answer(os_pid, From, running, #data{os_pid = OsPid}) ->
    {keep_state_and_data, [{reply, From, OsPid}]};
answer(os_pid, _From, _State, _D) ->
    {keep_state_and_data, [postpone]};
answer(Other, From, _State, _D) ->
    {keep_state_and_data, [{reply, From, {error, {unknown_call, Other}}}]}.

-spec terminate(term(), state(), data()) -> ok.
terminate(_Reason, _State, #data{port = undefined}) ->
    ok;
terminate(_Reason, _State, #data{port = Port, next_ref = Ref}) ->
    %% Neutral first, whatever the state: a program that has not said hello
    %% yet reads it once it does. Closing the port (stdin EOF) makes the
    %% program go neutral again on its way out; no reply is waited for.
    _ = toroco_pru_port_program:send(Port, {Ref, neutral}),
    catch port_close(Port),
    ok.

%%% ---------------------------------------------------------------------
%%% Requests while no program runs
%%% ---------------------------------------------------------------------

-spec phase(state(), data()) -> phase().
phase(configuring, _D) -> configuring;
phase(_, #data{start = {failed, _}}) -> start_failed;
phase(_, #data{port = undefined}) -> restart_backoff;
phase(_, _D) -> awaiting_hello.

-spec describe(state(), data()) -> #{state := state(), atom() => term()}.
describe(State, #data{os_pid = OsPid, counters = C, failures = F, pending = P,
                      subscribers = S}) ->
    C#{state => State, os_pid => OsPid, failures => F, pending => map_size(P),
       subscribers => map_size(S)}.

%%% ---------------------------------------------------------------------
%%% The program: start, configure, restart
%%% ---------------------------------------------------------------------

%% What the program sends, by state. In connecting only the hello (or why
%% it cannot start) is expected.
-spec from_program(term(), state(), data()) -> gen_statem:event_handler_result(state()).
from_program({hello, 1, _Backend}, connecting, D) ->
    configure(D#data{steps = toroco_pru_port_config:config_steps(D#data.config)});
from_program({fatal, Reason}, connecting, D) ->
    %% the exit follows; it is reported with this reason
    {keep_state, D#data{fatal = Reason}};
from_program(Other, connecting, D) ->
    program_failed({unexpected, Other}, connecting, D);
from_program({reply, Ref, Result}, configuring, #data{step = {Ref, Section}} = D) ->
    case Result of
        ok ->
            configure(D#data{step = undefined});
        {error, Reason} ->
            config_refused({Section, Reason}, D);
        Other ->
            config_refused({Section, Other}, D)
    end;
from_program({reply, Ref, Result}, _State, #data{pending = Pending} = D) ->
    case maps:take(Ref, Pending) of
        {{From, Request}, Rest} ->
            Config = toroco_pru_port_config:remember(Request, Result, D#data.config),
            {keep_state, D#data{pending = Rest, config = Config},
             [{reply, From, Result}]};
        error ->
            keep_state_and_data
    end;
from_program(Event, _State, D) ->
    toroco_pru_port_program:event(Event, D#data.subscribers),
    keep_state_and_data.

%% Sends the next configuration step, or enters running after the last.
-spec configure(data()) -> gen_statem:event_handler_result(state()).
configure(#data{steps = [{Section, Request} | Rest], port = Port, next_ref = Ref} = D) ->
    %% a closed port is followed by its exit_status, which ends the step
    _ = toroco_pru_port_program:send(Port, {Ref, Request}),
    {next_state, configuring, D#data{step = {Ref, Section}, steps = Rest, next_ref = Ref + 1},
     [{{timeout, step}, maps:get(reply_timeout_ms, D#data.opts, ?REPLY_TIMEOUT), Section}]};
configure(#data{steps = [], start = Start} = D) ->
    Cancel = {{timeout, step}, cancel},
    D1 = D#data{failures = 0},
    case Start of
        {awaiting, Froms} ->
            {next_state, running, D1#data{start = done},
             [Cancel | [{reply, From, ok} || From <- Froms]]};
        done ->
            logger:notice("pru_port program ~p running again (the last one: ~0p)",
                          [D#data.os_pid, D#data.down_why], ?LOG),
            toroco_pru_port_program:event({port_restarted, D#data.down_why}, D1#data.subscribers),
            {next_state, running, D1, [Cancel]}
    end.

%% The program refused a part of the configuration it was given: a first
%% start fails with it; after a restart nothing better can be done than
%% stopping (a supervisor may start it with its static options).
-spec config_refused({atom(), term()}, data()) -> gen_statem:event_handler_result(state()).
config_refused(Reason, #data{start = {awaiting, _}} = D) ->
    start_failed(Reason, D);
config_refused(Reason, D) ->
    logger:error("pru_port program refused its configuration again: ~0p", [Reason], ?LOG),
    {stop, {port_restart_failed, Reason}, D}.

%% The program exited (or its port broke).
-spec program_ended(term(), state(), data()) -> gen_statem:event_handler_result(state()).
program_ended(_Why, connecting, #data{fatal = Fatal} = D) when Fatal =/= undefined ->
    program_failed(Fatal, connecting, D#data{port = undefined});
program_ended(Why, configuring, #data{step = {_, Section}} = D) ->
    program_failed({Section, Why}, configuring, D#data{port = undefined});
program_ended(Why, State, D) ->
    program_failed(Why, State, D#data{port = undefined}).

%% The program is gone or given up on: a first start fails; otherwise the
%% program is started again, at once after one that ran, later after each
%% one that did not.
-spec program_failed(term(), state(), data()) -> gen_statem:event_handler_result(state()).
program_failed(Why, State, #data{start = {awaiting, _}} = D) ->
    start_failed(case State of
                     connecting -> {port_program, Why};
                     _ -> Why
                 end, D);
program_failed(Why, State, #data{opts = Opts, pending = Pending, counters = C} = D0) ->
    logger:warning("pru_port program ended (~0p) while ~p; restarting it", [Why, State], ?LOG),
    D1 = give_up_program(kill, D0),
    Replies = [{reply, From, {error, {port_exit, Why}}} || {From, _} <- maps:values(Pending)],
    {MaxR, WindowMs} = maps:get(max_restarts, Opts, {5, 10000}),
    Now = toroco_clock:now_ms(),
    Recent = [T || T <- D1#data.restart_times, Now - T < WindowMs],
    {Failures, DownWhy} = case State of
                              running -> {0, Why};
                              _ -> {D1#data.failures + 1, D1#data.down_why}
                          end,
    Delay = toroco_pru_port_config:backoff(Failures, maps:get(restart_backoff, Opts, ?BACKOFF)),
    D = D1#data{pending = #{}, step = undefined, steps = [], restart_times = [Now | Recent],
                failures = Failures, down_why = DownWhy,
                counters = C#{restarts := maps:get(restarts, C) + 1,
                              failed_starts := maps:get(failed_starts, C) + min(Failures, 1),
                              backoff_ms := Delay}},
    case length(Recent) >= MaxR of
        true ->
            logger:error("pru_port program failed ~b times within ~b ms; giving up",
                         [length(Recent) + 1, WindowMs], ?LOG),
            {stop_and_reply, {port_program_failed, Why}, Replies, D};
        false ->
            {next_state, connecting, D,
             [{state_timeout, Delay, start_program}, {{timeout, step}, cancel} | Replies]}
    end.

%% The first start failed: start_link's caller gets the reason and this
%% process ends; if that caller has not asked yet, the reason waits for it.
-spec start_failed(term(), data()) -> gen_statem:event_handler_result(state()).
start_failed(Reason, #data{start = {awaiting, Froms}} = D0) ->
    %% a program that refused its configuration ends on its own once closed
    D = give_up_program(case Reason of
                            {port_program, _} -> kill;
                            {_, timeout} -> kill;
                            _ -> close
                        end, D0),
    case Froms of
        [] ->
            {next_state, connecting, D#data{start = {failed, Reason}},
             [{state_timeout, 5000, give_up}, {{timeout, step}, cancel}]};
        _ ->
            {stop_and_reply, normal, [{reply, From, {error, Reason}} || From <- Froms],
             D#data{start = {failed, Reason}}}
    end.

%% Closes the port of a program that may still run (stdin EOF: it goes
%% neutral and exits) and, with `kill', kills it too: one that sent no
%% hello or does not answer is wedged, and the next one puts the servos at
%% neutral.
-spec give_up_program(kill | close, data()) -> data().
give_up_program(_How, #data{port = undefined} = D) ->
    D#data{os_pid = undefined};
give_up_program(How, #data{port = Port, os_pid = OsPid} = D) ->
    toroco_pru_port_program:close(How, Port, OsPid),
    D#data{port = undefined, os_pid = undefined}.
