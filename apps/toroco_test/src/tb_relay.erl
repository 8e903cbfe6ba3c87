%% A test behavior: relays what it is told on `in' to `out'.
%% Values: {set, V} latches V; {hold, V, Ms} sends with a hold; unset unsets;
%% {sleep, Ms, V} sleeps then sends (a slow receiver: its callback is busy
%% for Ms); crash crashes; anything
%% else is sent as a momentary event. Param `latch' sets a value from init/1.
-module(tb_relay).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [in, in2], outputs => [out, out2]}.

-spec init(map()) -> {ok, relaying, map(), toroco_behavior:actions()}.
init(P) ->
    Actions = case P of
                  #{latch := V} -> [{set, #{out => V}}];
                  #{} -> []
              end,
    {ok, relaying, P, Actions}.

-spec handle_input(atom(), term(), relaying, map()) -> toroco_behavior:result().
handle_input(_In, {set, V}, _S, _D) -> {keep_state_and_data, [{set, #{out => V}}]};
handle_input(_In, {hold, V, Ms}, _S, _D) -> {keep_state_and_data, [{send, #{out => V}, #{hold => Ms}}]};
handle_input(_In, unset, _S, _D) -> {keep_state_and_data, [{unset, [out]}]};
handle_input(_In, {sleep, Ms, V}, _S, _D) -> timer:sleep(Ms), {keep_state_and_data, [{send, #{out => V}}]};
handle_input(_In, crash, _S, _D) -> exit(crash_requested);
handle_input(_In, V, _S, _D) -> {keep_state_and_data, [{send, #{out => V}}]}.
