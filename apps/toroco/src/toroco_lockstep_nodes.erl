%% @doc One lockstep world over several nodes (SPEC §13, §17): the other
%% nodes of a robot join the clock of the node where the world runs.
%%
%% `toroco_lockstep' on the world's node stays the one clock. On every other
%% node of the robot an <em>agent</em> (this module's process, registered
%% as `toroco_lockstep_agent') points that node's event path at the world's
%% `toroco_lockstep' (the `persistent_term' that `toroco_wire:send/2',
%% `toroco_clock:set_timer/3' and the engine's `done' read) and keeps that
%% node's simulated time, an `atomics' cell as on the world's node. A step
%% for a process of another node goes through that node's agent: it sets
%% the cell to the step's simulated instant, finds the receiver (a name is
%% looked up there, as a send to `{Name, Node}' would be) and says which
%% process it is and who monitors it, then hands it the step. So a message
%% between nodes is a step like any other, in the world's one order, and a
%% timer of any node fires at its simulated deadline.
%%
%% Partitions are simulated inside the world, not made by cutting
%% distribution (the world's clock must keep reaching every node, and a run
%% must not depend on when the real net kernel notices anything): while a
%% node is cut, a step from one side to the other is lost when it is sent,
%% as a real partition loses it, and each side keeps running on the world's
%% clock. As with a real network drop, the remote sources' `max_age' (SPEC
%% §13) is what lets them go first; the monitors that consumers hold on
%% processes across the cut (`toroco_wire' tells the clock of each) fire as
%% `noconnection' when the net kernel would notice, the net tick time
%% (`net_kernel:get_net_ticktime/0') after the cut began, if it still
%% lasts; and when a cut whose monitors fired heals, those consumers are
%% told to subscribe again, as the wiring server tells them when a node
%% comes back. A node killed is cut for good, its monitors fire at once,
%% and its processes get no step again. This module keeps that state; the
%% clock asks it.
-module(toroco_lockstep_nodes).

-include("toroco_wire.hrl").

-export([join/2, leave/1, nodes/1, cut/4, due/2, event/4, lost/3, dest/3]).
-export([monitor/4, demonitor/2, timer_key/3]).
-export([step/5, batch/3, step_batch/2, node_of/1, regname/1, remember/2, send_out/2]).
-export([agent/2]).
-export_type([world/0]).

-define(TAG, '$toroco_lockstep').
-define(AGENT, toroco_lockstep_agent).
-define(CALL_MS, 10000).
-define(LOG, #{domain => [toroco, clock]}).
-define(REGS, '$toroco_lockstep_regs').

%% The world's nodes (this one first), the cuts (node -> the simulated
%% time it heals, or `forever' for a node killed), when each cut is noticed
%% (node -> simulated time), the consumers whose monitors fired for each
%% (told to subscribe again at the heal), the monitors across nodes
%% (reference -> {consumer, monitored}); the registered names of
%% the processes of other nodes are kept in the clock's process dictionary
%% (the trace and the settle's order name them).
-type world() :: #{nodes := [node()], cuts := #{node() => integer() | forever},
                   notices := #{node() => integer()}, downed := #{node() => [pid()]},
                   mons := #{reference() => {pid(), pid()}}}.

%%====================================================================
%% Joining and leaving
%%====================================================================

%% @doc The nodes `Nodes' (connected, other than this one) join the clock
%% `Clock' of this node: `{error, {node_not_connected, Node}}' before any
%% joins if one is not.
-spec join([node()], pid()) -> {ok, world()} | {error, {atom(), term()}}.
join(Nodes0, Clock) ->
    Nodes = lists:usort(Nodes0) -- [node()],
    case [N || N <- Nodes, not lists:member(N, erlang:nodes())] of
        [Node | _] ->
            {error, {node_not_connected, Node}};
        [] ->
            Joined = [{N, catch erpc:call(N, ?MODULE, agent, [start, Clock], ?CALL_MS)}
                      || N <- Nodes],
            case [{N, R} || {N, R} <- Joined, R =/= ok] of
                [] ->
                    {ok, world([node() | Nodes])};
                [{Node, Why} | _] ->
                    _ = leave(world([N || {N, ok} <- Joined])),
                    {error, {node_not_joined, {Node, Why}}}
            end
    end.

world(Nodes) ->
    #{nodes => Nodes, cuts => #{}, notices => #{}, downed => #{}, mons => #{}}.

%% @doc The other nodes go back to their own clocks.
-spec leave(world() | none) -> ok.
leave(none) ->
    ok;
leave(#{nodes := Nodes}) ->
    _ = erase(?REGS),
    _ = [catch erpc:call(N, ?MODULE, agent, [stop, self()], ?CALL_MS) || N <- Nodes, N =/= node()],
    ok.

-spec nodes(world()) -> [node()].
nodes(#{nodes := Nodes}) -> Nodes.

%%====================================================================
%% Partitions
%%====================================================================

%% @doc `Node' is cut from the rest of the robot from `Now' for `Ms'
%% simulated ms (`forever': the node is killed), with the trace's line. The
%% world's own node and a node not in the world are refused.
-spec cut(node(), non_neg_integer() | forever, integer(), world() | none) ->
          {ok, world(), iodata()} | {error, {atom(), node()}}.
cut(Node, _Ms, _Now, _W) when Node =:= node() ->
    {error, {own_node, Node}};
cut(Node, _Ms, _Now, none) ->
    {error, {unknown_node, Node}};
cut(Node, Ms, Now, W) ->
    case lists:member(Node, maps:get(nodes, W)) of
        false -> {error, {unknown_node, Node}};
        true when Ms =:= forever -> {ok, cut_until(Node, forever, Now, W), ["kill ", atom_to_list(Node)]};
        true -> {ok, cut_until(Node, Ms, Now, W), io_lib:format("cut ~s ~b", [Node, Ms])}
    end.

cut_until(Node, forever, Now, W = #{cuts := Cuts, notices := Notices}) ->
    W#{cuts := Cuts#{Node => forever}, notices := Notices#{Node => Now}};
cut_until(Node, Ms, Now, W = #{cuts := Cuts, notices := Notices, downed := Downed}) ->
    Until = case Cuts of
                #{Node := forever} -> forever;
                #{Node := Old} -> max(Old, Now + Ms);
                #{} -> Now + Ms
            end,
    %% noticed once a cut lasts the net tick time (a cut already noticed
    %% is not noticed again)
    Notice = case {Notices, is_map_key(Node, Downed)} of
                 {_, true} -> #{};
                 {#{Node := At}, false} -> #{Node => At};
                 {#{}, false} -> #{Node => Now + tick_ms()}
             end,
    W#{cuts := Cuts#{Node => Until}, notices := maps:merge(Notices, Notice)}.

%% When the net kernel notices a silent node.
tick_ms() ->
    case net_kernel:get_net_ticktime() of
        Secs when is_integer(Secs) -> Secs * 1000;
        {_, Secs} -> Secs * 1000;
        ignored -> 60000
    end.

%% @doc The world's earliest event due at or before `Limit': a heal or a
%% notice (a heal first at the same instant: the cut is over), or `none'.
-spec due(integer(), world() | none) -> {heal | notice, node(), integer()} | none.
due(_Limit, none) ->
    none;
due(Limit, #{cuts := Cuts, notices := Notices}) ->
    Events = [{At, 0, heal, N} || {N, At} <- maps:to_list(Cuts), is_integer(At), At =< Limit]
        ++ [{At, 1, notice, N} || {N, At} <- maps:to_list(Notices), At =< Limit],
    case lists:sort(Events) of
        [{At, _, Event, Node} | _] -> {Event, Node, At};
        [] -> none
    end.

%% @doc A heal (the consumers whose monitors fired for the cut are told
%% to subscribe again) or a notice (the monitors across the cut fire as
%% `noconnection'): the world after it, the trace's line and the steps it
%% queues, `{To, Pid, Msg}', by the receivers' names (`Name' names a pid).
-spec event(heal | notice, node(), fun((pid()) -> string()), world()) ->
          {world(), iodata(), [{pid(), pid(), term()}]}.
event(heal, Node, Name, W) ->
    {W1, Consumers} = heal(Node, W),
    {W1, ["heal ", atom_to_list(Node)],
     [{C, C, ?WIRE_RESUBSCRIBE} || {_, C} <- lists:sort([{Name(C), C} || C <- Consumers])]};
event(notice, Node, Name, W) ->
    {W1, Fired} = notice(Node, W),
    Downs = lists:sort([{Name(C), Name(P), C, {'DOWN', Ref, process, P, noconnection}}
                        || {C, Ref, P} <- Fired]),
    {W1, ["noconnection ", atom_to_list(Node)], [{C, C, Down} || {_, _, C, Down} <- Downs]}.

heal(Node, W = #{cuts := Cuts, notices := Notices, downed := Downed}) ->
    {W#{cuts := maps:remove(Node, Cuts), notices := maps:remove(Node, Notices),
        downed := maps:remove(Node, Downed)}, maps:get(Node, Downed, [])}.

notice(Node, W = #{mons := Mons, notices := Notices, downed := Downed}) ->
    Fired = [{C, Ref, P} || {Ref, {C, P}} <- maps:to_list(Mons), node(C) =/= node(P),
                            node(C) =:= Node orelse node(P) =:= Node],
    {W#{mons := maps:without([Ref || {_, Ref, _} <- Fired], Mons),
        notices := maps:remove(Node, Notices),
        downed := Downed#{Node => lists:usort([C || {C, _, _} <- Fired])}}, Fired}.

%% @doc Consumer `C' monitors `Pid' of another node with `Ref'.
-spec monitor(pid(), pid(), reference(), world()) -> world().
monitor(C, Pid, Ref, W = #{mons := Mons}) ->
    W#{mons := Mons#{Ref => {C, Pid}}}.

-spec demonitor(reference(), world()) -> world().
demonitor(Ref, W = #{mons := Mons}) ->
    W#{mons := maps:remove(Ref, Mons)}.

%% @doc Whether a message from node `From' to node `To' is lost to a cut.
-spec lost(node(), node(), world() | none) -> boolean().
lost(_From, _To, none) -> false;
lost(Same, Same, _W) -> false;
lost(From, To, #{cuts := Cuts}) -> is_map_key(From, Cuts) orelse is_map_key(To, Cuts).

%% @doc The node a step sent to `To' (found as `Pid' on the sender's
%% node, `remote' or `undefined') by `From' goes to.
-spec dest(term(), pid() | remote | undefined, pid()) -> node().
dest(_To, Pid, _From) when is_pid(Pid) -> node(Pid);
dest(To, _Pid, From) when is_atom(To) -> node(From);
dest(To, _Pid, _From) -> node_of(To).

%% Whether the processes of `Node' are gone for good.
killed(Node, #{cuts := Cuts}) -> maps:get(Node, Cuts, none) =:= forever.

%% @doc The key of a timer set outside any step: among the timers of its
%% deadline, ordered by `Owner' (its name and kind), not by when its
%% message came from whichever node; before those set inside steps.
-spec timer_key(integer(), term(), gb_trees:tree()) -> {integer(), integer()}.
timer_key(Deadline, Owner, Ts) ->
    free_key({Deadline, -1 - erlang:phash2(Owner, 1 bsl 27)}, Ts).

free_key(Key = {Deadline, N}, Ts) ->
    case gb_trees:is_defined(Key, Ts) of
        true -> free_key({Deadline, N - (1 bsl 27)}, Ts);
        false -> Key
    end.

%% @doc A message for another node that is no step goes as in real time,
%% and never waits.
-spec send_out(term(), term()) -> ok.
send_out(To, Msg) ->
    try erlang:send(To, Msg, [noconnect, nosuspend]) of
        _ -> ok
    catch
        error:badarg -> ok
    end.

%%====================================================================
%% Steps to other nodes
%%====================================================================

%% @doc The node an address (or the process it was resolved to) is on.
-spec node_of(term()) -> node().
node_of(Pid) when is_pid(Pid) -> node(Pid);
node_of({_Reg, Node}) when is_atom(Node) -> Node;
node_of(_) -> node().

%% @doc Hands `Msg' for `To' (`Target': its pid, or `remote' for a name
%% of another node) to its node's agent as a step at simulated `Now':
%% `{sent, Token}', or `lost' for a node killed.
-spec step(term(), pid() | remote, term(), integer(), world()) -> {sent, reference(), node()} | lost.
step(To, Target, Msg, Now, W) ->
    Node = node_of(case Target of
                       _ when is_pid(Target) -> Target;
                       _ -> To
                   end),
    case killed(Node, W) of
        true ->
            lost;
        false ->
            Token = make_ref(),
            Addr = case Target of
                       _ when is_pid(Target) -> Target;
                       _ -> element(1, To)
                   end,
            Body = case Msg of
                       {stimulus, M} -> M;
                       _ -> Msg
                   end,
            {?AGENT, Node} ! {deliver, Now, Addr, Token, Body, self()},
            {sent, Token, Node}
    end.

%% @doc The steps right behind step `Item' in the queue that go to the
%% same node (not this one, not killed), taken out of it: they go to that
%% node's agent with it, as one batch, and run there one at a time in the
%% same order. Each step's sends come to the clock in that order too (the
%% next step starts after the one before said `done', and all of them
%% travel over the one connection between the two nodes), so the queue is
%% what stepping them one by one from here would make it, for one round
%% trip instead of one per step.
-spec batch({term(), term(), term()}, queue:queue(), world()) -> {list(), queue:queue()}.
batch({To, Target, Msg}, Q, W) ->
    Node = item_node(To, Target),
    case Node =:= node() orelse killed(Node, W) orelse exit_step(Msg) of
        true -> {[], Q};
        false -> batch_more(Node, Q, [])
    end.

batch_more(Node, Q, Acc) ->
    case queue:peek(Q) of
        {value, {To, Target, Msg} = Item} when Target =/= undefined ->
            case item_node(To, Target) =:= Node andalso not exit_step(Msg)
                andalso (is_pid(Target) orelse Target =:= remote) of
                true -> batch_more(Node, queue:drop(Q), [Item | Acc]);
                false -> {lists:reverse(Acc), Q}
            end;
        _ ->
            {lists:reverse(Acc), Q}
    end.

item_node(_To, Target) when is_pid(Target) -> node(Target);
item_node(To, _Target) -> node_of(To).

exit_step({exit, _}) -> true;
exit_step(_) -> false.

%% @doc Hands a batch of steps (`{To, Target, Msg}', all for one node) to
%% that node's agent: the clock hears `{Tag, batched, Token, Lost, Rest}'.
-spec step_batch([{term(), term(), term()}], integer()) -> {reference(), node()}.
step_batch([{To, Target, _} | _] = Items, Now) ->
    Token = make_ref(),
    Steps = [{address(T, P), body(M), Item} || {T, P, M} = Item <- Items],
    Node = item_node(To, Target),
    {?AGENT, Node} ! {batch, Now, Steps, Token, self()},
    {Token, Node}.

address(_To, Target) when is_pid(Target) -> Target;
address(To, _Target) -> element(1, To).

body({stimulus, M}) -> M;
body(M) -> M.

%% @doc The registered name of a process of another node, as the trace
%% writes it (called by the clock).
-spec regname(pid()) -> string().
regname(Pid) ->
    case get(?REGS) of
        #{Pid := Reg} -> atom_to_list(Reg);
        _ -> "-"
    end.

%% @doc The clock keeps the registered name of a process of another node
%% that came up in the world.
-spec remember(pid(), world() | none) -> world() | none.
remember(Pid, W) when W =/= none, node(Pid) =/= node() ->
    case catch erpc:call(node(Pid), erlang, process_info, [Pid, registered_name], ?CALL_MS) of
        {registered_name, Reg} ->
            Regs = case get(?REGS) of
                       undefined -> #{};
                       R -> R
                   end,
            put(?REGS, Regs#{Pid => Reg});
        _ ->
            ok
    end,
    W;
remember(_Pid, W) ->
    W.

%%====================================================================
%% The agent (on each other node)
%%====================================================================

%% @doc `start': this node joins clock `Clock' (an agent is started, the
%% event path points at `Clock'); `stop': it leaves it.
-spec agent(start | stop, pid()) -> ok | {error, term()}.
agent(start, Clock) ->
    _ = agent(stop, Clock),
    Self = self(),
    Pid = spawn(fun() -> agent_init(Clock, Self) end),
    receive
        {Pid, ok} -> ok
    after ?CALL_MS ->
            exit(Pid, kill),
            {error, agent_timeout}
    end;
agent(stop, _Clock) ->
    case whereis(?AGENT) of
        undefined ->
            ok;
        Pid ->
            Mon = erlang:monitor(process, Pid),
            Pid ! stop,
            receive {'DOWN', Mon, process, Pid, _} -> ok
            after ?CALL_MS -> exit(Pid, kill), ok
            end
    end.

agent_init(Clock, Parent) ->
    true = register(?AGENT, self()),
    Cell = atomics:new(1, [{signed, true}]),
    persistent_term:put(toroco_lockstep, Clock),
    ok = toroco_clock:lockstep_cell(Cell),
    Mon = erlang:monitor(process, Clock),
    Parent ! {self(), ok},
    agent_loop(Cell, Mon).

agent_loop(Cell, Mon) ->
    receive
        {deliver, Now, Target, Token, Msg, Clock} ->
            atomics:put(Cell, 1, Now),
            Pid = case Target of
                      P when is_pid(P) -> P;
                      Reg -> whereis(Reg)
                  end,
            Clock ! {?TAG, at, Token, Pid, monitored_by(Pid)},
            _ = is_pid(Pid) andalso (Pid ! ?WIRE_STEP(Token, Msg)),
            agent_loop(Cell, Mon);
        {batch, Now, Steps, Token, Clock} ->
            atomics:put(Cell, 1, Now),
            {Lost, Rest} = run_batch(Steps, 0),
            Clock ! {?TAG, batched, Token, Lost, Rest},
            agent_loop(Cell, Mon);
        stop ->
            agent_end();
        {'DOWN', Mon, process, _, Reason} ->
            logger:warning("toroco_lockstep_nodes: the world's clock went away (~0p); this "
                           "node is back on its own clock", [Reason], ?LOG),
            agent_end()
    end.

%% A batch's steps, one at a time: each done before the next goes; one
%% whose receiver dies ends the batch, the steps behind it handed back.
run_batch([], Lost) ->
    {Lost, []};
run_batch([{Addr, Msg, _Item} | Steps], Lost) ->
    case whereis_addr(Addr) of
        undefined ->
            run_batch(Steps, Lost + 1);
        Pid ->
            Ref = erlang:monitor(process, Pid),
            Pid ! ?WIRE_STEP({relay, self(), Ref}, Msg),
            receive
                {?TAG, done, Ref} ->
                    erlang:demonitor(Ref, [flush]),
                    run_batch(Steps, Lost);
                {'DOWN', Ref, process, Pid, _} ->
                    {Lost, [Item || {_, _, Item} <- Steps]}
            end
    end.

whereis_addr(Pid) when is_pid(Pid) -> Pid;
whereis_addr(Reg) -> whereis(Reg).

agent_end() ->
    _ = persistent_term:erase(toroco_lockstep),
    ok = toroco_clock:lockstep_cell(undefined).

monitored_by(Pid) when is_pid(Pid) ->
    case erlang:process_info(Pid, monitored_by) of
        {monitored_by, By} -> [B || B <- By, is_pid(B)];
        undefined -> []
    end;
monitored_by(_) ->
    [].
