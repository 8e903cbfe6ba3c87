%% @doc Counts completed clicks (button releases) of either mouse button and
%% keeps the count latched on `count', so a receiver that was away (suspended,
%% restarted, newly wired) is re-delivered the current count. Used by the
%% verification program "suspend and resume" (thesis §5.3).
%%
%% Inputs `left' and `right' (the mouse), output `count' (`set' to the number
%% of releases so far).
-module(torobot_ex_click_counter).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [count]}.

-spec init(map()) -> {ok, counting, non_neg_integer()}.
init(_Params) -> {ok, counting, 0}.

-spec handle_input(left | right, term(), counting, non_neg_integer()) ->
          toroco_behavior:result().
handle_input(_Button, released, _State, N) ->
    {keep_state, N + 1, [{set, #{count => N + 1}}]};
handle_input(_Button, _Event, _State, _N) ->
    keep_state_and_data.
