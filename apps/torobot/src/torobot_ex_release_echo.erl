%% @doc Echoes button releases, numbered from its own start: the n-th release
%% since `init/1' is sent on `signal' as `{released, Button, N}'. The behavior
%% that the verification program "add and remove" (thesis §5.3) removes and
%% adds back; the numbering shows that an added-back behavior is a new one.
-module(torobot_ex_release_echo).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [signal]}.

-spec init(map()) -> {ok, echoing, non_neg_integer()}.
init(_Params) -> {ok, echoing, 0}.

-spec handle_input(left | right, term(), echoing, non_neg_integer()) ->
          toroco_behavior:result().
handle_input(Button, released, _State, N) ->
    {keep_state, N + 1, [{send, #{signal => {released, Button, N + 1}}}]};
handle_input(_Button, _Event, _State, _N) ->
    keep_state_and_data.
