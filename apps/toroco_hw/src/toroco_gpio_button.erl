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
%% {@link sim_button/2} sets the line's physical level on the sim backend;
%% in lockstep (SPEC §14) {@link stimulus/2} hands a debounced edge in as a
%% step instead.
%%
%% `info/2': `line', `active_low', `debounce_ms', `last', `edges', and the
%% attachment's keys (`port_status', `reconnect_failures', ...: see
%% `toroco_pru_client:describe/1').
-module(toroco_gpio_button).
-behaviour(toroco_device).
-behaviour(toroco_pru_client).

-export([sim_button/2, stimulus/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).
-export([configure/1, port_event/2]).

%% What sim_button/2 asks the device for: its owner.
-define(SIM_CALL, '$toroco_gpio_button_sim').

%% @doc Sim backend: the button line's physical level (0 or 1); with the
%% default `active_low', 0 is pressed.
-spec sim_button(atom(), 0 | 1) -> ok | {error, term()}.
sim_button(Device, Level) ->
    toroco_pru_client:sim(Device, ?SIM_CALL,
                          fun(Port, _) -> toroco_pru_port:sim_button(Port, Level) end).

%% @doc Lockstep: a debounced edge of device `Device', as a stimulus for
%% `toroco_clock:tick/2'.
-spec stimulus(atom(), pressed | released) -> toroco_clock:stimulus().
stimulus(Device, Edge) ->
    {Device, {?MODULE, edge, Edge}}.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [], outputs := [button]}.
interface(_Opts) ->
    #{inputs => [], outputs => [button]}.

-spec init(atom(), map()) -> {ok, up, map()} | {error, term()}.
init(Name, Opts) ->
    toroco_pru_client:init(?MODULE, Name, options(Opts)).

%% The button has no inputs: nothing is ever delivered.
-spec handle_input(atom(), term(), up | down, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), up | down, map()) ->
          toroco_behavior:result().
handle_event({call, From}, ?SIM_CALL, _State, D = #{button := #{line := Line}}) ->
    {keep_state_and_data, [{reply, From, toroco_pru_client:sim_reply(D, Line)}]};
handle_event(info, {?MODULE, edge, Edge}, _State, D) when Edge =:= pressed; Edge =:= released ->
    port_event({button, Edge, 0}, D);
handle_event(Type, Content, State, D) when Type =:= info; Type =:= {timeout, reconnect} ->
    toroco_pru_client:handle_event(?MODULE, Type, Content, State, D).

-spec info(up | down, map()) -> map().
info(_State, #{client := C, button := B, last := Last, edges := N}) ->
    maps:merge(toroco_pru_client:describe(C), B#{last => Last, edges => N}).

-spec terminate(term(), up | down, map()) -> ok.
terminate(_Reason, _State, #{client := C}) ->
    toroco_pru_client:release(C, fun(P) -> toroco_pru_port:configure_button(P, none) end).

%%====================================================================
%% toroco_pru_client
%%====================================================================

%% @doc The button section of the program.
-spec configure(map()) -> [{button, fun((pid()) -> ok | {error, term()})}].
configure(#{button := Button}) ->
    [{button, fun(P) -> toroco_pru_port:configure_button(P, Button) end}].

%% @doc Each debounced edge is sent on `button'.
-spec port_event(toroco_pru_port:event(), map()) -> toroco_behavior:result().
port_event({button, Edge, _T}, D = #{edges := N}) ->
    {keep_state, D#{last := Edge, edges := N + 1}, [{send, #{button => Edge}}]}.

%%====================================================================
%% Internals
%%====================================================================

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
                    Button = #{line => Line, active_low => ActiveLow, debounce_ms => Debounce},
                    {ok, #{button => Button, last => none, edges => 0}, C};
                Err -> Err
            end
    end.
