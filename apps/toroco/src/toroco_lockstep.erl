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
%% Quiescence: the node is quiescent when nothing is queued, nothing is in
%% flight and no timer is due at or before now; {@link tick/3} and
%% {@link settle/0} answer then. No process is polled.
%%
%% The trace: with `trace => true' every step is written down as one
%% canonical line with its simulated time (emissions, deliveries, acks,
%% timers, stimuli); {@link tick/3} hands the lines over.
%%
%% Messages (all from processes of this node):
%% <table>
%% <tr><th>message</th><th>from</th><th>effect</th></tr>
%% <tr><td>`{Tag, send, To, Pid, Msg}'</td><td>`toroco_wire:send/2'</td><td>queued
%%     for `Pid', the process `To' named then (`undefined' if none)</td></tr>
%% <tr><td>`{Tag, timer, Pid, Kind, Deadline, Msg}'</td><td>the timer's owner</td>
%%     <td>sets (or replaces) the owner's timer `Kind'</td></tr>
%% <tr><td>`{Tag, cancel, Pid, Kind}'</td><td>the owner</td><td>cancels it</td></tr>
%% <tr><td>`{Tag, done, Token}'</td><td>the receiver of a step</td><td>the next step goes</td></tr>
%% </table>
-module(toroco_lockstep).
-behaviour(gen_server).

-include("toroco_wire.hrl").

