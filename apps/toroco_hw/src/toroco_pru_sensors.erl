%% @doc The PRU's ADC sensors (the Torobot's Sharp IR pair) as a device: one
%% output per sensor, fed by the `pru_port' program's change reports.
%%
%% Options:
%% <ul>
%% <li>`sensors' (required): `[{SensorName, #{channel => 0..7, mode => analog |
%%     analog_threshold, threshold_high => 0..4095, threshold_low => 0..4095}}]';
%%     the thresholds are required for `analog_threshold', `low < high'.
%%     Each sensor name is an output.</li>
%% <li>`port': a `toroco_pru_port' owner (registered name or pid) shared with
%%     the other PRU devices; without it the device starts its own owner from
%%     the owner options (`backend', default `sim', `sysfs_root', `executable',
%%     `sim_script', ...; see `toroco_pru_client').</li>
%% </ul>
%% The device configures the owner's whole ADC channel set, so one
%% `toroco_pru_sensors' device serves one owner.
%%
%% It emits `{send, #{Sensor => Value}}' on each reported change: the raw
%% value for `analog'; for `analog_threshold', `1' once a sample reaches
%% `threshold_high' (near, for a Sharp IR) and `0' once one falls to
%% `threshold_low', with the hysteresis done by the C program (the same code
%% the PRU firmware runs). A value equal to the sensor's last emitted one is
%% not emitted again (after a program restart the first sample is reported
%% anew). {@link sim_adc/3} feeds a raw sample to a sensor's channel through
%% the sim backend: the simulator's way in. In lockstep (SPEC §14) the
%% simulator hands samples in as steps instead ({@link stimulus/3}): the
%% device runs the program's threshold and hysteresis itself (the same
%% rule as `adc_hysteresis' in `c_src/pru_port/src/adc_filter.c'), so no
%% sample waits on a port's timing.
%%
%% `info/2' (under `device' in `toroco:inspect(Name)'): `sensors' (channel,
%% mode, last value), `emitted', `foreign_events' (reports of channels that
%% are not this device's) and the attachment's keys (`port', `port_status',
%% `port_restarts', `port_losses', `reconnect_failures').
-module(toroco_pru_sensors).
-behaviour(toroco_device).
-behaviour(toroco_pru_client).

-export([sim_adc/3, stimulus/3]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).
-export([configure/1, port_event/2]).

%% What sim_adc/3 asks the device for: its owner and the sensor's channel.
-define(SIM_CALL, '$toroco_pru_sensors_sim').

%%====================================================================
%% API
%%====================================================================

%% @doc Sim backend: one raw ADC sample (0..4095) on `Sensor''s channel of
%% device `Device', through the program's real threshold/hysteresis code. The
%% event it causes is on its way to the device when this returns.
-spec sim_adc(atom(), atom(), 0..4095) -> ok | {error, term()}.
sim_adc(Device, Sensor, Raw) ->
    toroco_pru_client:sim(Device, {?SIM_CALL, Sensor},
                          fun(Port, Channel) -> toroco_pru_port:sim_adc(Port, Channel, Raw) end).

%% @doc Lockstep: one raw ADC sample of `Sensor' for device `Device', as a
%% stimulus for `toroco_clock:tick/2'.
-spec stimulus(atom(), atom(), 0..4095) -> toroco_clock:stimulus().
stimulus(Device, Sensor, Raw) ->
    {Device, {?MODULE, sample, Sensor, Raw}}.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [], outputs := [atom()]}.
interface(Opts) ->
    Outs = case maps:get(sensors, Opts, []) of
               L when is_list(L) -> [N || {N, _} <- L, is_atom(N)];
               _ -> []
           end,
    #{inputs => [], outputs => lists:usort(Outs)}.

-spec init(atom(), map()) -> {ok, up, map()} | {error, term()}.
init(Name, Opts) ->
    toroco_pru_client:init(?MODULE, Name, options(Opts)).

%% The sensors are outputs only: nothing is ever delivered.
-spec handle_input(atom(), term(), up | down, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), up | down, map()) ->
          toroco_behavior:result().
handle_event({call, From}, {?SIM_CALL, Sensor}, _State, D = #{name := Name,
                                                              sensors := Sensors}) ->
    Reply = case lists:keyfind(Sensor, 1, Sensors) of
                false -> {error, {unknown_sensor, {Name, Sensor}}};
                {_, #{channel := Ch}} -> toroco_pru_client:sim_reply(D, Ch)
            end,
    {keep_state_and_data, [{reply, From, Reply}]};
handle_event(info, {?MODULE, sample, Sensor, Raw}, _State, D = #{sensors := Sensors}) ->
    case lists:keyfind(Sensor, 1, Sensors) of
        {_, #{channel := Ch} = Cfg} when is_integer(Raw), Raw >= 0, Raw =< 4095 ->
            port_event({adc, Ch, filter(Raw, Cfg, maps:get(Sensor, maps:get(last, D), -1)), 0}, D);
        _ ->
            logger:warning("~p: sample ~0p for sensor ~0p refused", [maps:get(name, D), Raw, Sensor],
                           #{domain => [toroco, hw]}),
            keep_state_and_data
    end;
handle_event(Type, Content, State, D) when Type =:= info; Type =:= {timeout, reconnect} ->
    toroco_pru_client:handle_event(?MODULE, Type, Content, State, D).

-spec info(up | down, map()) -> map().
info(_State, #{client := C, sensors := Sensors, last := Last, emitted := E, foreign := F}) ->
    Ss = maps:from_list([{S, Cfg#{value => case Last of #{S := V} -> {value, V}; #{} -> none end}}
                         || {S, Cfg} <- Sensors]),
    maps:merge(toroco_pru_client:describe(C),
               #{sensors => Ss, emitted => E, foreign_events => F}).

-spec terminate(term(), up | down, map()) -> ok.
terminate(_Reason, _State, #{client := C}) ->
    %% a shared owner keeps the channels: its next ADC device sets its own
    toroco_pru_client:release(C, fun(_) -> ok end).

%%====================================================================
%% toroco_pru_client
%%====================================================================

%% @doc The whole ADC channel set of the program.
-spec configure(map()) -> [{adc, fun((pid()) -> ok | {error, term()})}].
configure(#{sensors := Sensors}) ->
    Channels = [maps:with([channel, mode, threshold_high, threshold_low], Cfg)
                || {_, Cfg} <- Sensors],
    [{adc, fun(P) -> toroco_pru_port:configure_adc(P, Channels) end}].

%% @doc A changed reading of one of this device's channels is sent on its
%% sensor's output; other channels are counted as foreign.
-spec port_event(toroco_pru_port:event(), map()) -> toroco_behavior:result().
port_event({adc, Ch, V, _T}, D = #{by_channel := ByCh, last := Last, emitted := E,
                                   foreign := F}) ->
    case ByCh of
        #{Ch := S} ->
            case Last of
                #{S := V} -> keep_state_and_data;
                #{} -> {keep_state, D#{last := Last#{S => V}, emitted := E + 1},
                        [{send, #{S => V}}]}
            end;
        #{} ->
            {keep_state, D#{foreign := F + 1}}
    end.

%%====================================================================
%% Internals
%%====================================================================

%% The program's filter (adc_filter.c): raw for `analog'; for
%% `analog_threshold' 1 from `threshold_high' up, 0 from `threshold_low'
%% down, the previous value in between (0 before any).
filter(Raw, #{mode := analog}, _Prev) -> Raw;
filter(Raw, #{threshold_high := High}, _Prev) when Raw >= High -> 1;
filter(Raw, #{threshold_low := Low}, _Prev) when Raw =< Low -> 0;
filter(_Raw, _Cfg, Prev) when Prev < 0 -> 0;
filter(_Raw, _Cfg, Prev) -> Prev.

options(Opts) ->
    Allowed = [port, sensors | toroco_pru_client:owner_keys()],
    case [K || K <- maps:keys(Opts), not lists:member(K, Allowed)] of
        [K | _] -> {error, {unknown_option, K}};
        [] ->
            case sensors(maps:get(sensors, Opts, missing)) of
                {ok, Sensors} ->
                    case toroco_pru_client:parse(Opts) of
                        {ok, C} ->
                            ByChannel = [{Ch, S} || {S, #{channel := Ch}} <- Sensors],
                            {ok, #{sensors => Sensors, by_channel => maps:from_list(ByChannel),
                                   last => #{}, emitted => 0, foreign => 0}, C};
                        Err -> Err
                    end;
                Err -> Err
            end
    end.

sensors(L) when is_list(L), L =/= [] ->
    case lists:foldl(fun sensor/2, {ok, []}, L) of
        {ok, Rev} ->
            Sensors = lists:reverse(Rev),
            Names = [N || {N, _} <- Sensors],
            Chs = [Ch || {_, #{channel := Ch}} <- Sensors],
            case {Names -- lists:usort(Names), Chs -- lists:usort(Chs)} of
                {[], []} -> {ok, Sensors};
                {[N | _], _} -> {error, {bad_option, {sensors, {duplicate_sensor, N}}}};
                {[], [Ch | _]} -> {error, {bad_option, {sensors, {duplicate_channel, Ch}}}}
            end;
        Err -> Err
    end;
sensors(Other) ->
    {error, {bad_option, {sensors, Other}}}.

sensor(_, {error, _} = Err) ->
    Err;
sensor({Name, Cfg} = S, {ok, Acc}) when is_atom(Name), is_map(Cfg) ->
    Keys = [channel, mode, threshold_high, threshold_low],
    Mode = maps:get(mode, Cfg, analog),
    Ch = maps:get(channel, Cfg, missing),
    case [K || K <- maps:keys(Cfg), not lists:member(K, Keys)] of
        [K | _] -> {error, {bad_option, {sensors, {Name, {unknown_key, K}}}}};
        [] when not is_integer(Ch); Ch < 0; Ch > 7 ->
            {error, {bad_option, {sensors, {Name, {channel, Ch}}}}};
        [] when Mode =:= analog ->
            case maps:is_key(threshold_high, Cfg) orelse maps:is_key(threshold_low, Cfg) of
                true -> {error, {bad_option, {sensors, {Name, thresholds_need_analog_threshold}}}};
                false -> {ok, [{Name, #{channel => Ch, mode => analog}} | Acc]}
            end;
        [] when Mode =:= analog_threshold ->
            High = maps:get(threshold_high, Cfg, missing),
            Low = maps:get(threshold_low, Cfg, missing),
            case is_integer(High) andalso is_integer(Low) andalso
                0 =< Low andalso Low < High andalso High =< 4095 of
                true ->
                    {ok, [{Name, #{channel => Ch, mode => analog_threshold,
                                   threshold_high => High, threshold_low => Low}} | Acc]};
                false ->
                    {error, {bad_option, {sensors, {Name, {thresholds, High, Low}}}}}
            end;
        [] ->
            {error, {bad_option, {sensors, {element(1, S), {mode, Mode}}}}}
    end;
sensor(Other, _) ->
    {error, {bad_option, {sensors, Other}}}.
