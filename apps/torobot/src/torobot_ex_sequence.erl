%% @doc Verification program "wait for event, coroutine style" (thesis §5.3):
%% the Lua coroutine that looped over
%% ```
%% wait_for_input(left)            -- then signal left_seen
%% wait_for_input(right, timeout)  -- then signal sequence_done, or timeout
%% '''
%% written as gen_statem states, one per `wait_for_input' (SPEC §4,
%% Wait-for-input): the point where the coroutine would resume is the state.
%%
%% Inputs `left' and `right' (the mouse), output `signal'. Only presses
%% count. In `wait_left' a left press sends `left_seen' and enters
%% `wait_right' with a `state_timeout' of `timeout_ms' (default 2000); there
%% a right press sends `sequence_done', the timeout sends `timeout', and both
%% go back to `wait_left'. Presses out of order (right while waiting for
%% left, left while waiting for right) are ignored, as a coroutine blocked in
%% `wait_for_input' would ignore them; they do not restart the wait.
-module(torobot_ex_sequence).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, handle_event/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal]}.

-spec init(map()) -> {ok, wait_left, #{timeout_ms := non_neg_integer()}}.
init(Params) -> {ok, wait_left, #{timeout_ms => maps:get(timeout_ms, Params, 2000)}}.

-spec handle_input(left | right, term(), wait_left | wait_right, map()) ->
          toroco_behavior:result().
handle_input(left, pressed, wait_left, D = #{timeout_ms := T}) ->
    {next_state, wait_right, D, [{send, #{signal => left_seen}}, {state_timeout, T, right}]};
handle_input(right, pressed, wait_right, D) ->
    {next_state, wait_left, D, [{send, #{signal => sequence_done}}]};
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), wait_left | wait_right, map()) ->
          toroco_behavior:result().
handle_event(state_timeout, right, wait_right, D) ->
    {next_state, wait_left, D, [{send, #{signal => timeout}}]}.
