%% @doc Verification program "sensor signalling" (thesis §5.3): the mouse's
%% button events, each signalled to the actuator as `{Button, Event}'.
%%
%% Inputs `left' and `right' (wired to the mouse), output `signal'. Stateless:
%% every event is passed on as a momentary send, so nothing is held.
-module(torobot_ex_signaller).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal]}.

-spec init(map()) -> {ok, signalling, map()}.
init(Params) -> {ok, signalling, Params}.

-spec handle_input(left | right, term(), signalling, map()) -> toroco_behavior:result().
handle_input(Button, Event, _State, _Data) ->
    {keep_state_and_data, [{send, #{signal => {Button, Event}}}]}.
