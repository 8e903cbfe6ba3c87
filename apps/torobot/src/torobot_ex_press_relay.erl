%% @doc The lower behavior of the verification program "inhibition and
%% suppression" (thesis §5.3): it signals each button press as
%% `{lower, Button}'.
%%
%% Inputs `left' and `right' (the mouse), output `signal'. Releases are left
%% to the higher behavior (`torobot_ex_takeover'), which takes over when a
%% click completes; since the two never act on the same event, which of them
%% reaches the actuator first is never a race.
-module(torobot_ex_press_relay).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal]}.

-spec init(map()) -> {ok, relaying, map()}.
init(Params) -> {ok, relaying, Params}.

-spec handle_input(left | right, term(), relaying, map()) -> toroco_behavior:result().
handle_input(Button, pressed, _State, _Data) ->
    {keep_state_and_data, [{send, #{signal => {lower, Button}}}]};
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.
