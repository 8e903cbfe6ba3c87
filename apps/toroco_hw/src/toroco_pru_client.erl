%% @doc A device's attachment to a `toroco_pru_port' owner, and the reconnect
%% state machine that `toroco_pru_sensors', `toroco_servo_motors' and
%% `toroco_gpio_button' share: each of them keeps only its own section of
%% the program and what its events mean.
%%
%% A device either uses a shared owner (option `port', a registered name or a
%% pid, e.g. the one `toroco_hw_sup' starts from the app env `pru_port') or
%% starts its own, linked to it, from the owner options it was given
%% (`backend', default `sim', `sysfs_root', `gpiochip', `executable', ...).
%% Each device configures only its own section of the program (the ADC
%% channels, the servos, the button), so one owner serves one device of each
%% kind.
%%
%% A device using it implements this behaviour next to `toroco_device', keeps
%% its name under `name' and the client under `client' in its data map, and
%% runs in state `up' (attached) or `down' (attaching again):
%% <ul>
%% <li>`configure(Data)': the steps that set the device's section on an
%% owner, in order, each named by the part of the section it sets (an error
%% says `{Part, Reason}'); they run on each attach.</li>
%% <li>`port_event(Event, Data)': what a program event of one of those parts
%% means to the device (`{adc, ...}' for part `adc', `{button, ...}' for
%% `button', `{watchdog, T}' for `watchdog'). The owner reports every
%% section's events to every subscriber; a device hears only its own.</li>
%% <li>`port_status(attached | restarted | lost, Data)' (optional): the
%% device's own part when it attached again, when the program was restarted
%% (the owner re-applied the configuration; the servos are at neutral), or
%% when the owner was lost.</li>
%% </ul>
%% The device's `init/2' calls {@link init/3}, its `handle_event/4' hands
%% `info' and `{timeout, reconnect}' to {@link handle_event/5}, its
%% `terminate/3' calls {@link release/2}.
%% After a loss the device attaches again after 100 ms, doubling up to 5 s
%% between failed tries: a shared owner is looked up again by name (a
%% supervisor may have restarted it with only its static options, which is
%% why the device configures its section again), an own owner is started
%% again. Every call to the owner goes through {@link call/2}, which turns an
%% owner that is gone or slow into an error value instead of an exit of the
%% device. {@link sim/3} and {@link sim_reply/2} carry a sim backend call
%% from a caller to the device's owner.
%%
%% Functions, by purpose:
%% <ul>
%% <li>options: `parse/1', `owner_keys/0'</li>
%% <li>the device's life: `init/3', `handle_event/5', `release/2'</li>
%% <li>the owner: `call/2', `is_own/1', `describe/1'</li>
%% <li>simulation: `sim/3', `sim_reply/2'</li>
%% </ul>
-module(toroco_pru_client).

-export([parse/1, owner_keys/0,
         init/3, handle_event/5, release/2,
         call/2, is_own/1, describe/1,
         sim/3, sim_reply/2]).
-export_type([t/0]).

-callback configure(Data :: map()) -> [{Part :: atom(), fun((pid()) -> ok | {error, term()})}].
-callback port_event(toroco_pru_port:event(), Data :: map()) -> toroco_behavior:result().
-callback port_status(attached | restarted | lost, Data :: map()) ->
    {Data :: map(), toroco_behavior:actions()}.
-optional_callbacks([port_status/2]).

-define(FIRST_RETRY_MS, 100).
-define(MAX_RETRY_MS, 5000).
-define(LOG, #{domain => [toroco, hw]}).

-type server() :: pid() | atom().
-opaque t() :: #{mode := {shared, server()} | {own, map()},
                 pid := pid() | undefined,
                 mon := reference() | undefined,
                 retry := pos_integer(),
                 restarts := non_neg_integer(),
                 losses := non_neg_integer(),
                 failures := non_neg_integer(),
                 parts := [atom()]}.

%%====================================================================
%% Options
%%====================================================================

%% @doc The options that configure an own owner (refused with `port').
-spec owner_keys() -> [atom()].
owner_keys() ->
    [backend, executable, sysfs_root, gpiochip, sim_script, remoteproc, firmware,
     rpmsg_dev, max_restarts, hello_timeout_ms, reply_timeout_ms, restart_backoff].

%% @doc A client from a device's options (only the `port' and owner keys are
%% looked at); nothing is started yet.
-spec parse(map()) -> {ok, t()} | {error, term()}.
parse(Opts) ->
    Own = maps:with(owner_keys(), Opts),
    case maps:find(port, Opts) of
        {ok, P} when is_pid(P); is_atom(P) ->
            case maps:keys(Own) of
                [] -> {ok, new({shared, P})};
                [K | _] -> {error, {bad_option, {K, only_without_port}}}
            end;
        {ok, P} ->
            {error, {bad_option, {port, P}}};
        error ->
            case maps:get(backend, Own, sim) of
                B when B =:= sim; B =:= pru -> {ok, new({own, Own#{backend => B}})};
                B -> {error, {bad_option, {backend, B}}}
            end
    end.

new(Mode) ->
    #{mode => Mode, pid => undefined, mon => undefined, retry => ?FIRST_RETRY_MS,
      restarts => 0, losses => 0, failures => 0, parts => []}.

%%====================================================================
%% The device's life
%%====================================================================

%% @doc The first attach, from the device `Name''s `init/2', given what the
%% device read from its options: its own data and the {@link parse/1}d
%% client, or an error, which is returned as it is. The device starts `up',
%% its data holding its `name' and `client' besides its own; a device that
%% cannot attach does not start.
-spec init(module(), atom(), {ok, map(), t()} | {error, term()}) ->
          {ok, up, map()} | {error, term()}.
init(Module, Name, {ok, Own, C}) ->
    D = Own#{name => Name, client => C},
    case attach(C, Module:configure(D)) of
        {ok, C1} ->
            {ok, up, D#{client := C1}};
        {error, Reason, _} ->
            logger:warning("~p (~p) not started: ~0p", [Name, Module, Reason], ?LOG),
            {error, Reason}
    end;
init(_Module, _Name, {error, _} = Err) ->
    Err.

%% @doc The device's `info' messages and its `{timeout, reconnect}'.
-spec handle_event(module(), info | {timeout, reconnect}, term(), up | down, map()) ->
          toroco_behavior:result().
handle_event(Module, info, Msg, _State, D) ->
    handle_info(Module, Msg, D);
handle_event(Module, {timeout, reconnect}, attach, down, D) ->
    reconnect(Module, D);
handle_event(_Module, {timeout, reconnect}, _Content, _State, _D) ->
    keep_state_and_data.

%% A message in the device's mailbox: a program event goes to the device's
%% port_event/2, a program restart or the loss of the owner to its
%% port_status/2 (after a loss the device goes down and tries to attach
%% again); anything else is ignored.
handle_info(Module, Msg, D = #{name := Name, client := C}) ->
    case classify(Msg, C) of
        {event, Event} ->
            Module:port_event(Event, D);
        {restarted, C1} ->
            {D1, Actions} = port_status(Module, restarted, D#{client := C1}),
            {keep_state, D1, Actions};
        {lost, Why, C1} ->
            logger:warning("~p lost its pru_port (~0p); attaching again", [Name, Why], ?LOG),
            {Ms, C2} = retry_ms(C1),
            {D1, Actions} = port_status(Module, lost, D#{client := C2}),
            {next_state, down, D1, [{{timeout, reconnect}, Ms, attach} | actions(Actions)]};
        unknown ->
            keep_state_and_data
    end.

%% The reconnect timeout of state down: attach again, or count the failure
%% and try again later.
reconnect(Module, D = #{name := Name, client := C}) ->
    case attach(C, Module:configure(D)) of
        {ok, C1} ->
            logger:notice("~p attached to its pru_port again", [Name], ?LOG),
            {D1, Actions} = port_status(Module, attached, D#{client := C1}),
            {next_state, up, D1, Actions};
        {error, Reason, C1 = #{failures := N}} ->
            {Ms, C2} = retry_ms(C1#{failures := N + 1}),
            logger:warning("~p could not attach to its pru_port (~0p); next try in ~b ms",
                           [Name, Reason, Ms], ?LOG),
            {keep_state, D#{client := C2}, [{{timeout, reconnect}, Ms, attach}]}
    end.

%% @doc From the device's `terminate/3': runs `Undo' on a shared owner (the
%% owner outlives the device, so the device takes back its section), then
%% lets the owner go: unsubscribes from a shared one, stops an own one
%% (which leaves the servos at neutral).
-spec release(t(), fun((pid()) -> term())) -> ok.
release(C, Undo) ->
    case is_own(C) of
        true -> ok;
        false -> _ = call(C, Undo)
    end,
    _ = detach(C),
    ok.

port_status(Module, Status, D) ->
    case erlang:function_exported(Module, port_status, 2) of
        true -> Module:port_status(Status, D);
        false -> {D, []}
    end.

actions(A) when is_list(A) -> A;
actions(A) -> [A].

%%====================================================================
%% The owner
%%====================================================================

%% @doc Runs `F(OwnerPid)'; an owner that is gone, dies or does not answer
%% is an error value.
-spec call(t(), fun((pid()) -> Result)) -> Result | {error, term()}.
call(#{pid := undefined}, _F) ->
    {error, port_down};
call(#{pid := Pid}, F) ->
    try F(Pid)
    catch exit:{Reason, _} -> {error, {port_call, Reason}}
    end.

-spec is_own(t()) -> boolean().
is_own(#{mode := {own, _}}) -> true;
is_own(#{mode := {shared, _}}) -> false.

%% @doc The attachment's part of the device's `info/2' map.
-spec describe(t()) -> map().
describe(#{mode := Mode, pid := Pid, restarts := R, losses := L, failures := F}) ->
    #{port => Pid,
      port_owner => case Mode of {shared, S} -> S; {own, _} -> own end,
      port_status => case Pid of undefined -> down; _ -> up end,
      port_restarts => R,
      port_losses => L,
      reconnect_failures => F}.

%%====================================================================
%% Simulation
%%====================================================================

%% @doc Sim backend: asks device `Device' for its owner with `Request' (which
%% the device answers with {@link sim_reply/2}) and runs `F(Owner, Detail)'.
-spec sim(atom(), term(), fun((pid(), term()) -> ok | {error, term()})) ->
          ok | {error, term()}.
sim(Device, Request, F) ->
    try toroco_device:call(Device, Request, 5000) of
        {ok, Pid, Detail} ->
            try F(Pid, Detail)
            catch exit:{Reason, _} -> {error, {port_call, Reason}}
            end;
        {error, _} = Err ->
            Err
    catch
        exit:{noproc, _} -> {error, {not_running, Device}};
        exit:{Reason, _} -> {error, {Reason, Device}}
    end.

%% @doc The device's answer to a {@link sim/3} request: its owner and
%% `Detail' (what `F' needs besides the owner), or why there is none.
-spec sim_reply(map(), term()) -> {ok, pid(), term()} | {error, {port_down, atom()}}.
sim_reply(#{name := Name, client := #{pid := Pid}}, Detail) ->
    case Pid of
        undefined -> {error, {port_down, Name}};
        _ -> {ok, Pid, Detail}
    end.

%%====================================================================
%% Internals
%%====================================================================

%% Finds or starts the owner, subscribes, and runs the Configure steps with
%% its pid; on any failure the client is left detached.
attach(C, Configure) ->
    case connect(C) of
        {ok, C1 = #{pid := Pid}} ->
            case call(C1, fun(P) -> toroco_pru_port:subscribe(P) end) of
                ok ->
                    case configure(Configure, Pid) of
                        ok -> {ok, C1#{retry := ?FIRST_RETRY_MS,
                                       parts := [Part || {Part, _} <- Configure]}};
                        {error, R} -> {error, R, detach(C1)}
                    end;
                {error, R} ->
                    {error, R, detach(C1)}
            end;
        {error, R} ->
            {error, R, C}
    end.

configure([], _Pid) ->
    ok;
configure([{Part, F} | Rest], Pid) ->
    case F(Pid) of
        ok -> configure(Rest, Pid);
        {error, R} -> {error, {Part, R}}
    end.

connect(C = #{mode := {shared, Server}}) ->
    case resolve(Server) of
        undefined -> {error, {port_not_running, Server}};
        Pid -> {ok, C#{pid := Pid, mon := erlang:monitor(process, Pid)}}
    end;
connect(C = #{mode := {own, Opts}}) ->
    case toroco_pru_port:start_link(Opts) of
        {ok, Pid} ->
            {ok, C#{pid := Pid}};
        {error, R} ->
            %% the failed start was linked to this process: drop its exit
            receive {'EXIT', _, _} -> ok after 0 -> ok end,
            {error, R}
    end.

resolve(Pid) when is_pid(Pid) ->
    case is_process_alive(Pid) of
        true -> Pid;
        false -> undefined
    end;
resolve(Name) ->
    whereis(Name).

detach(C = #{pid := undefined}) ->
    C;
detach(C = #{mode := {shared, _}, mon := Mon}) ->
    erlang:demonitor(Mon, [flush]),
    _ = call(C, fun(P) -> toroco_pru_port:unsubscribe(P) end),
    C#{pid := undefined, mon := undefined};
detach(C = #{mode := {own, _}, pid := Pid}) ->
    unlink(Pid),
    _ = catch toroco_pru_port:stop(Pid),
    receive {'EXIT', Pid, _} -> ok after 0 -> ok end,
    C#{pid := undefined}.

%% What a message in the device's mailbox means for the attachment.
classify({toroco_pru_port, {port_restarted, _Why}}, C = #{restarts := N}) ->
    {restarted, C#{restarts := N + 1}};
classify({toroco_pru_port, Event}, #{parts := Parts}) when is_tuple(Event), tuple_size(Event) > 0 ->
    case lists:member(element(1, Event), Parts) of
        true -> {event, Event};
        false -> unknown
    end;
classify({'DOWN', Mon, process, _, Reason}, C = #{mon := Mon}) when Mon =/= undefined ->
    lost(Reason, C);
classify({'EXIT', Pid, Reason}, C = #{mode := {own, _}, pid := Pid}) when is_pid(Pid) ->
    lost(Reason, C);
classify(_Other, _C) ->
    unknown.

lost(Reason, C = #{losses := N}) ->
    {lost, Reason, C#{pid := undefined, mon := undefined, losses := N + 1}}.

%% How long to wait before the next attach, and the client with the wait
%% after that (doubling, at most 5 s).
retry_ms(C = #{retry := Ms}) ->
    {Ms, C#{retry := min(Ms * 2, ?MAX_RETRY_MS)}}.
