%% @doc The observer tap's time stamps (SPEC §10): every event one
%% activation taps carries the activation's one time stamp, and the events
%% of one activation reach a subscriber in the order they happened, though
%% activations of other producers run meanwhile.
%%
%% The runtime runs two emitters (`prop_emitter', outputs `out'), both wired
%% to one fake actuator's inputs, and a subscriber to every kind of event.
%% A case is a list of activations: each is one callback's actions on one of
%% the emitters (sends, sets, unsets, each with a value of its own); they run
%% at once from two processes, one per emitter.
-module(prop_tap).

-include_lib("proper/include/proper.hrl").

-export([prop_activation_order/0, setup/0]).

%%====================================================================
%% Generators
%%====================================================================

action() ->
    oneof([send, set, unset]).

%% One activation: an emitter and its actions (1 to 6 of them).
activation() ->
    {oneof([p1, p2]), non_empty(resize(6, list(action())))}.

%%====================================================================
%% Model
%%====================================================================

%% The actions of activation `K', each with its own value; what the tap
%% says of each.
actions(K, Kinds) ->
    lists:unzip([act(Kind, {K, I}) || {I, Kind} <- lists:enumerate(Kinds)]).

act(send, V) -> {{send, #{out => V}}, {send, V}};
act(set, V) -> {{set, #{out => V}}, {set, V}};
act(unset, _V) -> {{unset, [out]}, {unset, none}}.

%%====================================================================
%% Properties
%%====================================================================

%% @doc The runtime the property runs on.
setup() ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok = toroco:add_behavior(p1, prop_emitter, #{layer => 1}),
    ok = toroco:add_behavior(p2, prop_emitter, #{layer => 2}),
    ok = toroco:add_device(act, toroco_fake_actuator, #{inputs => [in]}),
    ok = toroco:set_inputs(act, #{in => [{p2, out}, {p1, out}]}),
    ok.

prop_activation_order() ->
    ?FORALL(Activations, non_empty(resize(8, list(activation()))),
            begin
                {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [p1, p2]}),
                Planned = [{E, K, actions(K, Kinds)}
                           || {K, {E, Kinds}} <- lists:enumerate(Activations)],
                run(Planned),
                Expected = lists:sum([length(Seen) || {_, _, {_, Seen}} <- Planned]),
                Events = events(Ref, Expected),
                ok = toroco:unsubscribe_events(Ref),
                ?WHENFAIL(io:format("events ~p~n", [Events]),
                          kept(p1, Planned, Events) andalso kept(p2, Planned, Events))
            end).

%% Each emitter's activations from a process of its own, both at once.
run(Planned) ->
    Self = self(),
    Pids = [spawn_link(fun() ->
                               _ = [ok = prop_emitter:emit(E, Actions)
                                    || {E1, _, {Actions, _}} <- Planned, E1 =:= E],
                               Self ! {self(), done}
                       end) || E <- [p1, p2]],
    _ = [receive {P, done} -> ok after 10000 -> error(emitters_stuck) end || P <- Pids],
    ok.

%% The emit events, once `N' came (or 5 s passed).
events(Ref, N) ->
    events(Ref, N, []).

events(_Ref, 0, Acc) ->
    lists:reverse(Acc);
events(Ref, N, Acc) ->
    receive
        {toroco_event, Ref, {emit, _, _, _, _} = E} -> events(Ref, N - 1, [E | Acc])
    after 5000 ->
            lists:reverse(Acc)
    end.

%% Emitter `E''s events are its activations' events, in order, each
%% activation's with one time stamp, no earlier than the one before.
kept(E, Planned, Events) ->
    Mine = [{T, {Kind, V}} || {emit, T, {E1, out}, Kind, V} <- Events, E1 =:= E],
    Runs = [Seen || {E1, _, {_, Seen}} <- Planned, E1 =:= E],
    [S || {_, S} <- Mine] =:= lists:append(Runs) andalso stamps(Runs, [T || {T, _} <- Mine], 0).

stamps([], [], _Last) ->
    true;
stamps([Run | Runs], Ts, Last) ->
    {Mine, Rest} = lists:split(length(Run), Ts),
    case lists:usort(Mine) of
        [T] when T >= Last -> stamps(Runs, Rest, T);
        _ -> false
    end.
