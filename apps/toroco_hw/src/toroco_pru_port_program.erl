%% @doc The `pru_port' C program as an operating-system process, for its
%% owner (`toroco_pru_port'): where the executable is and its command line
%% from the owner's options, the port opened on it (`{packet, 2}', terms in
%% the external format), a frame written to it, and the port closed (and the
%% program killed) when the owner gives it up, and the program's events
%% passed on to the owner's subscribers.
%%
%% Functions: `open/1', `send/2', `close/3'; `event/2' for what the
%% program sends unsolicited.
-module(toroco_pru_port_program).

-export([open/1, send/2, close/3, event/2]).

-define(LOG, #{domain => [toroco, hw, pru_port]}).

%% @doc A new program, started with the options' backend and paths: its
%% port and OS pid, or why it could not start.
-spec open(toroco_pru_port:opts()) -> {ok, port(), integer()} | {error, term()}.
open(Opts) ->
    case executable(Opts) of
        {ok, Exe} ->
            try open_port({spawn_executable, Exe},
                          [{packet, 2}, binary, exit_status, use_stdio,
                           {args, program_args(Opts)}]) of
                Port ->
                    {os_pid, OsPid} = erlang:port_info(Port, os_pid),
                    {ok, Port, OsPid}
            catch
                error:Reason -> {error, {Reason, Exe}}
            end;
        {error, _} = Error ->
            Error
    end.

%% @doc Writes one frame. A port whose program has died is closed before
%% its exit_status is handled: writing to it then is not an error of the
%% owner.
-spec send(port() | undefined, {pos_integer(), toroco_pru_port:request()}) -> ok | closed.
send(undefined, _Frame) ->
    closed;
send(Port, Frame) ->
    try port_command(Port, term_to_binary(Frame)) of
        true -> ok
    catch
        error:badarg -> closed
    end.

%% @doc Closes the port of a program that may still run (stdin EOF: it goes
%% neutral and exits) and, with `kill', kills it too. The kill runs in a
%% process of its own, not in the owner.
-spec close(kill | close, port(), integer() | undefined) -> ok.
close(How, Port, OsPid) ->
    catch port_close(Port),
    _ = case How of
            kill when is_integer(OsPid) ->
                spawn(fun() -> os:cmd("kill -KILL " ++ integer_to_list(OsPid) ++ " 2>/dev/null") end);
            _ ->
                ok
        end,
    ok.

-spec executable(toroco_pru_port:opts()) -> {ok, file:filename_all()} | {error, term()}.
executable(#{executable := Exe}) ->
    {ok, Exe};
executable(_) ->
    case code:priv_dir(toroco_hw) of
        {error, _} -> {error, {no_priv_dir, toroco_hw}};
        Dir -> {ok, filename:join(Dir, "pru_port")}
    end.

-spec program_args(toroco_pru_port:opts()) -> [string() | binary()].
program_args(Opts) ->
    Flags = [{backend, "--backend"}, {sysfs_root, "--sysfs-root"}, {gpiochip, "--gpiochip"},
             {sim_script, "--sim-script"}, {remoteproc, "--remoteproc"},
             {firmware, "--firmware"}, {rpmsg_dev, "--rpmsg-dev"}],
    lists:append([[Flag, arg(V)] || {Key, Flag} <- Flags, {ok, V} <- [maps:find(Key, Opts)]]).

-spec arg(atom() | string() | binary()) -> string() | binary().
arg(A) when is_atom(A) -> atom_to_list(A);
arg(S) -> S.


%% @doc What the program sends unsolicited: logged when it says something went
%% wrong, and passed on to each subscriber.
-spec event(term(), #{pid() => reference()}) -> ok.
event({adc, _, _, _} = Event, Subs) ->
    notify(Event, Subs);
event({button, _, _} = Event, Subs) ->
    notify(Event, Subs);
event({watchdog, _} = Event, Subs) ->
    logger:notice("pru_port watchdog: no servo command in time, servos at neutral", [], ?LOG),
    notify(Event, Subs);
event({fault, Reason} = Event, Subs) ->
    logger:warning("pru_port fault: ~0p", [Reason], ?LOG),
    notify(Event, Subs);
event({port_restarted, _} = Event, Subs) ->
    notify(Event, Subs);
event({error, {bad_frame, Why}}, _Subs) ->
    logger:error("pru_port refused a frame from this process (~0p)", [Why], ?LOG);
event(Other, _Subs) ->
    logger:warning("pru_port sent an unexpected term: ~0p", [Other], ?LOG).

-spec notify(toroco_pru_port:event(), #{pid() => reference()}) -> ok.
notify(Event, Subs) ->
    %% a notice, so that in lockstep the devices act on it as a step
    maps:foreach(fun(Pid, _) -> toroco_clock:notify(Pid, {toroco_pru_port, Event}) end, Subs).
