%% @doc The Torobot's push button: each press toggles the motors on or off.
%%
%% The `press' input is wired to the button device; a press is `pressed',
%% `1' or `true' (what the GPIO button and the ADC button devices send),
%% anything else (a release) is ignored. The `enable' output is latched, so
%% the motors' `enable' input always has the current state, also after the
%% motors restart. At start it sets the initial state.
%%
%% Params: `enabled' (default `false': the robot waits for a press).
-module(torobot_button).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [press], outputs := [enable]}.
interface() ->
    #{inputs => [press], outputs => [enable]}.

-spec init(map()) -> {ok, boolean(), map(), toroco_behavior:actions()}.
init(Params) ->
    Enabled = maps:get(enabled, Params, false) =:= true,
    {ok, Enabled, Params, [{set, #{enable => Enabled}}]}.

-spec handle_input(press, term(), boolean(), map()) -> toroco_behavior:result().
handle_input(press, Press, Enabled, P) when Press =:= pressed; Press =:= 1; Press =:= true ->
    {next_state, not Enabled, P, [{set, #{enable => not Enabled}}]};
handle_input(press, _Release, _Enabled, _P) ->
    keep_state_and_data.
