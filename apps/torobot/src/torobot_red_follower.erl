%% @doc Charge a red object: the Torobot's `red_follower', its highest layer.
%%
%% The `red' input is the camera's `update_red': `{X, Y}' pixels from the
%% frame's centre (x right) for the largest red blob of a frame, or `none'.
%% The behavior steers towards it with a latched command on `motors': a hard
%% turn beyond `hard_px' from the centre, a soft one beyond `soft_px',
%% straight ahead in between; it unsets when red is gone, handing the motors
%% back to the layers below. A command is set only when it changes, so a
%% steady blob costs nothing downstream.
%%
%% Params (defaults in brackets): `straight' [80], the speed of both wheels
%% ahead; `soft' [{80, 50}] and `hard' [{80, 20}], the `{Outer, Inner}'
%% wheel velocities of a soft and a hard turn (turning right puts `Outer'
%% on the left wheel); `soft_px' [25] and `hard_px' [50], the thresholds.
-module(torobot_red_follower).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).
-export([command/2]).

-define(DEFAULTS, #{straight => 80, soft => {80, 50}, hard => {80, 20},
                    soft_px => 25, hard_px => 50}).

-spec interface() -> #{inputs := [red], outputs := [motors]}.
interface() ->
    #{inputs => [red], outputs => [motors]}.

-spec init(map()) -> {ok, unseen, map()}.
init(Params) ->
    {ok, unseen, maps:merge(?DEFAULTS, Params)}.

-spec handle_input(red, term(), unseen | {charging, {number(), number()}}, map()) ->
          toroco_behavior:result().
handle_input(red, none, unseen, _P) ->
    keep_state_and_data;
handle_input(red, none, {charging, _}, P) ->
    {next_state, unseen, P, [{unset, [motors]}]};
handle_input(red, {X, _Y}, State, P) when is_number(X) ->
    case command(X, P) of
        Command when State =:= {charging, Command} -> keep_state_and_data;
        Command -> {next_state, {charging, Command}, P, [{set, #{motors => Command}}]}
    end;
handle_input(red, _Other, _State, _P) ->
    keep_state_and_data.

%% @doc The wheel velocities that steer towards a blob at `X' pixels right
%% of the centre, for the given params (the defaults fill what is missing).
-spec command(number(), map()) -> {number(), number()}.
command(X, Params) ->
    #{straight := S, soft := {SoftO, SoftI}, hard := {HardO, HardI},
      soft_px := SoftPx, hard_px := HardPx} = maps:merge(?DEFAULTS, Params),
    if
        X > HardPx -> {HardO, HardI};
        X > SoftPx -> {SoftO, SoftI};
        X < -HardPx -> {HardI, HardO};
        X < -SoftPx -> {SoftI, SoftO};
        true -> {S, S}
    end.
