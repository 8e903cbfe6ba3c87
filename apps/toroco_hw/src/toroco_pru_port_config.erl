%% @doc The configuration of a `pru_port' program, as pure functions for
%% its owner (`toroco_pru_port'): the options checked and turned into the
%% protocol's wire terms (`c_src/pru_port/PROTOCOL.md'), the order in
%% which a new program is configured, what an accepted request changes in
%% the configuration a restart re-applies, which requests wait for a
%% program, and the delay before the next one.
%%
%% Functions, by purpose:
%% <ul>
%% <li>the configuration: `initial_config/1', `config_steps/1', `remember/3',
%%     and the wire form of each section: `wire_adc/1', `wire_servos/1',
%%     `wire_button/1'</li>
%% <li>restarts: `waits_for_program/1', `backoff/2'</li>
%% </ul>
-module(toroco_pru_port_config).

-export([initial_config/1, config_steps/1, remember/3,
         wire_adc/1, wire_servos/1, wire_button/1,
         waits_for_program/1, backoff/2]).

-export_type([config/0, opts/0, adc_channel/0, servo_id/0, servo/0, button/0]).

%% The options of toroco_pru_port:start_link/1 and their parts.
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
                  max_restarts => {non_neg_integer(), pos_integer()},
                  hello_timeout_ms => pos_integer(),
                  reply_timeout_ms => pos_integer(),
                  restart_backoff => {non_neg_integer(), non_neg_integer()}}.

%% The configuration as applied, in wire form: `adc', `servos', `button',
%% `watchdog' and `enabled'.
-type config() :: #{atom() => term()}.

-define(DEFAULT_PERIOD_NS, 20000000).
-define(DEFAULT_NEUTRAL_NS, 1500000).
-define(DEFAULT_SPAN_NS, 500000).

%%% ---------------------------------------------------------------------
%%% The configuration
%%% ---------------------------------------------------------------------

-spec initial_config(opts()) -> {ok, config()} | {error, term()}.
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

%% Each section in a fixed order: the watchdog and servos first so that
%% outputs are safe before any input starts reporting, and neutral as the
%% first servo command of every program.
-spec config_steps(config()) -> [{atom(), toroco_pru_port:request()}].
config_steps(Config) ->
    Steps = [{watchdog, {configure_watchdog, maps:get(watchdog, Config)}},
             {servos, {configure_servos, maps:get(servos, Config)}},
             {neutral, neutral},
             {enabled, {enable_servos, maps:get(enabled, Config)}},
             {adc, {configure_adc, maps:get(adc, Config)}},
             {button, maps:get(button, Config)}],
    %% servos start disabled, and a button unconfigured: saying so again
    %% would only arm the watchdog
    [S || S <- Steps, S =/= {enabled, {enable_servos, false}},
          S =/= {button, {configure_button, none}}].

%% Accepted configuration requests become the configuration re-applied
%% after a restart.
-spec remember(toroco_pru_port:request(), term(), config()) -> config().
remember(Request, ok, Config) ->
    case Request of
        {configure_adc, Wire} -> Config#{adc := Wire};
        {configure_servos, Wire} -> Config#{servos := Wire};
        {enable_servos, On} -> Config#{enabled := On};
        {configure_watchdog, Ms} -> Config#{watchdog := Ms};
        {configure_button, _} = B -> Config#{button := B};
        {configure_button, _, _, _} = B -> Config#{button := B};
        _ -> Config
    end;
remember(_Request, _Result, Config) ->
    Config.

%%% ---------------------------------------------------------------------
%%% Restarts
%%% ---------------------------------------------------------------------

%% Configuration follows the re-applied configuration, so it waits; a
%% neutral waits for a program that can take it. Anything else is answered
%% at once: a velocity is not kept for later.
-spec waits_for_program(toroco_pru_port:request()) -> boolean().
waits_for_program(neutral) -> true;
waits_for_program({configure_adc, _}) -> true;
waits_for_program({configure_servos, _}) -> true;
waits_for_program({configure_watchdog, _}) -> true;
waits_for_program({configure_button, _}) -> true;
waits_for_program({configure_button, _, _, _}) -> true;
waits_for_program(_) -> false.

%% The delay before the next program: none after one that ran, then the
%% first delay doubled for each failure in a row, at most the last.
-spec backoff(non_neg_integer(), {non_neg_integer(), non_neg_integer()}) -> non_neg_integer().
backoff(0, _) -> 0;
backoff(Failures, {First, Max}) -> min(Max, First bsl min(Failures - 1, 20)).
