%% @doc Verification program "wait for event, trigger style" (thesis §5.3):
%% after a left press, wait up to `timeout_ms' (default 2000) for a right
%% press. The behaviour is the thesis' "inverted" one: the behavior speaks
%% when the awaited event does <b>not</b> come, and stays silent when it does.
%%
%% Inputs `left' and `right' (the mouse), output `signal'. Two states:
%% <ul>
%% <li>`idle': a left press sends `armed' and enters `waiting' with a
%% `state_timeout'; everything else is ignored.</li>
%% <li>`waiting': a right press in time goes back to `idle' silently (leaving
%% the state cancels the timeout); the timeout sends `timeout' and goes back
%% to `idle'. Other events, a second left press included, are ignored and do
%% not restart the wait.</li>
%% </ul>
%% So left, right (in time) gives `[armed]'; left and no right gives
%% `[armed, timeout]', the second about `timeout_ms' after the first.
-module(torobot_ex_trigger).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, handle_event/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal]}.

-spec init(map()) -> {ok, idle, #{timeout_ms := non_neg_integer()}}.
init(Params) -> {ok, idle, #{timeout_ms => maps:get(timeout_ms, Params, 2000)}}.

-spec handle_input(left | right, term(), idle | waiting, map()) -> toroco_behavior:result().
handle_input(left, pressed, idle, D = #{timeout_ms := T}) ->
    {next_state, waiting, D, [{send, #{signal => armed}}, {state_timeout, T, right}]};
handle_input(right, pressed, waiting, D) ->
    {next_state, idle, D};
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), idle | waiting, map()) ->
          toroco_behavior:result().
handle_event(state_timeout, right, waiting, D) ->
    {next_state, idle, D, [{send, #{signal => timeout}}]}.
