%% @doc Version B (torobot 0.1.1) of the release-upgrade demo's behavior
%% (scripts/release-upgrade-demo): the beat also says which version emitted
%% it, and the state remembers since when (system time, s) this version runs.
%% code_change converts A's state on the upgrade and back on the downgrade.
-module(torobot_beacon).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, code_change/4]).

-spec interface() -> #{inputs := [tick], outputs := [beat]}.
interface() -> #{inputs => [tick], outputs => [beat]}.

-spec init(map()) -> {ok, beating, #{count := 0, since := integer()}}.
init(_Params) -> {ok, beating, #{count => 0, since => erlang:system_time(second)}}.

-spec handle_input(tick, term(), beating, #{count := non_neg_integer(), since := integer()}) ->
          toroco_behavior:result().
handle_input(tick, _Tick, _State, #{count := N} = Data) ->
    {keep_state, Data#{count := N + 1}, [{set, #{beat => {beat, N + 1, v2}}}]}.

-spec code_change(term(), beating, map(), term()) -> {ok, beating, map()}.
code_change({down, _Vsn}, State, Data, _Extra) ->
    {ok, State, maps:remove(since, Data)};
code_change(_OldVsn, State, Data, _Extra) ->
    {ok, State, Data#{since => erlang:system_time(second)}}.
