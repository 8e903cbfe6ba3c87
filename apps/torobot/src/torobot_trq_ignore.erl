%% @doc Steer away from a blue ("turquoise") object: the Torobot's
%% `trq_ignore' (layer 2, above the avoids, which it suppresses).
%%
%% The `trq' input is the camera's `update_trq': `{X, Y}' pixels from the
%% frame's centre (x right) for the largest blue blob of a frame, or `none'.
%% While blue is seen the behavior sets a turn to the other side on
%% `motors', latched; the side is chosen when blue appears (blue right of
%% centre, or dead ahead: turn left) and kept until blue is gone, so a blob
%% crossing the centre while the robot turns does not make it dither. When
%% blue is gone it unsets. Nothing is emitted for frames that change
%% nothing.
%%
%% Params: `turn', the `{Slow, Fast}' wheel velocities of the turn (default
%% `{50, 70}', an arc); turning left puts `Slow' on the left wheel.
-module(torobot_trq_ignore).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [trq], outputs := [motors]}.
interface() ->
    #{inputs => [trq], outputs => [motors]}.

-spec init(map()) -> {ok, unseen, map()}.
init(Params) ->
    {ok, unseen, maps:merge(#{turn => {50, 70}}, Params)}.

-spec handle_input(trq, term(), unseen | {turning, left | right}, map()) ->
          toroco_behavior:result().
handle_input(trq, none, unseen, _P) ->
    keep_state_and_data;
handle_input(trq, none, {turning, _}, P) ->
    {next_state, unseen, P, [{unset, [motors]}]};
handle_input(trq, {X, _Y}, unseen, #{turn := {Slow, Fast}} = P) when is_number(X) ->
    case X >= 0 of
        true -> {next_state, {turning, left}, P, [{set, #{motors => {Slow, Fast}}}]};
        false -> {next_state, {turning, right}, P, [{set, #{motors => {Fast, Slow}}}]}
    end;
handle_input(trq, _Seen, _State, _P) ->
    keep_state_and_data.
