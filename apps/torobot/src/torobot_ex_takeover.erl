%% @doc The higher behavior of the verification program "inhibition and
%% suppression" (thesis §5.3): a completed click takes over from the lower
%% behavior for a window (param `window_ms', default 2500).
%%
%% Inputs `left' and `right' (the mouse), outputs `signal' and `inhibit'.
%% <ul>
%% <li>A left click (on release) <b>suppresses</b>: `{upper, suppress}' is sent
%% on `signal' with a hold of the window, so at every input that lists
%% `signal' above the lower behavior the lower one's events are dropped until
%% the hold expires. Where this behavior is not wired they still arrive.</li>
%% <li>A right click (on release) <b>inhibits</b>: `on' is sent on `inhibit'
%% with a hold of the window; wired as the inhibitor of the lower behavior's
%% output, it silences that output everywhere. `{upper, inhibit}' is also sent
%% on `signal' as a momentary event (no hold), only to show the click was
%% seen: it suppresses nothing.</li>
%% </ul>
%% A click during a window starts a new window of full length: a new emission
%% replaces the output's previous hold.
-module(torobot_ex_takeover).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal, inhibit]}.

-spec init(map()) -> {ok, watching, #{window_ms := non_neg_integer()}}.
init(Params) -> {ok, watching, #{window_ms => maps:get(window_ms, Params, 2500)}}.

-spec handle_input(left | right, term(), watching, map()) -> toroco_behavior:result().
handle_input(left, released, _State, #{window_ms := W}) ->
    {keep_state_and_data, [{send, #{signal => {upper, suppress}}, #{hold => W}}]};
handle_input(right, released, _State, #{window_ms := W}) ->
    {keep_state_and_data, [{send, #{inhibit => on}, #{hold => W}},
                           {send, #{signal => {upper, inhibit}}}]};
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.
