%% @doc The lockstep clock's side of a world of several nodes (SPEC §13,
%% §17), on its state: steps to another node's processes through its agent,
%% batched; the agent's answers; heals and cuts (the world's side is
%% `toroco_lockstep_nodes').
-module(toroco_lockstep_remote).

-include("toroco_lockstep.hrl").

-import(toroco_lockstep_trace, [trace/4, note/2]).

-export([deliver/4, batched/4, at/4, event/3, cut/3]).

%% A step for a process of another node, through its agent (which answers
%% `at'); none goes to a node killed.
-spec deliver(term(), term(), term(), #s{}) -> #s{}.
deliver(To, Target, Msg, S = #s{steps = N, world = W, now = Now, queue = Q}) ->
    {More, Q1} = toroco_lockstep_nodes:batch({To, Target, Msg}, Q, W),
    case More of
        [] ->
            case toroco_lockstep_nodes:step(To, Target, Msg, Now, W) of
                lost -> S#s{lost = S#s.lost + 1};
                {sent, Token, Node} ->
                    trace(To, Target, Msg, S#s{inflight = {Token, make_ref(), {pending, Node}},
                                               steps = N + 1})
            end;
        _ ->
            %% the steps for that node next in the queue go as one batch
            Items = [{To, Target, Msg} | More],
            {Token, Node} = toroco_lockstep_nodes:step_batch(Items, Now),
            lists:foldl(fun({T, P, M}, Acc) -> trace(T, P, M, Acc) end,
                        S#s{queue = Q1, inflight = {Token, make_ref(), {pending, Node}},
                            steps = N + length(Items)}, Items)
    end.

%% A batch is done (`Rest': the steps not run, since one's receiver died:
%% they go first again).
-spec batched(term(), non_neg_integer(), [item()], #s{}) -> #s{}.
batched(Token, Lost, Rest, S = #s{inflight = {Token, _, {pending, _}}, queue = Q}) ->
    S#s{inflight = none, lost = S#s.lost + Lost,
        queue = queue:join(queue:from_list(Rest), Q)};
batched(_Token, _Lost, _Rest, S) ->
    S.

%% The agent found the step's receiver (`undefined': none had the name)
%% and who monitors it; the step is in flight to it.
-spec at(term(), pid() | undefined, [pid()], #s{}) -> #s{}.
at(Token, Pid, By, S = #s{inflight = {Token, _, {pending, _}}, procs = Procs, watch = W})
  when is_pid(Pid) ->
    Consumers = [C || C <- By, case Procs of
                                   #{C := #{layer := consumer}} -> true;
                                   #{} -> false
                               end],
    S#s{inflight = {Token, erlang:monitor(process, Pid), Pid},
        watch = case Procs of
                    #{Pid := _} -> W#{Pid => Consumers};
                    #{} -> W
                end};
at(Token, _Pid, _By, S = #s{inflight = {Token, _, {pending, _}}}) ->
    S#s{inflight = none, lost = S#s.lost + 1};
at(_Token, _Pid, _By, S) ->
    S.

%% A heal, or the net kernel noticing a cut: its line, and what it sends.
-spec event(term(), node(), #s{}) -> #s{}.
event(Event, Node, S = #s{world = W, queue = Q}) ->
    Name = fun toroco_lockstep_trace:pname/1,
    {W1, Line, Steps} = toroco_lockstep_nodes:event(Event, Node, Name, W),
    note(Line, S#s{world = W1, queue = lists:foldl(fun queue:in/2, Q, Steps)}).

-spec cut(node(), non_neg_integer() | forever, #s{}) -> {reply, ok | {error, term()}, #s{}}.
cut(Node, Ms, S = #s{world = W, now = Now}) ->
    case toroco_lockstep_nodes:cut(Node, Ms, Now, W) of
        {ok, W1, Line} -> {reply, ok, note(Line, S#s{world = W1})};
        Error -> {reply, Error, S}
    end.
