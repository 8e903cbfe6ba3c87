%% @doc A device's attachment to a `toroco_pru_port' owner: the part that
%% `toroco_pru_sensors', `toroco_servo_motors' and `toroco_gpio_button'
%% share.
%%
%% A device either uses a shared owner (option `port', a registered name or a
%% pid, e.g. the one `toroco_hw_sup' starts from the app env `pru_port') or
%% starts its own, linked to it, from the owner options it was given
%% (`backend', default `sim', `sysfs_root', `gpiochip', `executable', ...).
%% Each device configures only its own section of the program (the ADC
%% channels, the servos, the button), so one owner serves one device of each
%% kind.
%%
%% The client subscribes to the owner's events and turns what the device's
%% mailbox receives into {@link handle_info/2} results: a program event, a
%% program restart (the owner re-applied the configuration; the servos are
%% at neutral), or the loss of the owner itself. After a loss the device
%% attaches again with {@link attach/2} after {@link retry_ms/1}: a shared
%% owner is looked up again by name (a supervisor may have restarted it with
%% only its static options, which is why the device configures its section
%% again), an own owner is started again. Every call to the owner goes
%% through {@link call/2}, which turns an owner that is gone or slow into an
%% error value instead of an exit of the device.
-module(toroco_pru_client).

-export([parse/1, owner_keys/0, attach/2, detach/1, handle_info/2, call/2,
         retry_ms/1, server/1, is_own/1, describe/1]).
-export_type([t/0]).

-define(FIRST_RETRY_MS, 100).
-define(MAX_RETRY_MS, 5000).

-type server() :: pid() | atom().
-opaque t() :: #{mode := {shared, server()} | {own, map()},
                 pid := pid() | undefined,
                 mon := reference() | undefined,
                 retry := pos_integer(),
                 restarts := non_neg_integer(),
                 losses := non_neg_integer()}.
-type info_result() :: {event, toroco_pru_port:event()}
                     | {restarted, term(), t()}
                     | {lost, term(), t()}
                     | unknown.

%% @doc The options that configure an own owner (refused with `port').
-spec owner_keys() -> [atom()].
owner_keys() ->
    [backend, executable, sysfs_root, gpiochip, sim_script, remoteproc, firmware,
     rpmsg_dev, max_restarts].

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
      restarts => 0, losses => 0}.

%% @doc Finds or starts the owner, subscribes, and runs `Configure' with its
%% pid; on any failure the client is left detached.
-spec attach(t(), fun((pid()) -> ok | {error, term()})) -> {ok, t()} | {error, term(), t()}.
attach(C, Configure) ->
    case connect(C) of
        {ok, C1 = #{pid := Pid}} ->
            case call(C1, fun(P) -> toroco_pru_port:subscribe(P) end) of
                ok ->
                    case Configure(Pid) of
                        ok -> {ok, C1#{retry := ?FIRST_RETRY_MS}};
                        {error, R} -> {error, R, detach(C1)}
                    end;
                {error, R} ->
                    {error, R, detach(C1)}
            end;
        {error, R} ->
            {error, R, C}
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

%% @doc Lets go of the owner: unsubscribes from a shared one, stops an own
%% one (which leaves the servos at neutral).
-spec detach(t()) -> t().
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

%% @doc What a message in the device's mailbox means for the attachment.
-spec handle_info(term(), t()) -> info_result().
handle_info({toroco_pru_port, {port_restarted, Why}}, C = #{restarts := N}) ->
    {restarted, Why, C#{restarts := N + 1}};
handle_info({toroco_pru_port, Event}, _C) ->
    {event, Event};
handle_info({'DOWN', Mon, process, _, Reason}, C = #{mon := Mon}) when Mon =/= undefined ->
    lost(Reason, C);
handle_info({'EXIT', Pid, Reason}, C = #{mode := {own, _}, pid := Pid}) when is_pid(Pid) ->
    lost(Reason, C);
handle_info(_Other, _C) ->
    unknown.

lost(Reason, C = #{losses := N}) ->
    {lost, Reason, C#{pid := undefined, mon := undefined, losses := N + 1}}.

%% @doc Runs `F(OwnerPid)'; an owner that is gone, dies or does not answer
%% is an error value.
-spec call(t(), fun((pid()) -> Result)) -> Result | {error, term()}.
call(#{pid := undefined}, _F) ->
    {error, port_down};
call(#{pid := Pid}, F) ->
    try F(Pid)
    catch exit:{Reason, _} -> {error, {port_call, Reason}}
    end.

%% @doc How long to wait before the next attach, and the client with the
%% wait after that (doubling, at most 5 s).
-spec retry_ms(t()) -> {pos_integer(), t()}.
retry_ms(C = #{retry := Ms}) ->
    {Ms, C#{retry := min(Ms * 2, ?MAX_RETRY_MS)}}.

%% @doc The owner's pid, while attached.
-spec server(t()) -> pid() | undefined.
server(#{pid := Pid}) -> Pid.

-spec is_own(t()) -> boolean().
is_own(#{mode := {own, _}}) -> true;
is_own(#{mode := {shared, _}}) -> false.

%% @doc The attachment's part of the device's `info/2' map.
-spec describe(t()) -> map().
describe(#{mode := Mode, pid := Pid, restarts := R, losses := L}) ->
    #{port => Pid,
      port_owner => case Mode of {shared, S} -> S; {own, _} -> own end,
      port_status => case Pid of undefined -> down; _ -> up end,
      port_restarts => R,
      port_losses => L}.