-export([start_link/0, send/3, timer/4, cancel/2, done/1]).
-export([start/1, stop/0, tick/3, settle/0, info/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).
-export_type([stimulus/0]).

%% A stimulus from the world: `Msg' to behavior or device `Name' of this
%% node (a device, as a rule), delivered as a step like any other.
-type stimulus() :: {atom(), term()}.

-define(TAG, '$toroco_lockstep').
-define(CALL_MS, 60000).
-define(LOG, #{domain => [toroco, clock]}).

%% a queued message: its address, the process it was sent to, the message
-type item() :: {term(), pid() | undefined | remote, term()}.

-record(s, {queue = queue:new() :: queue:queue(item()),
            inflight = none :: none | {reference(), reference()},
            timers = gb_trees:empty() :: gb_trees:tree({integer(), non_neg_integer()},
                                                       {pid(), term(), term()}),
            owned = #{} :: #{{pid(), term()} => {integer(), non_neg_integer()}},
            seq = 0 :: non_neg_integer(),
            now = 0 :: integer(),
            target = 0 :: integer(),
            cell :: atomics:atomics_ref() | undefined,
            waiters = [] :: [gen_server:from()],
            %% a tick's stimuli: they go once its time is reached
            stimuli = [] :: [stimulus()],
            trace = off :: off | [iodata()],
            steps = 0 :: non_neg_integer(),
            lost = 0 :: non_neg_integer()}).

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
    Server ! {?TAG, send, To, whereis_local(To), Msg},
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
-spec done(reference()) -> ok.
done(Token) ->
    case persistent_term:get(?MODULE, none) of
        none -> ok;
        Server -> Server ! {?TAG, done, Token}, ok
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
    {reply, ok, #s{cell = Cell, trace = case Trace of true -> []; false -> off end}};
handle_call(stop, _From, S = #s{cell = undefined}) ->
    {reply, ok, S};
handle_call(stop, _From, #s{queue = Q}) ->
    _ = persistent_term:erase(?MODULE),
    ok = toroco_clock:lockstep_cell(undefined),
    _ = [forward(To, Pid, Msg) || {To, Pid, Msg} <- queue:to_list(Q)],
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
    {reply, #{steps => N, lost => L, timers => gb_trees:size(Ts), now_ms => Now}, S};
handle_call(_Req, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), #s{}) -> {noreply, #s{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #s{}) -> {noreply, #s{}}.
handle_info({?TAG, send, To, Pid, Msg}, S = #s{cell = undefined}) ->
    %% sent as lockstep ended: on its way as in real time
    forward(To, Pid, Msg),
    {noreply, S};
handle_info({?TAG, send, To, Pid, Msg}, S = #s{queue = Q}) ->
    case is_step(Msg) of
        true -> {noreply, run(S#s{queue = queue:in({To, Pid, Msg}, Q)})};
        false -> forward(To, Pid, Msg), {noreply, S}
    end;
handle_info({?TAG, timer, Pid, Kind, Deadline, Msg}, S) ->
    #s{timers = Ts, owned = Owned, seq = Seq} = S1 = drop_timer(Pid, Kind, S),
    Key = {Deadline, Seq},
    {noreply, run(S1#s{timers = gb_trees:insert(Key, {Pid, Kind, Msg}, Ts),
                       owned = Owned#{{Pid, Kind} => Key}, seq = Seq + 1})};
handle_info({?TAG, cancel, Pid, Kind}, S) ->
    {noreply, run(drop_timer(Pid, Kind, S))};
handle_info({?TAG, done, Token}, S = #s{inflight = {Token, Mon}}) ->
    erlang:demonitor(Mon, [flush]),
    {noreply, run(S#s{inflight = none})};
handle_info({?TAG, done, _Stale}, S) ->
    {noreply, S};
handle_info({'DOWN', Mon, process, _, _}, S = #s{inflight = {_, Mon}}) ->
    {noreply, run(S#s{inflight = none})};
handle_info(_Info, S) ->
    {noreply, S}.

%%====================================================================
%% Stepping
%%====================================================================

%% One step at a time: the queue first, then the earliest timer due by the
%% time being reached; with neither, time is there: the tick's stimuli
%% go, and once they are handled the waiters are answered.
run(S = #s{inflight = {_, _}}) ->
    S;
run(S = #s{cell = undefined}) ->
    S;
run(S = #s{queue = Q}) ->
    case queue:out(Q) of
        {{value, {To, Pid, Msg}}, Q1} ->
            run(deliver(To, Pid, Msg, S#s{queue = Q1}));
        {empty, _} ->
            due(S)
    end.

due(S = #s{timers = Ts, target = Target}) ->
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
    Q1 = lists:foldl(fun({Name, Msg}, Acc) ->
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

deliver(To, Target, Msg, S = #s{steps = N}) ->
    case Target of
        Pid when is_pid(Pid) ->
            Token = make_ref(),
            Mon = erlang:monitor(process, Pid),
            Pid ! ?WIRE_STEP(Token, case Msg of
                                        {stimulus, M} -> M;
                                        _ -> Msg
                                    end),
            trace(To, Pid, Msg, S#s{inflight = {Token, Mon}, steps = N + 1});
        remote ->
            toroco_wire:send(To, Msg),
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
is_step(_) -> false.

%% Sent as in real time, to the process the address named when it was sent.
forward(_To, Pid, Msg) when is_pid(Pid) -> Pid ! Msg, ok;
forward(To, remote, Msg) -> toroco_wire:send(To, Msg);
forward(_To, undefined, _Msg) -> ok.

whereis_local(Pid) when is_pid(Pid), node(Pid) =:= node() -> Pid;
whereis_local(Pid) when is_pid(Pid) -> remote;
whereis_local({Reg, Node}) when Node =:= node() -> whereis(Reg);
whereis_local({_, _}) -> remote;
whereis_local(Reg) when is_atom(Reg) -> whereis(Reg).

drop_timer(Pid, Kind, S = #s{owned = Owned, timers = Ts}) ->
    case Owned of
        #{{Pid, Kind} := Key} ->
            S#s{owned = maps:remove({Pid, Kind}, Owned), timers = gb_trees:delete(Key, Ts)};
        #{} ->
            S
    end.

%%====================================================================
%% The trace
%%====================================================================

trace(_To, _Pid, _Msg, S = #s{trace = off}) ->
    S;
trace(To, Pid, Msg, S = #s{trace = Lines, now = Now}) ->
    Line = io_lib:format("~b ~ts ~ts~n", [Now, name(To, Pid), line(Msg)]),
    S#s{trace = [Line | Lines]}.

name({Reg, _Node}, _Pid) -> atom_to_list(Reg);
name(Reg, _Pid) when is_atom(Reg) -> atom_to_list(Reg);
name(_To, Pid) when is_pid(Pid) ->
    case erlang:process_info(Pid, registered_name) of
        {registered_name, Reg} -> atom_to_list(Reg);
        _ -> "-"
    end;
name(_To, _) ->
    "-".

line(?WIRE_EVENT({E, O}, Op)) -> io_lib:format("emit ~s.~s ~ts", [E, O, op(Op)]);
line(?WIRE_GATED({E, O}, Op)) -> io_lib:format("gated ~s.~s ~ts", [E, O, op(Op)]);
line(?WIRE_IN(I, V)) -> io_lib:format("deliver ~s ~0tp", [I, V]);
line(?WIRE_IN(I, V, _)) -> io_lib:format("deliver ~s ~0tp", [I, V]);
line(?WIRE_ACK(I)) -> io_lib:format("ack ~s", [I]);
line(?WIRE_TIMER(Kind, Msg)) -> io_lib:format("timer ~0tp ~0tp", [Kind, Msg]);
line({stimulus, Msg}) -> io_lib:format("stimulus ~0tp", [Msg]);
line(Msg) -> io_lib:format("~0tp", [strip(Msg)]).

op({send, V, Hold}) -> io_lib:format("send ~0tp ~0tp", [V, Hold]);
op({set, V}) -> io_lib:format("set ~0tp", [V]);
op(unset) -> "unset".

%% Pids are not the same from one run to the next: a line names none.
strip(T) when is_pid(T) -> pid;
strip(T) when is_reference(T) -> ref;
strip(T) when is_tuple(T) -> list_to_tuple([strip(E) || E <- tuple_to_list(T)]);
strip(T) when is_list(T) -> [strip(E) || E <- T];
strip(T) -> T.
