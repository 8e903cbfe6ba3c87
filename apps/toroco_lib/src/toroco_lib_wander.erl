%% @doc Wander: drive forward along random arcs, a new arc every while.
%% Seeded, so a run can be repeated: the same seed gives the same arcs.
%%
%% Inputs: none. Outputs: `motors', latched `{Speed + Turn, Speed - Turn}'
%% with `Turn' drawn uniformly from `-turn..turn' each time an interval
%% drawn uniformly from `min_ms..max_ms' ends.
%%
%% Parameters: `speed' [50], `turn' [30] (0..100), `min_ms' [800],
%% `max_ms' [2500] (not below `min_ms'), `seed' [1] (an integer).
%%
%% Usual layer: 0, under `avoid' (SPEC §14: the wanderer).
-module(toroco_lib_wander).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, handle_event/4]).

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{speed, speed, 50}, {turn, pos_speed, 30}, {min_ms, ms, 800}, {max_ms, ms, 2500},
     {seed, integer, 1}].

-spec interface() -> #{inputs := [], outputs := [motors]}.
interface() -> #{inputs => [], outputs => [motors]}.

-spec init(map()) -> {ok, wandering, map(), toroco_behavior:actions()}
                         | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, #{min_ms := Min, max_ms := Max} = P} when Max < Min ->
            toroco_lib_params:refuse(max_ms, P);
        {ok, #{seed := Seed} = P} ->
            {Actions, P1} = arc(P#{rand => rand:seed_s(exsss, Seed)}),
            {ok, wandering, P1, Actions};
        {error, _} = Error ->
            Error
    end.

-spec handle_input(atom(), term(), wandering, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _P) -> keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), wandering, map()) ->
          toroco_behavior:result().
handle_event(state_timeout, arc, _State, P) ->
    {Actions, P1} = arc(P),
    {keep_state, P1, Actions};
handle_event(_Type, _Content, _State, _P) ->
    keep_state_and_data.

%% A new arc and the time it lasts.
arc(#{speed := S, turn := Turn, min_ms := Min, max_ms := Max, rand := R0} = P) ->
    {A, R1} = rand:uniform_s(R0),
    {B, R2} = rand:uniform_s(R1),
    Command = toroco_lib_drive:steer(S, (2 * A - 1) * Turn),
    Ms = Min + round(B * (Max - Min)),
    {[{set, #{motors => Command}}, {state_timeout, Ms, arc}], P#{rand := R2}}.
