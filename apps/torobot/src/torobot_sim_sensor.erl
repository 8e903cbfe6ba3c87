%% @doc A simulated sensor device: the simulator feeds it readings, it
%% emits those that changed, latched, so a behavior that starts or
%% restarts gets the current reading at once.
%%
%% `torobot_sim' adds one per device of `torobot_sensors:devices/0'
%% (`range', `bumper', `odometry', `light', `beacon') and calls
%% {@link feed/2} each tick (in lockstep, {@link stimulus/2} hands the
%% same readings in as a step). Options: `outputs' (required).
-module(torobot_sim_sensor).
-behaviour(toroco_device).

-export([feed/2, stimulus/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2]).

%% @doc Hands readings `#{Out => Value}' to device `Name' (asynchronous).
-spec feed(atom(), #{atom() => term()}) -> ok.
feed(Name, Readings) ->
    toroco_device:cast(Name, {?MODULE, Readings}).

%% @doc Lockstep: readings for device `Name', as a stimulus for
%% `toroco_clock:tick/2'.
-spec stimulus(atom(), #{atom() => term()}) -> toroco_clock:stimulus().
stimulus(Name, Readings) ->
    {Name, {?MODULE, Readings}}.

-spec interface(map()) -> #{inputs := [], outputs := [atom()]}.
interface(#{outputs := Outs}) when is_list(Outs) -> #{inputs => [], outputs => Outs};
interface(Opts) -> error({bad_option, {outputs, maps:get(outputs, Opts, missing)}}).

-spec init(atom(), map()) -> {ok, sensing, map()}.
init(_Name, #{outputs := Outs}) ->
    {ok, sensing, #{outputs => Outs, last => #{}, emitted => 0}}.

-spec handle_input(atom(), term(), sensing, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), sensing, map()) -> toroco_behavior:result().
handle_event(Type, {?MODULE, Readings}, _State, D = #{outputs := Outs, last := Last, emitted := N})
  when Type =:= cast; Type =:= info ->
    Changed = maps:filter(fun(Out, V) -> lists:member(Out, Outs) andalso
                                             maps:get(Out, Last, undefined) =/= V
                          end, Readings),
    case map_size(Changed) of
        0 -> keep_state_and_data;
        K -> {keep_state, D#{last := maps:merge(Last, Changed), emitted := N + K},
              [{set, Changed}]}
    end;
handle_event({call, From}, Request, _State, _D) ->
    %% fed by the world, not polled: a Lua converter on it applies alone
    {keep_state_and_data, [{reply, From, {error, {unknown_call, Request}}}]};
handle_event(_Type, _Content, _State, _D) ->
    keep_state_and_data.

-spec info(sensing, map()) -> map().
info(_State, #{last := Last, emitted := N}) ->
    #{readings => Last, emitted => N}.
