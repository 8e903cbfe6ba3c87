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

-export([join/2, leave/1, nodes/1, cut/4, due/2, heal/2, notice/2, lost/3, killed/2]).
-export([monitor/4, demonitor/2]).
-export([deliver/5, node_of/1, regname/1, remember/2]).
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
%% simulated ms (`forever': the node is killed). The world's own node and
%% a node not in the world are refused.
-spec cut(node(), non_neg_integer() | forever, integer(), world()) ->
          {ok, world()} | {error, {atom(), node()}}.
cut(Node, _Ms, _Now, _W) when Node =:= node() ->
    {error, {own_node, Node}};
cut(Node, Ms, Now, W = #{nodes := Nodes, cuts := Cuts, notices := Notices, downed := Downed}) ->
    case lists:member(Node, Nodes) of
        false ->
            {error, {unknown_node, Node}};
        true when Ms =:= forever ->
            {ok, W#{cuts := Cuts#{Node => forever}, notices := Notices#{Node => Now}}};
        true ->
            Until = case Cuts of
                        #{Node := forever} -> forever;
                        #{Node := Old} -> max(Old, Now + Ms);
                        #{} -> Now + Ms
                    end,
            Notice = case Notices of
                         #{Node := At} -> At;
                         #{} -> Now + tick_ms()
                     end,
            {ok, W#{cuts := Cuts#{Node => Until},
                    notices := case is_map_key(Node, Downed) of
                                   true -> Notices;
                                   false -> Notices#{Node => Notice}
                               end}}
    end.

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

%% @doc `Node''s cut is over: the world without it, and the consumers
%% whose monitors fired for it (to be told to subscribe again).
-spec heal(node(), world()) -> {world(), [pid()]}.
heal(Node, W = #{cuts := Cuts, notices := Notices, downed := Downed}) ->
    {W#{cuts := maps:remove(Node, Cuts), notices := maps:remove(Node, Notices),
        downed := maps:remove(Node, Downed)}, maps:get(Node, Downed, [])}.

%% @doc The net kernel notices `Node''s cut: the monitors across it fire,
%% `[{Consumer, Ref, Monitored}]'.
-spec notice(node(), world()) -> {world(), [{pid(), reference(), pid()}]}.
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

%% @doc Whether the processes of `Node' are gone for good.
-spec killed(node(), world() | none) -> boolean().
killed(_Node, none) -> false;
killed(Node, #{cuts := Cuts}) -> maps:get(Node, Cuts, none) =:= forever.

%%====================================================================
%% Steps to other nodes
%%====================================================================

%% @doc The node an address (or the process it was resolved to) is on.
-spec node_of(term()) -> node().
node_of(Pid) when is_pid(Pid) -> node(Pid);
node_of({_Reg, Node}) when is_atom(Node) -> Node;
node_of(_) -> node().

%% @doc Hands step `Token' (message `Msg') to `Target' on its node, at
%% simulated `Now', through that node's agent.
-spec deliver(node(), pid() | atom(), reference(), term(), integer()) -> ok.
deliver(Node, Target, Token, Msg, Now) ->
    {?AGENT, Node} ! {deliver, Now, Target, Token, Msg, self()},
    ok.

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
        stop ->
            agent_end();
        {'DOWN', Mon, process, _, Reason} ->
            logger:warning("toroco_lockstep_nodes: the world's clock went away (~0p); this "
                           "node is back on its own clock", [Reason], ?LOG),
            agent_end()
    end.

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
