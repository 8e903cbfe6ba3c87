%% @doc Lockstep virtual time (SPEC §14, "Lockstep"): the process through
%% which a node's event path runs while a simulated world is its clock.
%%
%% In lockstep (`toroco_clock:lockstep/1') every message of the event path
%% (`toroco_wire:send/2': emissions, gated emissions, deliveries, acks,
%% hellos) is handed to this process instead of being sent, and this process
%% delivers them one at a time, in the order it received them: it sends one
%% as `WIRE_STEP(Token, Msg)', monitors the receiver, and sends the next
%% only when the receiver says `done' (the engine and the consumer shell do,
%% once the message and every event it inserted were handled) or dies. A
%% message to a registered name goes to the process that had the name when
%% it was sent, as `Name ! Msg' would in real time, not to one that took the
%% name while the message waited its turn (a behavior removed and added
%% again must not get the unsubscription meant for the one before). Since
%% only one process of the event path works at a time, and what it sends is
%% queued in the order it sends it, the order of everything that happens
%% depends only on the stimuli and the wiring: not on the schedulers, the
%% machine's load or `erl +T'.
%%
%% Timers live here too. The engine's gen_statem timeouts (`state_timeout',
%% `{timeout, Name}', event timeouts) and the routers' and gates' hold
%% timers are registered with a simulated deadline; the world moves time
%% with {@link tick/3}, and a timer fires (as a step, `WIRE_TIMER(Kind,
%% Msg)') when the queue is empty and its deadline is at or before the time
%% being reached, in order of deadline, then of registration. Simulated time
%% is read by `toroco_clock:now_ms/0' from an `atomics' cell this process
%% writes.
%%
%% Exits are steps (SPEC §17): every process of the event path (behavior,
%% device, router, gate) says `up' as its `init' starts, with its name,
%% its supervisor and its layer, and `ready' as it ends; this process
%% monitors it. When one dies (a crash while handling its step, or the
%% `{exit, Pid, Reason}' stimulus of a fault schedule) the node settles
%% before anything else goes: nothing is delivered and no timer fires until
%% the dead process's restart is `ready' (its `init', its hellos,
%% re-subscriptions and latch handover queued as steps), or its layer is
%% out; the consumers that monitored it hand their
%% `DOWN' over instead of acting on it (`down/1'); then a barrier asks
%% every process of the path to answer once what it had before is handled,
%% and what the settle gathered is queued in a fixed order: the `DOWN's by
%% receiver's name, then what the restarted processes sent and the timers
%% they set, by sender's name. Restart intensity counts simulated time: a
%% layer whose behaviors restart more than `layer_restart_intensity'
%% ({MaxRestarts, Seconds}, app env) allows within that many simulated
%% seconds is taken out (its supervisor's own real-time intensity is lifted
%% while lockstep runs: `toroco_layer_sup'). The trace shows each exit
%% (`exit Reason'), restart (`restarted') and layer taken out (`layer L
%% out'). A settle that does not resolve within 5 s of real time is given
%% up with a warning and counted (`unsettled' in {@link info/0}).
%%
%% Quiescence: the node is quiescent when nothing is queued, nothing is in
%% flight, no exit is settling and no timer is due at or before now;
%% {@link tick/3} and {@link settle/0} answer then. No process is polled.
%%
%% Several nodes (SPEC §13, §17): {@link join/1} makes the robot's other
%% nodes join this clock (`toroco_lockstep_nodes': an agent on each points
%% its event path here and hands it its steps at their simulated instant),
%% so a message between nodes (keep-alives and subscriptions included) is
%% a step in this one order, and {@link cut/2} cuts a node off inside the
%% world. Each trace line names its node after the time then.
%%
%% The trace: with `trace => true' every step is written down as one
%% canonical line with its simulated time (emissions, deliveries, acks,
%% timers, stimuli); {@link tick/3} hands the lines over.
%%
%% This module is the clock's process and its stepping; its state
%% (`toroco_lockstep.hrl') is shared with its parts: `toroco_lockstep_settle'
%% (exits), `toroco_lockstep_timers', `toroco_lockstep_remote' (the clock's
%% side of several nodes) and `toroco_lockstep_trace' (the lines).
%%
%% Messages (from processes of this node, or of the world's other nodes):
%% <table>
%% <tr><th>message</th><th>from</th><th>effect</th></tr>
%% <tr><td>`{Tag, send, To, Pid, Msg}'</td><td>`toroco_wire:send/2'</td><td>queued
%%     for `Pid', the process `To' named then (`undefined' if none)</td></tr>
%% <tr><td>`{Tag, send, Pid, Pid, {notice, Msg, Shown}}'</td><td>`toroco_clock:notify/3'
%%     (a port program's owner)</td><td>`Msg' queued as a step for `Pid', a
%%     process of the path (traced `notice Shown'); to any other process sent
%%     as is</td></tr>
%% <tr><td>`{Tag, timer, Pid, Kind, Deadline, Msg}'</td><td>the timer's owner</td>
%%     <td>sets (or replaces) the owner's timer `Kind'</td></tr>
%% <tr><td>`{Tag, cancel, Pid, Kind}'</td><td>the owner</td><td>cancels it</td></tr>
%% <tr><td>`{Tag, done, Token}'</td><td>the receiver of a step</td><td>the next step goes</td></tr>
%% <tr><td>call `{up, Pid, Name, Sup, Layer}'</td><td>a process of the path,
%%     as its `init' starts</td><td>its predecessor's exit settled first,
%%     then monitored; answered `ok'</td></tr>
%% <tr><td>`{Tag, ready, Pid, Name}'</td><td>the same, as its `init' ends</td>
%%     <td>a restart awaited is done</td></tr>
%% <tr><td>`{Tag, down, Pid, Down}'</td><td>a consumer given a `DOWN'</td>
%%     <td>the `DOWN' comes back to it as a step once the exit settles</td></tr>
%% <tr><td>`{Tag, at, Token, Pid, MonitoredBy}'</td><td>another node's agent</td>
%%     <td>the step `Token' for that node is in flight to `Pid'</td></tr>
%% <tr><td>`{Tag, monitor, C, Pid, Ref}' / `{Tag, demonitor, Ref}'</td>
%%     <td>a consumer (`toroco_wire')</td><td>its monitor of a process of
%%     another node, fired by a cut</td></tr>
%% <tr><td>`WIRE_BARRIER(Ref)' / `{Tag, synced, Ref, Pid}'</td><td>this
%%     process → the path / back</td><td>the settle's barrier</td></tr>
%% </table>
-module(toroco_lockstep).
-behaviour(gen_server).

-include("toroco_wire.hrl").
-include("toroco_lockstep.hrl").

-import(toroco_lockstep_settle, [progress/1, exited/3, hold/3, watch/2]).
-import(toroco_lockstep_trace, [trace/4, note/2]).

-define(CALL_MS, 60000).

-export([start_link/0, send/3, timer/4, cancel/2, done/1, up/2, ready/1, down/1, synced/1]).
-export([monitored/2, demonitored/1]).
-export([start/1, stop/0, tick/3, settle/0, info/0, join/1, cut/2]).
-export([term/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).
-export_type([stimulus/0, token/0]).

%% A stimulus from the world: `Msg' to behavior or device `Name' of this
%% node (a device, as a rule), delivered as a step like any other; or
%% `{exit, Pid, Reason}', the exit signal `Reason' sent to process `Pid'
%% of the path (a behavior's, device's, router's or gate's, see
%% `toroco:whereis/1'), the step done once its exit has settled.
-type stimulus() :: {atom(), term()} | {exit, pid(), term()}.

%% A step's token: its receiver says `done' with it; another node's agent
%% relays its own (toroco_lockstep_nodes).
-type token() :: reference() | {relay, pid(), reference()}.

%%====================================================================
%% The event path's side
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Queues `Msg' for `To' (an address of this node), that is for the
%% process `To' names now.
-spec send(pid(), term(), term()) -> ok.
send(Server, To, Msg) ->
    Server ! {?TAG, send, To, whereis_local(To), Msg, self()},
    ok.

%% @doc Sets the calling process's timer `Kind' to fire at simulated
%% `Deadline' (ms) with `Msg' (a new one replaces the old).
-spec timer(pid(), term(), integer(), term()) -> ok.
timer(Server, Kind, Deadline, Msg) ->
    Server ! {?TAG, timer, self(), Kind, Deadline, Msg},
    ok.

%% @doc Cancels the calling process's timer `Kind', if set.
-spec cancel(pid(), term()) -> ok.
cancel(Server, Kind) ->
    Server ! {?TAG, cancel, self(), Kind},
    ok.

%% @doc The step `Token' was handled (sent by its receiver).
-spec done(token()) -> ok.
done({relay, Agent, Ref}) ->
    Agent ! {?TAG, done, Ref},
    ok;
done(Token) ->
    case persistent_term:get(?MODULE, none) of
        none -> ok;
        Server -> Server ! {?TAG, done, Token}, ok
    end.

%% @doc The calling process of the event path (a behavior's, device's,
%% router's or gate's) starts as `Name' in `Layer' (`none' outside the
%% layers; `consumer' for a router or a gate, which hand their `DOWN's
%% over), under the supervisor that started it: at the start of its
%% `init', in lockstep only; {@link ready/1} at its end.
-spec up(atom(), non_neg_integer() | none | consumer) -> ok.
up(Name, Layer) ->
    case persistent_term:get(?MODULE, none) of
        none ->
            ok;
        Server ->
            %% before the process sends anything: a new incarnation's
            %% messages wait for its predecessor's exit to be settled
            try gen_server:call(Server, {up, self(), Name, supervisor(), Layer}, ?CALL_MS)
            catch exit:_ -> ok
            end
    end.

%% @doc The calling process, `up' as `Name', is done with its `init'.
-spec ready(atom()) -> ok.
ready(Name) ->
    case persistent_term:get(?MODULE, none) of
        none -> ok;
        Server -> Server ! {?TAG, ready, self(), Name}, ok
    end.

%% @doc In lockstep, a consumer hands over a `DOWN' it was given: it comes
%% back as a step once the exit has settled. `false' in real time (the
%% caller acts on it at once).
-spec down(term()) -> boolean().
down(Down) ->
    case persistent_term:get(?MODULE, none) of
        none -> false;
        Server -> Server ! {?TAG, down, self(), Down}, true
    end.

%% @doc The settle's barrier `Ref' reached the calling process.
-spec synced(reference()) -> ok.
synced(Ref) ->
    case persistent_term:get(?MODULE, none) of
        none -> ok;
        Server -> Server ! {?TAG, synced, Ref, self()}, ok
    end.

%% @doc The calling consumer monitors `Pid', of another node, with `Ref'
%% (a lockstep world over several nodes fires it when it cuts that node).
-spec monitored(pid(), reference()) -> ok.
monitored(Pid, Ref) ->
    tell({?TAG, monitor, self(), Pid, Ref}).

%% @doc The calling consumer's monitor `Ref' is off.
-spec demonitored(reference()) -> ok.
demonitored(Ref) ->
    tell({?TAG, demonitor, Ref}).

%% Tells the clock, in lockstep.
tell(Msg) ->
    case persistent_term:get(?MODULE, none) of
        none -> ok;
        Server -> Server ! Msg, ok
    end.

%% The calling process's supervisor: proc_lib's first ancestor.
supervisor() ->
    case get('$ancestors') of
        [Pid | _] when is_pid(Pid) -> Pid;
        [Name | _] when is_atom(Name) -> whereis(Name);
        _ -> undefined
    end.

%%====================================================================
%% The world's side (through toroco_clock)
%%====================================================================

%% @doc Lockstep starts on this node at simulated time 0.
-spec start(#{trace => boolean()}) -> ok.
start(Opts) ->
    gen_server:call(?MODULE, {start, maps:get(trace, Opts, false)}, ?CALL_MS).

%% @doc Back to real time: pending steps are delivered as plain messages,
%% timers are dropped.
-spec stop() -> ok.
stop() ->
    gen_server:call(?MODULE, stop, ?CALL_MS).

%% @doc Moves simulated time to `T' (timers due on the way fire at their
%% deadlines), hands over the stimuli in order, and answers once the node
%% is quiescent, with the trace lines since the last tick.
-spec tick(integer() | now, [stimulus()], timeout()) -> {ok, [iodata()]} | {error, term()}.
tick(T, Stimuli, Timeout) ->
    try gen_server:call(?MODULE, {tick, T, Stimuli}, Timeout)
    catch exit:{timeout, _} -> {error, {not_quiescent, T}}
    end.

%% @doc Answers once the node is quiescent, time unchanged.
-spec settle() -> ok | {error, term()}.
settle() ->
    case tick(now, [], ?CALL_MS) of
        {ok, _} -> ok;
        Error -> Error
    end.

%% @doc The robot's other nodes `Nodes' join this node's clock (SPEC §13,
%% §17): their event paths run as steps of this one, at its simulated time.
%% `{error, {node_not_connected, Node}}' if one is not connected.
-spec join([node()]) -> ok | {error, {atom(), term()}}.
join(Nodes) ->
    gen_server:call(?MODULE, {join, Nodes}, ?CALL_MS).

%% @doc Cuts `Node' from the rest of the robot for `Ms' simulated ms from
%% now (`forever': the node is killed): a step between it and another node
%% is lost; the heal comes at its simulated time. The trace shows both.
-spec cut(node(), non_neg_integer() | forever) -> ok | {error, {atom(), node()}}.
cut(Node, Ms) ->
    gen_server:call(?MODULE, {cut, Node, Ms}, ?CALL_MS).

%% @doc Counters: steps delivered, steps lost (their receiver was not
%% there), timers pending, the simulated time.
-spec info() -> map().
info() ->
    gen_server:call(?MODULE, info, ?CALL_MS).

%%====================================================================
%% gen_server
%%====================================================================

-spec init([]) -> {ok, #s{}}.
init([]) ->
    {ok, #s{}}.

-spec handle_call(term(), gen_server:from(), #s{}) -> {reply, term(), #s{}} | {noreply, #s{}}.
handle_call({start, Trace}, _From, _S) ->
    Cell = atomics:new(1, [{signed, true}]),
    persistent_term:put(?MODULE, self()),
    ok = toroco_clock:lockstep_cell(Cell),
    {reply, ok, #s{cell = Cell, trace = case Trace of true -> []; false -> off end,
                   intensity = application:get_env(toroco, layer_restart_intensity, {5, 10}),
                   device_intensity = application:get_env(toroco, device_restart_intensity,
                                                          {20, 10})}};
handle_call(stop, _From, S = #s{cell = undefined}) ->
    {reply, ok, S};
handle_call(stop, _From, S) ->
    #s{queue = Q} = toroco_lockstep_settle:flush(S),
    _ = persistent_term:erase(?MODULE),
    ok = toroco_clock:lockstep_cell(undefined),
    _ = [forward(To, Pid, Msg) || {To, Pid, Msg} <- queue:to_list(Q)],
    ok = toroco_lockstep_nodes:leave(S#s.world),
    {reply, ok, #s{}};
handle_call({tick, _, _}, _From, S = #s{cell = undefined}) ->
    {reply, {error, not_lockstep}, S};
handle_call({tick, T, Stimuli}, From, S = #s{now = Now, waiters = W, stimuli = Old}) ->
    Target = case T of
                 now -> Now;
                 _ -> max(Now, T)
             end,
    {noreply, run(S#s{target = Target, stimuli = Old ++ Stimuli, waiters = [From | W]})};
handle_call(info, _From, S = #s{steps = N, lost = L, timers = Ts, now = Now}) ->
    {reply, #{steps => N, lost => L, timers => gb_trees:size(Ts), now_ms => Now,
              processes => map_size(S#s.procs), unsettled => S#s.unsettled}, S};
handle_call({up, Pid, Name, Sup, Layer}, _From, S = #s{cell = Cell}) when Cell =/= undefined ->
    S1 = toroco_lockstep_settle:predecessor(Name, S),
    {reply, ok, run(progress(toroco_lockstep_settle:up(Pid, Name, Sup, Layer, S1)))};
handle_call({up, _, _, _, _}, _From, S) ->
    {reply, ok, S};
handle_call({join, _}, _From, S = #s{cell = undefined}) ->
    {reply, {error, {not_lockstep, node()}}, S};
handle_call({join, Nodes}, _From, S) ->
    case toroco_lockstep_nodes:join(Nodes, self()) of
        {ok, W} -> {reply, ok, S#s{world = W}};
        Error -> {reply, Error, S}
    end;
handle_call({cut, Node, Ms}, _From, S) ->
    toroco_lockstep_remote:cut(Node, Ms, S);
handle_call(_Req, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), #s{}) -> {noreply, #s{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #s{}) -> {noreply, #s{}}.
handle_info({?TAG, send, To, Pid, Msg, _From}, S = #s{cell = undefined}) ->
    %% sent as lockstep ended: on its way as in real time
    forward(To, Pid, Msg),
    {noreply, S};
handle_info({?TAG, send, To, Pid, Msg, From}, S = #s{queue = Q, settle = Settle}) ->
    case is_step(Msg) orelse is_notice(Msg, Pid, S)
        orelse (S#s.world =/= none andalso is_sub(Msg)) of
        true when S#s.world =/= none -> {noreply, across(To, Pid, Msg, From, S)};
        true when Settle =/= none -> {noreply, hold(From, {send, To, Pid, Msg}, S)};
        true -> {noreply, run(S#s{queue = queue:in({To, Pid, Msg}, Q)})};
        false -> forward(To, Pid, Msg), {noreply, S}
    end;
handle_info({?TAG, timer, Pid, Kind, Deadline, Msg}, S = #s{settle = #settle{}}) ->
    {noreply, hold(Pid, {timer, Pid, Kind, Deadline, Msg}, S)};
handle_info({?TAG, timer, Pid, Kind, Deadline, Msg}, S = #s{world = none}) ->
    {noreply, run(toroco_lockstep_timers:set(Pid, Kind, Deadline, Msg, S))};
handle_info({?TAG, timer, Pid, Kind, Deadline, Msg}, S) ->
    {noreply, run(toroco_lockstep_timers:world(Pid, Kind, Deadline, Msg, S))};
handle_info({?TAG, at, Token, Pid, By}, S) ->
    {noreply, run(toroco_lockstep_remote:at(Token, Pid, By, S))};
handle_info({?TAG, batched, Token, Lost, Rest}, S) ->
    {noreply, run(toroco_lockstep_remote:batched(Token, Lost, Rest, S))};
handle_info({?TAG, monitor, C, Pid, Ref}, S = #s{world = W}) when W =/= none ->
    {noreply, S#s{world = toroco_lockstep_nodes:monitor(C, Pid, Ref, W)}};
handle_info({?TAG, demonitor, Ref}, S = #s{world = W}) when W =/= none ->
    {noreply, S#s{world = toroco_lockstep_nodes:demonitor(Ref, W)}};
handle_info({?TAG, cancel, Pid, Kind}, S = #s{settle = #settle{}}) ->
    {noreply, hold(Pid, {cancel, Pid, Kind}, S)};
handle_info({?TAG, cancel, Pid, Kind}, S) ->
    {noreply, run(toroco_lockstep_timers:drop(Pid, Kind, S))};
handle_info({?TAG, done, Token}, S = #s{inflight = {Token, Mon, _}}) ->
    erlang:demonitor(Mon, [flush]),
    {noreply, run(S#s{inflight = none})};
handle_info({?TAG, done, _Stale}, S) ->
    {noreply, S};
handle_info({?TAG, Kind, _} = Msg, S) when Kind =:= devices_out; Kind =:= settle_guard ->
    settled(toroco_lockstep_settle:info(Msg, S), S);
handle_info({?TAG, Kind, _, _} = Msg, S) when Kind =:= ready; Kind =:= down; Kind =:= synced ->
    settled(toroco_lockstep_settle:info(Msg, S), S);
handle_info({'DOWN', Mon, process, Pid, Reason}, S = #s{procs = Procs}) ->
    case Procs of
        #{Pid := #{mon := Mon}} ->
            {noreply, run(progress(exited(Pid, Reason, S)))};
        #{Pid := #{mon := Other}} ->
            %% the step's own monitor: the death is the path's all the same
            erlang:demonitor(Other, [flush]),
            {noreply, run(progress(exited(Pid, Reason, S)))};
        #{} ->
            case S#s.inflight of
                {_, Mon, _} ->
                    {noreply, run(S#s{inflight = none})};
                _ ->
                    {noreply, run(progress(toroco_lockstep_settle:sup_down(Pid, S)))}
            end
    end;
handle_info(_Info, S) ->
    {noreply, S}.

%% What an exit's settle made of a message: the node steps on from there.
settled(unchanged, S) -> {noreply, S};
settled(S1, _S) -> {noreply, run(S1)}.

%%====================================================================
%% Exits
%%====================================================================

%%====================================================================
%% Stepping
%%====================================================================

%% One step at a time: the queue first, then the earliest timer due by the
%% time being reached; with neither, time is there: the tick's stimuli
%% go, and once they are handled the waiters are answered.
run(S = #s{inflight = {_, _, _}}) ->
    S;
run(S = #s{cell = undefined}) ->
    S;
run(S = #s{settle = #settle{}}) ->
    S;
run(S = #s{queue = Q}) ->
    case queue:out(Q) of
        {{value, {To, Pid, Msg}}, Q1} ->
            run(deliver(To, Pid, Msg, S#s{queue = Q1}));
        {empty, _} ->
            due(S)
    end.

due(S = #s{world = W}) when W =/= none ->
    case toroco_lockstep_nodes:due(toroco_lockstep_timers:next_deadline(S), W) of
        {Event, Node, At} ->
            S1 = set_now(max(S#s.now, At), S),
            run(toroco_lockstep_remote:event(Event, Node, S1));
        none ->
            due_timer(S)
    end;
due(S) ->
    due_timer(S).

due_timer(S = #s{timers = Ts, target = Target}) ->
    case gb_trees:is_empty(Ts) of
        false ->
            case gb_trees:smallest(Ts) of
                {{Deadline, _} = Key, {Pid, Kind, Msg}} when Deadline =< Target ->
                    S1 = set_now(max(S#s.now, Deadline), S),
                    S2 = S1#s{timers = gb_trees:delete(Key, Ts),
                              owned = maps:remove({Pid, Kind}, S1#s.owned)},
                    run(deliver(Pid, Pid, ?WIRE_TIMER(Kind, Msg), S2));
                _ ->
                    stimuli(S)
            end;
        true ->
            stimuli(S)
    end.

stimuli(S = #s{stimuli = []}) ->
    quiescent(S);
stimuli(S = #s{stimuli = Stimuli, queue = Q}) ->
    Q1 = lists:foldl(fun({exit, Pid, Reason}, Acc) ->
                             queue:in({Pid, Pid, {exit, Reason}}, Acc);
                        ({Name, Msg}, Acc) ->
                             To = {toroco_names:process(Name), node()},
                             queue:in({To, whereis_local(To), {stimulus, Msg}}, Acc)
                     end, Q, Stimuli),
    run(set_now(S#s.target, S#s{stimuli = [], queue = Q1})).

quiescent(S = #s{waiters = []}) ->
    set_now(S#s.target, S);
quiescent(S = #s{waiters = W, trace = Trace}) ->
    S1 = set_now(S#s.target, S),
    Lines = case Trace of
                off -> [];
                _ -> lists:reverse(Trace)
            end,
    _ = [gen_server:reply(From, {ok, Lines}) || From <- lists:reverse(W)],
    S1#s{waiters = [], trace = case Trace of off -> off; _ -> [] end}.

set_now(T, S = #s{now = T}) ->
    S;
set_now(T, S = #s{cell = Cell}) ->
    atomics:put(Cell, 1, T),
    S#s{now = T}.

deliver(To, Target, {exit, Reason} = Msg, S = #s{steps = N}) when is_pid(Target) ->
    %% a fault: the exit signal, the step done once the exit has settled
    Mon = erlang:monitor(process, Target),
    S1 = watch(Target, S),
    exit(Target, Reason),
    trace(To, Target, Msg, S1#s{inflight = {none, Mon, Target}, steps = N + 1});
deliver({Reg, Node} = To, remote, Msg, S = #s{world = W}) when W =/= none, Node =:= node() ->
    %% sent from another node to this one: found here, as it arrives
    deliver(To, whereis(Reg), Msg, S);
deliver(To, Target, Msg, S = #s{world = W}) when W =/= none, Target =/= undefined,
                                              not is_pid(Target) orelse node(Target) =/= node() ->
    toroco_lockstep_remote:deliver(To, Target, Msg, S);
deliver(To, Target, Msg, S = #s{steps = N}) ->
    case Target of
        Pid when is_pid(Pid) ->
            Token = make_ref(),
            Mon = erlang:monitor(process, Pid),
            S1 = watch(Pid, S),
            Pid ! ?WIRE_STEP(Token, case Msg of
                                        {stimulus, M} -> M;
                                        {notice, M, _} -> M;
                                        _ -> Msg
                                    end),
            trace(To, Pid, Msg, S1#s{inflight = {Token, Mon, Pid}, steps = N + 1});
        remote ->
            toroco_lockstep_nodes:send_out(To, Msg),
            S;
        undefined ->
            trace(To, undefined, Msg, S#s{lost = S#s.lost + 1})
    end.

%% The messages that are steps: those of the event path, which every
%% receiver of them (the engine, the consumer shell) hands back as done.
%% Anything else sent through toroco_wire (the wiring servers' directory
%% exchange) goes as it would in real time, since its receiver would never
%% say done.
is_step(?WIRE_EVENT(_, _)) -> true;
is_step(?WIRE_GATED(_, _)) -> true;
is_step(?WIRE_IN(_, _)) -> true;
is_step(?WIRE_IN(_, _, _)) -> true;
is_step(?WIRE_ACK(_)) -> true;
is_step(?WIRE_HELLO(_, _, _)) -> true;
is_step(?WIRE_STATE(_, _, _, _)) -> true;
is_step(?WIRE_RX(_, _)) -> true;
is_step(?WIRE_UNSUB(_, _)) -> true;
is_step(?WIRE_RESUBSCRIBE) -> true;
is_step(?WIRE_ALIVE(_, _, _)) -> true;
is_step(_) -> false.

%% A notice (toroco_clock:notify/2) to a process of the path is a step.
is_notice({notice, _, _}, Pid, #s{procs = Procs}) -> is_map_key(Pid, Procs);
is_notice(_Msg, _Pid, _S) -> false.

%% A subscription to another node's upstream: a step in a world of several
%% nodes (toroco_wire sends no other through the clock).
is_sub(?WIRE_SUB(_, _)) -> true;
is_sub(_) -> false.

%% Sent as in real time, to the process the address named when it was sent.
forward(_To, _Pid, {exit, _}) -> ok;
forward(_To, Pid, {notice, Msg, _}) when is_pid(Pid) -> Pid ! Msg, ok;
forward(_To, Pid, Msg) when is_pid(Pid) -> Pid ! Msg, ok;
forward(To, remote, Msg) -> toroco_lockstep_nodes:send_out(To, Msg);
forward(_To, undefined, _Msg) -> ok.

whereis_local(Pid) when is_pid(Pid), node(Pid) =:= node() -> Pid;
whereis_local(Pid) when is_pid(Pid) -> remote;
whereis_local({Reg, Node}) when Node =:= node() -> whereis(Reg);
whereis_local({_, _}) -> remote;
whereis_local(Reg) when is_atom(Reg) -> whereis(Reg).

%% @private `~0tp' of a term, written fast (`toroco_lockstep_trace').
-spec term(term()) -> iolist().
term(T) ->
    toroco_lockstep_trace:term(T).

%%====================================================================
%% Several nodes (the world's side is toroco_lockstep_nodes)
%%====================================================================

%% A step sent in a world of several nodes: lost if it crosses a cut.
across(To, Pid, Msg, From, S = #s{world = W}) ->
    case toroco_lockstep_nodes:lost(node(From), toroco_lockstep_nodes:dest(To, Pid, From), W) of
        true -> S#s{lost = S#s.lost + 1};
        false when S#s.settle =/= none -> hold(From, {send, To, Pid, Msg}, S);
        false -> run(S#s{queue = queue:in({To, Pid, Msg}, S#s.queue)})
    end.
