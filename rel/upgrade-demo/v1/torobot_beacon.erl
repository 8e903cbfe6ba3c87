%% @doc Version A (torobot 0.1.0) of the release-upgrade demo's behavior
%% (scripts/release-upgrade-demo): on each `tick' it latches `beat' with
%% the number of ticks seen.
-module(torobot_beacon).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, code_change/4]).

-spec interface() -> #{inputs := [tick], outputs := [beat]}.
interface() -> #{inputs => [tick], outputs => [beat]}.

-spec init(map()) -> {ok, beating, #{count := 0}}.
init(_Params) -> {ok, beating, #{count => 0}}.

-spec handle_input(tick, term(), beating, #{count := non_neg_integer()}) ->
          toroco_behavior:result().
handle_input(tick, _Tick, _State, #{count := N} = Data) ->
    {keep_state, Data#{count := N + 1}, [{set, #{beat => {beat, N + 1}}}]}.

-spec code_change(term(), beating, map(), term()) -> {ok, beating, map()}.
code_change(_OldVsn, State, Data, _Extra) -> {ok, State, Data}.
