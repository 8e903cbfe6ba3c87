%% @doc The Torobot's two continuous-rotation servos as an actuator device,
%% driven through the `pru_port' program's sysfs PWM.
%%
%% Inputs:
%% <ul>
%% <li>`setvel': `{Left, Right}', each a velocity in -100..100 (floats are
%%     rounded; values out of range are clamped and counted as `clamped').</li>
%% <li>`enable': `true' | `false'. Disabled, the servos are held at neutral and
%%     their PWM outputs are off; `setvel' is remembered and applied on
%%     `enable' (it is what the wiring currently commands).</li>
%% </ul>
%% Output `applied': `{send, #{applied => {Left, Right}}}' each time the
%% velocities really applied to the servos change, `{0, 0}' included: on
%% disable, on the program's watchdog, when the program dies and is
%% restarted, when the owner is lost, and on terminate. A simulator wires its
%% world to this output. After a safety stop the command is forgotten and the
%% servos are at neutral. When the program was restarted or the owner found
%% again, the device asks its `setvel' router for the current winner again,
%% so a latched command (the Torobot's `forward') drives the servos once the
%% port is back; after a watchdog stop (this side stalled) the servos stay at
%% neutral until the next `setvel'.
%%
%% Options:
%% <ul>
%% <li>`servos': `#{left => Calib, right => Calib}', each merged over the
%%     Torobot's defaults: left `#{pwmchip => 0, channel => 0}', right
%%     `#{pwmchip => 0, channel => 1, reversed => true}' (the servos face
%%     each other), both `period_ns => 20000000, neutral_ns => 1500000,
%%     span_ns => 500000' (1-2 ms pulses; calibrate `neutral_ns' until a
%%     servo at 0 stands still).</li>
%% <li>`watchdog_ms' (default 500, 0 = off): the program puts the servos at
%%     neutral when no servo command came for that long.</li>
%% <li>`keepalive' (default `true'): while the device runs it repeats the
%%     applied velocities every `watchdog_ms div 3' of real time (at any
%%     speed of the runtime's clock), so the watchdog fires
%%     only when this side stalls, not when the wiring holds a latched
%%     velocity. With `false' a velocity lasts `watchdog_ms' unless sent
%%     again.</li>
%% <li>`enabled' (default `true').</li>
%% <li>`port', or the owner options (`backend', default `sim', ...), as in
%%     `toroco_pru_client'. An own owner on the `sim' backend without
%%     `sysfs_root' gets a private fake PWM tree in a temporary directory
%%     (removed on terminate), so the device runs anywhere.</li>
%% </ul>
%% The device configures the owner's whole servo set and its watchdog, so one
%% `toroco_servo_motors' device serves one owner.
%%
%% `info/2': `applied', `commanded', `enabled', `clamped', `watchdogs',
%% `port_errors', `bad_input' (by reason), `sysfs_root', `watchdog_ms',
%% `keepalive_ms', and what `toroco_pru_client:describe/1' says of the
%% attachment (`port_status', `port_losses', `reconnect_failures', ...).
-module(toroco_servo_motors).
-behaviour(toroco_device).
-behaviour(toroco_pru_client).

-export([default_servos/0]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).
-export([configure/1, port_event/2, port_status/2]).

-define(STOP, {0, 0}).
-define(CALIB_KEYS, [pwmchip, channel, period_ns, neutral_ns, span_ns, reversed]).

%% @doc The Torobot's servo calibration, the base the `servos' option is
%% merged over.
-spec default_servos() -> #{left := map(), right := map()}.
default_servos() ->
    Base = #{period_ns => 20000000, neutral_ns => 1500000, span_ns => 500000,
             reversed => false},
    #{left => Base#{pwmchip => 0, channel => 0},
      right => Base#{pwmchip => 0, channel => 1, reversed => true}}.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [atom()], outputs := [atom()]}.
interface(_Opts) ->
    #{inputs => [setvel, enable], outputs => [applied]}.

-spec init(atom(), map()) -> {ok, up, map(), toroco_behavior:actions()} |
                                {error, term()}.
