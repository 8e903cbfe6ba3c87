%% @doc Shows the click count it is given: each value on `count' is sent on
%% `signal' as `{count, N}'. The behavior that the verification program
%% "suspend and resume" (thesis §5.3) suspends and resumes; what it signals
%% tells which counts reached it.
-module(torobot_ex_display).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [count], outputs => [signal]}.

-spec init(map()) -> {ok, showing, map()}.
init(Params) -> {ok, showing, Params}.

-spec handle_input(count, term(), showing, map()) -> toroco_behavior:result().
handle_input(count, N, _State, _Data) ->
    {keep_state_and_data, [{send, #{signal => {count, N}}}]}.
