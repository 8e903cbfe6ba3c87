%% @doc Dock: home on a beacon and stop on the dock.
%%
%% Inputs: `beacon', `{BearingDeg, DistanceM}' of the dock's beacon
%% (bearing counter-clockwise from the heading, so positive is to the
%% left) or `none' when it cannot be seen; `docked', `true' on the dock's
%% contacts, else `false'.
%% Outputs: `motors', latched: while the beacon is seen and the robot is
%% not docked, a spin towards it when it is more than `align_deg' off the
%% heading, else forward (at `slow_speed' within `slow_within' metres) with
%% a turn of `gain' x bearing clamped to `max_turn'; `{0, 0}' once docked,
%% for as long as it is; unset when the beacon is lost, so lower layers
%% search.
%%
%% Parameters: `speed' [50], `slow_speed' [25], `slow_within' [0.5] m,
%% `gain' [1.0] (servo units per degree), `max_turn' [30], `align_deg'
%% [40], `spin' [35].
%%
%% Usual layer: above `wander', below `avoid' (docks stand in the open).
-module(toroco_lib_dock).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4]).

-type state() :: searching | homing | docked.

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{speed, speed, 50}, {slow_speed, speed, 25}, {slow_within, metres, 0.5},
     {gain, non_neg_number, 1.0}, {max_turn, pos_speed, 30}, {align_deg, pos_number, 40},
     {spin, pos_speed, 35}].

-spec interface() -> #{inputs := [beacon | docked], outputs := [motors]}.
interface() -> #{inputs => [beacon, docked], outputs => [motors]}.

-spec init(map()) -> {ok, searching, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, P} -> {ok, searching, P#{last => none, beacon => none}};
        {error, _} = Error -> Error
    end.

-spec handle_input(beacon | docked, term(), state(), map()) -> toroco_behavior:result().
handle_input(docked, true, _State, #{last := Last} = P) ->
    {Actions, Last1} = toroco_lib_drive:set({0, 0}, Last),
    {next_state, docked, P#{last := Last1}, Actions};
handle_input(docked, _Off, docked, P) ->
    home(P);
handle_input(docked, _Off, _State, _P) ->
    keep_state_and_data;
handle_input(beacon, Beacon, docked, P) ->
    {keep_state, P#{beacon := Beacon}};
handle_input(beacon, Beacon, _State, P) ->
    home(P#{beacon := Beacon}).

home(#{beacon := {Bearing, Dist}, last := Last} = P) when is_number(Bearing), is_number(Dist) ->
    {Actions, Last1} = toroco_lib_drive:set(command(Bearing, Dist, P), Last),
    {next_state, homing, P#{last := Last1}, Actions};
home(#{last := Last} = P) ->
    {Actions, Last1} = toroco_lib_drive:release(Last),
    {next_state, searching, P#{last := Last1}, Actions}.

command(Bearing, _Dist, #{align_deg := Align, spin := Spin}) when abs(Bearing) > Align ->
    toroco_lib_drive:spin(case Bearing > 0 of true -> left; false -> right end, Spin);
command(Bearing, Dist, #{speed := S, slow_speed := Slow, slow_within := Within, gain := G,
                         max_turn := M}) ->
    Speed = case Dist =< Within of true -> Slow; false -> S end,
    toroco_lib_drive:steer(Speed, -max(-M, min(M, G * Bearing))).