init(Name, Opts) ->
    case options(Opts) of
        {ok, Settings} ->
            start(Name, Opts, Settings);
        {error, _} = Err ->
            Err
    end.

start(Name, Opts, S = #{servos := Servos}) ->
    {Opts1, Tmp} = own_sysfs(Name, Opts, Servos),
    {ok, Client} = toroco_pru_client:parse(Opts1),
    D0 = maps:merge(S, #{tmp => Tmp,
                         sysfs_root => maps:get(sysfs_root, Opts1, "/sys"),
                         commanded => ?STOP, applied => ?STOP, clamped => 0,
                         watchdogs => 0, port_errors => 0,
                         bad => toroco_bad_input:new(Name)}),
    case toroco_pru_client:init(?MODULE, Name, {ok, D0, Client}) of
        {ok, up, D1} ->
            {ok, up, D1, keepalive(D1)};
        {error, _} = Err ->
            remove_tmp(Tmp),
            Err
    end.

-spec handle_input(atom(), term(), up | down, map()) ->
          toroco_behavior:result().
handle_input(setvel, {L, R} = V, State, D = #{commanded := Old, clamped := N})
  when is_number(L), is_number(R) ->
    Cmd = {velocity(L), velocity(R)},
    D1 = D#{commanded := Cmd, clamped := N + clamps(V, Cmd)},
    case State of
        up when Cmd =/= Old -> drive(D1);
        _ -> {keep_state, D1}
    end;
handle_input(enable, On, State, D = #{enabled := Was}) when is_boolean(On) ->
    case {State, On} of
        {_, Was} -> keep_state_and_data;
        {down, _} -> {keep_state, D#{enabled := On}};
        {up, true} ->
            case port(D, fun(P) -> toroco_pru_port:enable_servos(P, true) end) of
                {ok, D1} -> drive(D1#{enabled := true});
                {error, D1} -> {keep_state, D1}
            end;
        {up, false} ->
            {_, D1} = port(D, fun(P) -> toroco_pru_port:set_servos(P, to_map(?STOP)) end),
            {_, D2} = port(D1, fun(P) -> toroco_pru_port:enable_servos(P, false) end),
            applied(?STOP, D2#{enabled := false})
    end;
handle_input(Input, V, _State, D = #{bad := B}) ->
    {keep_state, D#{bad := toroco_bad_input:count(bad_value, {Input, V}, B)}}.

-spec handle_event(gen_statem:event_type(), term(), up | down, map()) ->
          toroco_behavior:result().
handle_event({timeout, keepalive}, tick, up, D = #{applied := A}) ->
    {_, D1} = port(D, fun(P) -> toroco_pru_port:set_servos(P, to_map(A)) end),
    {keep_state, D1, keepalive(D1)};
handle_event({timeout, keepalive}, tick, down, _D) ->
    keep_state_and_data;
handle_event(Type, Content, State, D) when Type =:= info; Type =:= {timeout, reconnect} ->
    toroco_pru_client:handle_event(?MODULE, Type, Content, State, D).

-spec info(up | down, map()) -> map().
info(_State, D = #{client := C, bad := B}) ->
    maps:merge(toroco_pru_client:describe(C),
               (maps:with([applied, commanded, enabled, clamped, watchdogs, port_errors,
                           sysfs_root, watchdog_ms, servos], D))#{
                 bad_input => toroco_bad_input:counts(B),
                 keepalive_ms => keepalive_ms(D)}).

-spec terminate(term(), up | down, map()) -> ok | {emit, toroco_behavior:actions()}.
terminate(_Reason, _State, #{client := C, applied := A, tmp := Tmp}) ->
    %% stopping an own owner puts the servos at neutral; a shared one is told
    ok = toroco_pru_client:release(C, fun(P) -> toroco_pru_port:call(P, neutral, 1000) end),
    remove_tmp(Tmp),
    case A of
        ?STOP -> ok;
        _ -> {emit, [{send, #{applied => ?STOP}}]}
    end.

%%====================================================================
%% toroco_pru_client
%%====================================================================

%% @doc The whole servo set of the program, its watchdog and enable state.
-spec configure(map()) -> [{atom(), fun((pid()) -> ok | {error, term()})}].
configure(#{servos := Servos, watchdog_ms := W, enabled := On}) ->
    [{servos, fun(P) -> toroco_pru_port:configure_servos(P, Servos) end},
     {watchdog, fun(P) -> toroco_pru_port:configure_watchdog(P, W) end},
     {enabled, fun(P) -> toroco_pru_port:enable_servos(P, On) end}].

%% @doc The program's watchdog put the servos at neutral.
-spec port_event(toroco_pru_port:event(), map()) -> toroco_behavior:result().
port_event({watchdog, _T}, D) ->
    watchdog(D).

%% @doc A restarted program or a lost owner leaves the servos at neutral.
%% Once the port is back (restarted, or attached again) the wiring's current
%% command (a latched setvel) is asked for again, so the robot carries on.
-spec port_status(attached | restarted | lost, map()) -> {map(), toroco_behavior:actions()}.
port_status(attached, D) ->
    {D, keepalive(D) ++ [{redeliver, [setvel]}]};
port_status(restarted, D) ->
    {keep_state, D1, Actions} = applied(?STOP, D#{commanded := ?STOP}),
    {D1, Actions ++ [{redeliver, [setvel]}]};
port_status(lost, D) ->
    {keep_state, D1, Actions} = applied(?STOP, D#{commanded := ?STOP}),
    {D1, Actions}.

%%====================================================================
%% Driving
%%====================================================================

%% The servos follow the command while enabled, stand at neutral otherwise.
drive(D = #{enabled := false}) ->
    applied(?STOP, D);
drive(D = #{commanded := Cmd}) ->
    case port(D, fun(P) -> toroco_pru_port:set_servos(P, to_map(Cmd)) end) of
        {ok, D1} -> applied(Cmd, D1);
        {error, D1} -> {keep_state, D1}
    end.

watchdog(D = #{watchdogs := N, applied := ?STOP}) ->
    {keep_state, D#{watchdogs := N + 1, commanded := ?STOP}};
watchdog(D = #{watchdogs := N, name := Name}) ->
    %% The program is at neutral already; saying so again also undoes a
    %% keepalive that was queued behind the stall and re-drove the old speed.
    logger:warning("~p: pru_port watchdog fired; servos at neutral until the next setvel",
                   [Name], #{domain => [toroco, hw]}),
    {_, D1} = port(D, fun(P) -> toroco_pru_port:set_servos(P, to_map(?STOP)) end),
    applied(?STOP, D1#{watchdogs := N + 1, commanded := ?STOP}).

applied(V, D = #{applied := V}) ->
    {keep_state, D, []};
applied(V, D) ->
    {keep_state, D#{applied := V}, [{send, #{applied => V}}]}.

port(D = #{client := C, port_errors := N, name := Name}, F) ->
    case toroco_pru_client:call(C, F) of
        ok -> {ok, D};
        {error, Reason} ->
            logger:warning("~p: servo command refused: ~0p", [Name, Reason],
                           #{domain => [toroco, hw]}),
            {error, D#{port_errors := N + 1}}
    end.

%% The watchdog it feeds counts real time, so the keepalive does too: an
%% absolute deadline on the monotonic clock, which the engine passes as is
%% whatever the runtime clock's speed (toroco_clock scales relative ones).
keepalive(D) ->
    case keepalive_ms(D) of
        off -> [];
        Ms -> [{{timeout, keepalive}, erlang:monotonic_time(millisecond) + Ms, tick,
                [{abs, true}]}]
    end.

keepalive_ms(#{keepalive := true, watchdog_ms := W}) when W > 0 -> max(10, W div 3);
keepalive_ms(_) -> off.

to_map({L, R}) -> #{left => L, right => R}.

velocity(V) -> max(-100, min(100, round(V))).

clamps({L, R}, {CL, CR}) ->
    length([x || {V, C} <- [{L, CL}, {R, CR}], round(V) =/= C]).

%%====================================================================
%% Options
%%====================================================================

options(Opts) ->
    Allowed = [port, servos, watchdog_ms, keepalive, enabled | toroco_pru_client:owner_keys()],
    Checks = [{servos, fun servos/1, #{}},
              {watchdog_ms, fun(V) -> is_integer(V) andalso V >= 0 end, 500},
              {keepalive, fun is_boolean/1, true},
              {enabled, fun is_boolean/1, true}],
    case [K || K <- maps:keys(Opts), not lists:member(K, Allowed)] of
        [K | _] ->
            {error, {unknown_option, K}};
        [] ->
            case toroco_pru_client:parse(Opts) of
                {ok, _} -> check(Checks, Opts, #{});
                Err -> Err
            end
    end.

check([], _Opts, Acc) ->
    {ok, Acc};
check([{K, Check, Default} | Rest], Opts, Acc) ->
    V = maps:get(K, Opts, Default),
    case Check(V) of
        true -> check(Rest, Opts, Acc#{K => V});
        false -> {error, {bad_option, {K, V}}};
        {ok, V1} -> check(Rest, Opts, Acc#{K => V1});
        {error, Why} -> {error, {bad_option, {K, Why}}}
    end.

servos(M) when is_map(M) ->
    Defaults = default_servos(),
    case maps:keys(maps:without([left, right], M)) of
        [Bad | _] -> {error, {unknown_servo, Bad}};
        [] ->
            Merged = maps:map(fun(Side, Base) -> maps:merge(Base, maps:get(Side, M, #{})) end,
                              Defaults),
            case [{Side, Why} || {Side, Cal} <- maps:to_list(Merged),
                                 Why <- [calibration_error(Cal, maps:get(Side, M, #{}))],
                                 Why =/= ok] of
                [] -> {ok, Merged};
                [E | _] -> {error, E}
            end
    end;
servos(Other) ->
    {error, {not_a_map, Other}}.

calibration_error(_Cal, Given) when not is_map(Given) ->
    {not_a_map, Given};
calibration_error(Cal = #{period_ns := P, neutral_ns := N, span_ns := S}, Given) ->
    case [K || K <- maps:keys(Given), not lists:member(K, ?CALIB_KEYS)] of
        [K | _] -> {unknown_key, K};
        [] ->
            Ints = [pwmchip, channel, period_ns, neutral_ns, span_ns],
            case [K || K <- Ints, not (is_integer(maps:get(K, Cal)) andalso maps:get(K, Cal) >= 0)] of
                [K | _] -> {K, maps:get(K, Cal)};
                [] when not is_boolean(map_get(reversed, Cal)) -> {reversed, map_get(reversed, Cal)};
                [] when P =:= 0; S > N; N + S > P -> {pulse_out_of_period, {P, N, S}};
                [] -> ok
            end
    end.

%% A private fake PWM tree for an own owner on the sim backend, so that the
%% program's real PWM code runs against plain files.
own_sysfs(Name, Opts, Servos) ->
    Own = not maps:is_key(port, Opts),
    case Own andalso maps:get(backend, Opts, sim) =:= sim andalso
        not maps:is_key(sysfs_root, Opts) of
        true ->
            Root = filename:join(tmp_base(),
                                 lists:flatten(io_lib:format("toroco_servo_motors_~s_~s_~b",
                                                             [Name, os:getpid(),
                                                              erlang:unique_integer([positive])]))),
            _ = [fake_pwm(Root, Chip, Ch)
                 || #{pwmchip := Chip, channel := Ch} <- maps:values(Servos)],
            {Opts#{sysfs_root => Root}, Root};
        false ->
            {Opts, undefined}
    end.

tmp_base() ->
    case os:getenv("TMPDIR") of
        false -> "/tmp";
        "" -> "/tmp";
        Dir -> Dir
    end.

fake_pwm(Root, Chip, Ch) ->
    ChipDir = filename:join(Root, "class/pwm/pwmchip" ++ integer_to_list(Chip)),
    Dir = filename:join(ChipDir, "pwm" ++ integer_to_list(Ch)),
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    ok = file:write_file(filename:join(ChipDir, "export"), ""),
    _ = [ok = file:write_file(filename:join(Dir, F), "0\n")
         || F <- ["period", "duty_cycle", "enable"]],
    ok.

remove_tmp(undefined) -> ok;
remove_tmp(Dir) -> _ = file:del_dir_r(Dir), ok.
