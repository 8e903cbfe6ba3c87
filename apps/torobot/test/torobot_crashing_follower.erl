%% A red_follower that crashes: every 2 s it checks whether red is in view
%% and, if so, dies. Otherwise it is torobot_red_follower. The scenario
%% suite wires it in place of the real one to see the layers below carry
%% on. Each crash bumps the counter the suite keeps in persistent_term.
-module(torobot_crashing_follower).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, handle_event/4]).

-define(EVERY_MS, 2000).

interface() ->
    torobot_red_follower:interface().

init(Params) ->
    {ok, State, Data} = torobot_red_follower:init(Params),
    {ok, State, Data#{seen => false}, [{{timeout, crash}, ?EVERY_MS, check}]}.

handle_input(red, V, State, Data) ->
    Data1 = Data#{seen => V =/= none},
    case torobot_red_follower:handle_input(red, V, State, maps:remove(seen, Data)) of
        keep_state_and_data -> {keep_state, Data1};
        {next_state, S, _D, Actions} -> {next_state, S, Data1, Actions}
    end.

handle_event({timeout, crash}, check, _State, #{seen := true}) ->
    case persistent_term:get(torobot_crashes, undefined) of
        undefined -> ok;
        Counter -> counters:add(Counter, 1, 1)
    end,
    exit(red_follower_crash_test);
handle_event({timeout, crash}, check, _State, _Data) ->
    {keep_state_and_data, [{{timeout, crash}, ?EVERY_MS, check}]};
handle_event(_Type, _Content, _State, _Data) ->
    keep_state_and_data.
