%% @doc A push button on a GPIO line, read by the `pru_port' program through
%% libgpiod, as a sensor device.
%%
%% Output `button': `{send, #{button => pressed | released}}' on each
%% debounced edge.
%%
%% Options:
%% <ul>
%% <li>`line' (required): the line offset on the GPIO chip.</li>
%% <li>`active_low' (default `true': a button to ground, line pulled up) and
%%     `debounce_ms' (default 20).</li>
%% <li>`gpiochip' (default `/dev/gpiochip0'): the chip, for an own owner; a
%%     shared owner (`port') was started with its chip.</li>
%% <li>`port', or the owner options (`backend', default `sim', ...), as in
%%     `toroco_pru_client'. The program reads one button, so one
%%     `toroco_gpio_button' device serves one owner.</li>
%% </ul>
%% {@link sim_button/2} sets the line's physical level on the sim backend.
%%
%% `info/2': `line', `active_low', `debounce_ms', `last', `edges',
%% `reconnect_failures', and the attachment's `port', `port_status',
%% `port_restarts', `port_losses'.
-module(toroco_gpio_button).
-behaviour(toroco_device).

-export([sim_button/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).

-define(SIM_CALL, '$toroco_gpio_button_sim').

%% @doc Sim backend: the button line's physical level (0 or 1); with the
%% default `active_low', 0 is pressed.
-spec sim_button(atom(), 0 | 1) -> ok | {error, term()}.
sim_button(Device, Level) ->
    try gen_statem:call(toroco_names:process(Device), ?SIM_CALL, 5000) of
        {ok, Port} ->
            try toroco_pru_port:sim_button(Port, Level)
            catch exit:{Reason, _} -> {error, {port_call, Reason}}
            end;
        {error, _} = Err ->
            Err
    catch
        exit:{noproc, _} -> {error, {not_running, Device}};
        exit:{Reason, _} -> {error, {Reason, Device}}
    end.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [], outputs := [button]}.
interface(_Opts) ->
    #{inputs => [], outputs => [button]}.

-spec init(atom(), map()) -> {ok, up, map()} | {error, term()}.
init(Name, Opts) ->
    case options(Opts) of
        {ok, Button, Client} ->
            case toroco_pru_client:attach(Client, configure(Button)) of
                {ok, C1} ->
                    {ok, up, #{name => Name, client => C1, button => Button, last => none,
                               edges => 0, reconnect_failures => 0}};
                {error, Reason, _} ->
                    logger:warning("~p (toroco_gpio_button) not started: ~0p", [Name, Reason],
                                   #{domain => [toroco, hw]}),
                    {error, Reason}
            end;
        {error, _} = Err ->
            Err
    end.

-spec handle_input(atom(), term(), up | down, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), up | down, map()) ->
          toroco_behavior:result().
handle_event({call, From}, ?SIM_CALL, _State, #{name := Name, client := C}) ->
    Reply = case toroco_pru_client:server(C) of
                undefined -> {error, {port_down, Name}};
                Pid -> {ok, Pid}
            end,
    {keep_state_and_data, [{reply, From, Reply}]};
handle_event({timeout, reconnect}, attach, down, D = #{name := Name, client := C,
                                                       button := B}) ->
    case toroco_pru_client:attach(C, configure(B)) of
        {ok, C1} ->
            logger:notice("~p attached to its pru_port again", [Name], #{domain => [toroco, hw]}),
            {next_state, up, D#{client := C1}};
        {error, Reason, C1} ->
            #{reconnect_failures := N} = D,
            {Ms, C2} = toroco_pru_client:retry_ms(C1),
            logger:warning("~p could not attach to its pru_port (~0p); next try in ~b ms",
                           [Name, Reason, Ms], #{domain => [toroco, hw]}),
            {keep_state, D#{client := C2, reconnect_failures := N + 1},
             [{{timeout, reconnect}, Ms, attach}]}
    end;
handle_event(info, Msg, _State, D = #{name := Name, client := C, edges := N}) ->
    case toroco_pru_client:handle_info(Msg, C) of
        {event, {button, Edge, _T}} ->
            {keep_state, D#{last := Edge, edges := N + 1}, [{send, #{button => Edge}}]};
        {event, _} ->
            keep_state_and_data;
        {restarted, _Why, C1} ->
            {keep_state, D#{client := C1}};
        {lost, Why, C1} ->
            logger:warning("~p lost its pru_port (~0p); attaching again", [Name, Why],
                           #{domain => [toroco, hw]}),
            {Ms, C2} = toroco_pru_client:retry_ms(C1),
            {next_state, down, D#{client := C2}, [{{timeout, reconnect}, Ms, attach}]};
        unknown ->
            keep_state_and_data
    end;
handle_event({call, From}, Request, _State, #{name := Name}) ->
    {keep_state_and_data, [{reply, From, {error, {unknown_call, {Name, Request}}}}]};
handle_event(_Type, _Content, _State, _D) ->
    keep_state_and_data.

-spec info(up | down, map()) -> map().
info(_State, #{client := C, button := B, last := Last, edges := N, reconnect_failures := RF}) ->
    maps:merge(toroco_pru_client:describe(C),
               B#{last => Last, edges => N, reconnect_failures => RF}).

-spec terminate(term(), up | down, map()) -> ok.
terminate(_Reason, _State, #{client := C}) ->
    case toroco_pru_client:is_own(C) of
        true -> ok;
        false -> _ = toroco_pru_client:call(C, fun(P) -> toroco_pru_port:configure_button(P, none) end)
    end,
    _ = toroco_pru_client:detach(C),
    ok.

%%====================================================================
%% Internals
%%====================================================================

configure(Button) ->
    fun(P) ->
            case toroco_pru_port:configure_button(P, Button) of
                ok -> ok;
                {error, R} -> {error, {button, R}}
            end
    end.

options(Opts) ->
    Allowed = [port, line, active_low, debounce_ms | toroco_pru_client:owner_keys()],
    Line = maps:get(line, Opts, missing),
    ActiveLow = maps:get(active_low, Opts, true),
    Debounce = maps:get(debounce_ms, Opts, 20),
    case [K || K <- maps:keys(Opts), not lists:member(K, Allowed)] of
        [K | _] -> {error, {unknown_option, K}};
        [] when not is_integer(Line); Line < 0 -> {error, {bad_option, {line, Line}}};
        [] when not is_boolean(ActiveLow) -> {error, {bad_option, {active_low, ActiveLow}}};
        [] when not is_integer(Debounce); Debounce < 0 ->
            {error, {bad_option, {debounce_ms, Debounce}}};
        [] ->
            case toroco_pru_client:parse(Opts) of
                {ok, C} ->
                    {ok, #{line => Line, active_low => ActiveLow, debounce_ms => Debounce}, C};
                Err -> Err
            end
    end.
