%% @doc Keep an avoid turn while blue is seen: the Torobot's `hold_left' and
%% `hold_right' (layer 3, above `trq_ignore' at the motors).
%%
%% Near a wall with a blue object in view, steering away from blue can turn
%% the robot into the wall, and the IR avoid, suppressed by `trq_ignore',
%% cannot stop it; the avoid's turn, once it clears, gives way to
%% `trq_ignore', which turns the robot back: the robot dithers between the
%% two (thesis §5.2.2). A hold sits on one avoid's output: while blue is
%% seen it keeps emitting the last turn that avoid made since blue came into
%% view, even after the avoid cleared, so the robot finishes turning away
%% from the wall past the blue object; when blue is gone it passes the
%% avoid's output through. Placed above `trq_ignore' at the motors, the held
%% turn wins over steering away from blue.
%%
%% Inputs: `avoid', wired to the avoid's `motors' output with an `idle'
%% value (`clear' in the shipped wiring), so that the end of the avoid's
%% hold (its unset, or its inhibition by the other avoid) arrives as an
%% event; `trq', the camera's `update_trq' (`{X, Y}' or `none').
%%
%% The thesis needed two extra modules emitting constant events to keep its
%% hold modules' output suppressing; here the turn is a latched `set', which
%% holds at the router until it is unset, so no such modules exist.
%%
%% States: `passing' (no blue), `watching' (blue in view, nothing to hold),
%% `holding' (blue in view, a turn latched). The data remembers whether the
%% avoid is turning now and with what.
-module(torobot_hold).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-type state() :: passing | watching | holding.

-spec interface() -> #{inputs := [avoid | trq], outputs := [motors]}.
interface() ->
    #{inputs => [avoid, trq], outputs => [motors]}.

-spec init(map()) -> {ok, passing, #{avoid := none}}.
init(_Params) ->
    {ok, passing, #{avoid => none}}.

-spec handle_input(avoid | trq, term(), state(), map()) -> toroco_behavior:result().
%% The avoid turns: passed on whatever the state; held from now on if blue
%% is in view.
handle_input(avoid, Turn, State, D) when is_tuple(Turn) ->
    Next = case State of
               passing -> passing;
               _ -> holding
           end,
    {next_state, Next, D#{avoid := Turn}, [{set, #{motors => Turn}}]};
%% The avoid stopped turning (its idle value): passed on, unless held.
handle_input(avoid, _Clear, holding, D) ->
    {keep_state, D#{avoid := none}};
handle_input(avoid, _Clear, _State, D) ->
    {keep_state, D#{avoid := none}, [{unset, [motors]}]};
%% Blue appears: a turn in progress is held from now on.
handle_input(trq, {_, _}, passing, #{avoid := none} = D) ->
    {next_state, watching, D};
handle_input(trq, {_, _}, passing, D) ->
    {next_state, holding, D};
%% Blue is gone: back to passing the avoid through.
handle_input(trq, none, holding, #{avoid := none} = D) ->
    {next_state, passing, D, [{unset, [motors]}]};
handle_input(trq, none, State, D) when State =/= passing ->
    {next_state, passing, D};
handle_input(trq, _Seen, _State, _D) ->
    keep_state_and_data.
