%% @doc The lockstep clock's timers: each owner's timer of a kind, keyed
%% by simulated deadline, then by the order they were set (in a world of
%% several nodes, a timer set outside any step by its owner's name).
-module(toroco_lockstep_timers).

-include("toroco_lockstep.hrl").

-export([set/5, drop/3, world/5, next_deadline/1]).

-spec set(pid(), term(), integer(), term(), #s{}) -> #s{}.
set(Pid, Kind, Deadline, Msg, S) ->
    #s{timers = Ts, owned = Owned, seq = Seq} = S1 = drop(Pid, Kind, S),
    Key = {Deadline, Seq},
    S1#s{timers = gb_trees:insert(Key, {Pid, Kind, Msg}, Ts),
         owned = Owned#{{Pid, Kind} => Key}, seq = Seq + 1}.

-spec drop(pid(), term(), #s{}) -> #s{}.
drop(Pid, Kind, S = #s{owned = Owned, timers = Ts}) ->
    case Owned of
        #{{Pid, Kind} := Key} ->
            S#s{owned = maps:remove({Pid, Kind}, Owned), timers = gb_trees:delete(Key, Ts)};
        #{} ->
            S
    end.

%% A timer set inside its owner's step is ordered as on one node; one set
%% outside any step is ordered by its owner's name (toroco_lockstep_nodes).
-spec world(pid(), term(), integer(), term(), #s{}) -> #s{}.
world(Pid, Kind, Deadline, Msg, S = #s{inflight = {_, _, Pid}}) ->
    set(Pid, Kind, Deadline, Msg, S);
world(Pid, Kind, Deadline, Msg, S = #s{inflight = {_, _, {pending, Node}}})
  when node(Pid) =:= Node ->
    %% set by a step of the batch in flight there
    set(Pid, Kind, Deadline, Msg, S);
world(Pid, Kind, Deadline, Msg, S) ->
    S1 = #s{timers = Ts, owned = Owned} = drop(Pid, Kind, S),
    Key = toroco_lockstep_nodes:timer_key(Deadline, {toroco_lockstep_trace:pname(Pid), Kind}, Ts),
    S1#s{timers = gb_trees:insert(Key, {Pid, Kind, Msg}, Ts),
         owned = Owned#{{Pid, Kind} => Key}}.

%% How far time may go before the next timer: a world's event due by
%% then comes first.
-spec next_deadline(#s{}) -> integer().
next_deadline(#s{timers = Ts, target = Target}) ->
    case gb_trees:is_empty(Ts) of
        true -> Target;
        false -> min(Target, element(1, element(1, gb_trees:smallest(Ts))))
    end.
