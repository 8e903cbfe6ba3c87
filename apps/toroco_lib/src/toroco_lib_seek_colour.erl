%% @doc Seek a colour: steer towards a camera target while it is in view.
%%
%% Inputs: `target', a camera output (`update_red' or `update_trq' of
%% `toroco_udp_camera'): `{X, Y}' pixels from the frame's centre, x right,
%% or `none'. Which colour is sought is the wiring's choice.
%% Outputs: `motors': latched `{Speed + Turn, Speed - Turn}' with `Turn' =
%% `gain' x X clamped to `max_turn' (a target to the right turns right),
%% emitted when it changes; unset when the target is gone.
%%
%% Parameters: `speed' [60], `gain' [0.3] (servo units per pixel),
%% `max_turn' [35].
%%
%% Usual layer: above `avoid' when the target is to be touched (the range
%% sensors see it as an obstacle), above `wander'.
-module(toroco_lib_seek_colour).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4]).

-spec params() -> [toroco_lib_params:spec()].
params() -> [{speed, speed, 60}, {gain, non_neg_number, 0.3}, {max_turn, pos_speed, 35}].

-spec interface() -> #{inputs := [target], outputs := [motors]}.
interface() -> #{inputs => [target], outputs => [motors]}.

-spec init(map()) -> {ok, unseen, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, P} -> {ok, unseen, P#{last => none}};
        {error, _} = Error -> Error
    end.

-spec handle_input(target, term(), unseen | seeking, map()) -> toroco_behavior:result().
handle_input(target, {X, _Y}, _State, #{speed := S, gain := G, max_turn := M, last := Last} = P)
  when is_number(X) ->
    Turn = max(-M, min(M, G * X)),
    {Actions, Last1} = toroco_lib_drive:set(toroco_lib_drive:steer(S, Turn), Last),
    {next_state, seeking, P#{last := Last1}, Actions};
handle_input(target, _None, _State, #{last := Last} = P) ->
    {Actions, Last1} = toroco_lib_drive:release(Last),
    {next_state, unseen, P#{last := Last1}, Actions}.
