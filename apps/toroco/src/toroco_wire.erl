%% @doc The protocol of the event path: how emitters, gates, routers and
%% receivers talk, written down once. The messages themselves are the
%% macros of `toroco_wire.hrl'; this module holds the consumers' side of the
%% subscription handshake (their links to upstreams) and the one send
%% primitive. Everything is a plain asynchronous message, processes are
%% addressed as `{RegisteredName, Node}' or by pid, and every process that
%% waits for another monitors it, so nothing here assumes one node.
%%
%% An <em>upstream</em> is the process a source's events come from: the
%% emitter, or the gate of an inhibited output. A <em>consumer</em> is a
%% router or a gate (a gate is both). A consumer waiting for answers keeps
%% serving everything else (see `toroco_consumer').
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>`WIRE_SUB(Src, Consumer)'</td><td>consumer → upstream</td>
%%     <td>wiring attaches the consumer to Src</td>
%%     <td>`WIRE_STATE', in the same step as the consumer joins Src's
%%         subscribers, so nothing is lost or repeated</td></tr>
%% <tr><td>`WIRE_STATE(Kind, Src, Pid, Latch)'</td><td>upstream → consumer</td>
%%     <td>answer to `WIRE_SUB'; `Latch' is `{value, V}', `none', or
%%         `inhibited' from a gate holding Src back</td><td>none</td></tr>
%% <tr><td>`WIRE_UNSUB(Src, Consumer)'</td><td>consumer → upstream</td>
%%     <td>Src leaves the consumer's wiring, or the consumer stops</td><td>none</td></tr>
%% <tr><td>`WIRE_EVENT(Src, Op)'</td><td>emitter → consumers</td>
%%     <td>each emission (`{send, V, Hold}', `{set, V}', `unset')</td><td>none</td></tr>
%% <tr><td>`WIRE_GATED(Src, Op)'</td><td>gate → consumers</td>
%%     <td>an emission let through, an `unset' when Src becomes inhibited,
%%         its latch as a `set' when freed</td><td>none</td></tr>
%% <tr><td>`WIRE_HELLO(Kind, Src, Pid)'</td><td>upstream → consumers</td>
%%     <td>a new incarnation starts: nothing of the last one holds</td><td>none</td></tr>
%% <tr><td>`WIRE_ALIVE(Kind, Src, Latch)'</td><td>upstream → consumers on other nodes</td>
%%     <td>every `remote_keepalive_ms' (app env, default 100) while it has
%%         remote consumers; `Latch' as in `WIRE_STATE'</td>
%%     <td>none; a consumer that hears nothing of a remote source for its
%%         `max_age' lets it go (as if it had died), and takes its latch back
%%         from the next one</td></tr>
%% <tr><td>`WIRE_RX(Input, Pid)'</td><td>receiver → router</td>
%%     <td>the receiver (re)starts, resumes, or asks for a redelivery</td>
%%     <td>the router forgets the last value and delivers the winner's latch</td></tr>
%% <tr><td>`WIRE_IN(Input, V)' / `WIRE_IN(Input, V, Router)'</td><td>router → receiver</td>
%%     <td>a delivery (the second with `buffer => latest')</td>
%%     <td>`WIRE_ACK(Input)' for the second</td></tr>
%% <tr><td>`WIRE_ACK(Input)'</td><td>receiver → router</td>
%%     <td>a `latest' delivery was handled</td><td>the newest pending value, if any</td></tr>
%% <tr><td>`WIRE_IDLE'</td><td>a process → itself</td>
%%     <td>the idle tick (see `idle_arm/0')</td><td>none</td></tr>
%% <tr><td>`WIRE_TAP(Subs)'</td><td>`toroco_tap' → emitters, routers (the
%%     members of its `pg' group)</td>
%%     <td>observer subscriptions change</td><td>none</td></tr>
%% <tr><td>`WIRE_TAP_FLUSH(Feeder, Tag)'</td><td>a subscription's feeder
%%     (`toroco_tap_feeder') → emitters, routers</td>
%%     <td>a subscriber asks for every event emitted so far
%%         (`toroco_tap:sync/1')</td>
%%     <td>the process's tapped batch at once, then `FLUSHED' to the
%%         feeder (`toroco_tap:flushed/3')</td></tr>
%% <tr><td>`WIRE_RESUBSCRIBE'</td><td>wiring server → consumers</td>
%%     <td>a node of the robot came back</td>
%%     <td>the consumer subscribes again to its orphaned remote sources</td></tr>
%% <tr><td>`WIRE_STEP(Token, Msg)'</td><td>`toroco_lockstep' → any of the above</td>
%%     <td>lockstep (SPEC §14): one message of the path, a stimulus or a
%%         timer (`WIRE_TIMER(Kind, Msg)'), in its turn</td>
%%     <td>`toroco_lockstep:done(Token)' once it and the events it inserted
%%         (the last one `WIRE_STEP_DONE(Token)') are handled</td></tr>
%% <tr><td>`WIRE_BARRIER(Ref)'</td><td>`toroco_lockstep' → every process of
%%     the path</td><td>lockstep: an exit settles (SPEC §17)</td>
%%     <td>`toroco_lockstep:synced(Ref)' at once; a consumer in lockstep
%%         hands a `DOWN' to `toroco_lockstep:down/1', and acts on it when
%%         it comes back as a step</td></tr>
%% </table>
%%
%% The wiring server reaches consumers with calls (`toroco_consumer':
%% rewire, ready, unwire, info) whose answers are bounded by the consumer's
%% own wait for its upstreams (`sync_timeout_ms'); a consumer never waits
%% for the process whose wiring call it is serving (the caller's answer
%% arrives as soon as its callback returns).
-module(toroco_wire).

-include("toroco_wire.hrl").

-export([address/1, send/2, call/4, start_opts/0, keepalive_ms/0, max_age_ms/0, remote/1]).
-export([new_swallowed/0, swallowed/0]).
-export([idle_arm/0, idle_tick/1, step_done/2]).
-export([new_links/0, start_sync/4, sync_answer/5, sync_down/2, sync_expire/1, sync_done/1,
         sync_fresh/3, finish_sync/2, detach_all/2, hello/4, late_state/4, down/3, carries/3,
         orphans/1, resubscribe/3]).
-export_type([address/0, links/0, sync/0, upstream/0, idle/0]).

-type source() :: {atom(), atom()}.
%% Where a process is reached: its registered name on its node, or its pid.
-type address() :: {atom(), node()} | pid().
%% The idle tick: armed (with the process's reductions then), off (the
%% process hibernated; its next event arms it), or never.
-type idle() :: {armed, non_neg_integer()} | off | never.
-type upstream() :: {emitter | gate, atom() | {atom(), node()}}.
-type latch() :: toroco_router_core:latch().
%% What a consumer knows of its upstreams: where each source comes from, the
%% pid of the incarnation it currently listens to, and one monitor per pid.
-type links() :: #{ups := #{source() => upstream()},
                   pids := #{source() => pid()},
                   mons := #{pid() => reference()}}.
%% A re-wiring in progress: the new upstreams, the subscriptions still
%% waiting for an answer (with a monitor of the upstream each), and the
%% answers so far.
-opaque sync() :: #{ups := #{source() => upstream()},
                    old := #{source() => upstream()},
                    fresh := #{source() => upstream()},
                    pending := #{source() => reference()},
                    synced := [{source(), pid() | undefined, latch() | inhibited}]}.

%%====================================================================
%% Addresses and sends
%%====================================================================

%% @doc The address of a registered process: of this node, or already
%% addressed on another one (a remote upstream of the plan).
-spec address(atom() | {atom(), node()}) -> address().
address({Reg, Node}) -> {Reg, Node};
address(Reg) -> {Reg, node()}.

%% @doc Sends to an address; one that names no process (it is restarting or
%% gone), or a node that is not connected or whose connection is congested
%% (a frozen peer), swallows the message, as a cut wire would: the event
%% path never waits for another node.
%% In lockstep (`toroco_clock:lockstep/1') a send is handed to
%% `toroco_lockstep', which delivers it as a step in its turn (one to
%% another node too: in a world of several nodes it is a step there).
-spec send(address() | atom(), term()) -> ok.
send({Reg, Node} = To, Msg) when Node =:= node() ->
    %% the event path's common case: a plain send to a local name
    case persistent_term:get(toroco_lockstep, none) of
        none ->
            try Reg ! Msg of
                _ -> ok
            catch
                error:badarg -> ok
            end;
        Lockstep ->
            toroco_lockstep:send(Lockstep, To, Msg)
    end;
send(Pid, Msg) when is_pid(Pid), node(Pid) =:= node() ->
    case persistent_term:get(toroco_lockstep, none) of
        none -> Pid ! Msg, ok;
        Lockstep -> toroco_lockstep:send(Lockstep, Pid, Msg)
    end;
send(To, Msg) ->
    case persistent_term:get(toroco_lockstep, none) of
        none -> send_remote(To, Msg);
        %% a robot over several nodes in one lockstep world (SPEC §13, §17)
        Lockstep -> toroco_lockstep:send(Lockstep, To, Msg)
    end.

send_remote(To, Msg) ->
    try erlang:send(To, Msg, [noconnect, nosuspend]) of
        ok -> ok;
        nosuspend -> swallowed(1, congested, To);
        noconnect -> swallowed(2, not_connected, To)
    catch
        error:badarg -> ok
    end.

-define(SWALLOWED, toroco_wire_swallowed).

%% @doc Creates the node's counts of {@link swallowed/0} unless they exist
%% (they outlive a restart of the runtime: `toroco_store' calls this).
-spec new_swallowed() -> ok.
new_swallowed() ->
    case persistent_term:get(?SWALLOWED, none) of
        none -> persistent_term:put(?SWALLOWED, counters:new(2, [write_concurrency]));
        _ -> ok
    end.

%% @doc How many sends to another node were swallowed since this node
%% started: its connection `congested' (busy) or `not_connected'.
-spec swallowed() -> #{congested := non_neg_integer(), not_connected := non_neg_integer()}.
swallowed() ->
    case persistent_term:get(?SWALLOWED, none) of
        none -> #{congested => 0, not_connected => 0};
        C -> #{congested => counters:get(C, 1), not_connected => counters:get(C, 2)}
    end.

%% Counted, and logged at the 1st, 2nd, 4th, 8th, ... of each kind.
swallowed(I, Why, To) ->
    case persistent_term:get(?SWALLOWED, none) of
        none -> ok;
        C ->
            counters:add(C, I, 1),
            N = counters:get(C, I),
            _ = N band (N - 1) =:= 0 andalso
                logger:warning("~b sends to other nodes swallowed so far, the connection ~s "
                               "(the last to ~0p): the event path does not wait for another node",
                               [N, case Why of congested -> "congested"; not_connected -> "not up" end, To],
                               #{domain => [toroco, wire]}),
            ok
    end.

%% @doc A call to a process of the network, with a time limit; what goes
%% wrong comes back as an error naming `Name': `{not_running, Name}',
%% `{timeout, Name}', or the exit reason.
-spec call(atom() | address(), term(), timeout(), term()) -> term().
call(To, Req, Timeout, Name) ->
    try gen_statem:call(To, Req, Timeout)
    catch exit:{noproc, _} -> {error, {not_running, Name}};
          exit:{{nodedown, _}, _} -> {error, {not_running, Name}};
          exit:{timeout, _} -> {error, {timeout, Name}};
          exit:{Reason, _} -> {error, {Reason, Name}}
    end.

%%====================================================================
%% Links: a consumer's view of its upstreams
%%====================================================================

-spec new_links() -> links().
new_links() -> #{ups => #{}, pids => #{}, mons => #{}}.

%% @doc Starts moving the links to a new set of upstreams: unsubscribes from
%% the sources that left (or whose upstream changed) and subscribes to the
%% new ones, without waiting. `Caller' (the process whose wiring call this
%% is, or `none') is subscribed to but not waited for: it is busy in that
%% call, and its answer comes later as a late state.
-spec start_sync(#{source() => upstream()}, links(), address(), pid() | none) -> {links(), sync()}.
start_sync(NewUps, Links = #{ups := OldUps}, Me, Caller) ->
    Gone = [S || {S, Up} <- maps:to_list(OldUps), maps:get(S, NewUps, none) =/= Up],
    _ = [unsubscribe(S, maps:get(S, OldUps), Me) || S <- Gone],
    Fresh = maps:filter(fun(S, Up) -> maps:get(S, OldUps, none) =/= Up end, NewUps),
    Pending = maps:fold(
                fun(S, {_, Reg} = Up, Acc) ->
                        subscribe(S, Up, Me),
                        case is_atom(Reg) andalso whereis(Reg) of
                            Caller -> Acc;
                            _ -> Acc#{S => erlang:monitor(process, address(Reg))}
                        end
                end, #{}, Fresh),
    Links1 = lists:foldl(fun(S, Acc) -> forget(S, Acc) end,
                         Links#{ups := maps:without(Gone, OldUps)}, Gone),
    {Links1, #{ups => NewUps, old => OldUps, fresh => Fresh, pending => Pending, synced => []}}.

%% @doc An answer to a subscription; `ignore' if it is not one this sync
%% waits for.
-spec sync_answer(emitter | gate, source(), pid(), latch() | inhibited, sync()) ->
          {ok, sync()} | ignore.
sync_answer(Tag, Src, Pid, Latch, Sync = #{fresh := Fresh, pending := P, synced := Acc}) ->
    case {Fresh, P} of
        {#{Src := {Tag, _}}, #{Src := Mref}} ->
            erlang:demonitor(Mref, [flush]),
            {ok, Sync#{pending := maps:remove(Src, P), synced := [{Src, Pid, Latch} | Acc]}};
        _ ->
            ignore
    end.

%% @doc A waited-for upstream is not running: its source comes with no latch.
-spec sync_down(reference(), sync()) -> {ok, sync()} | ignore.
sync_down(Mref, Sync = #{pending := P, synced := Acc}) ->
    case [S || {S, M} <- maps:to_list(P), M =:= Mref] of
        [Src] -> {ok, Sync#{pending := maps:remove(Src, P), synced := [{Src, undefined, none} | Acc]}};
        [] -> ignore
    end.

%% @doc The wait is over: sources still unanswered come with no latch (an
%% answer that comes later is taken as a late state).
-spec sync_expire(sync()) -> sync().
sync_expire(Sync = #{pending := P, synced := Acc}) ->
    maps:foreach(fun(_, M) -> erlang:demonitor(M, [flush]) end, P),
    Sync#{pending := #{}, synced := Acc ++ [{S, undefined, none} || S <- maps:keys(P)]}.

-spec sync_done(sync()) -> boolean().
sync_done(#{pending := P}) -> map_size(P) =:= 0.

%% @doc Whether `Src' (tagged `Tag') is one this sync brings in: its events
%% wait until the sync is applied.
-spec sync_fresh(emitter | gate, source(), sync()) -> boolean().
sync_fresh(Tag, Src, #{fresh := Fresh}) ->
    case Fresh of
        #{Src := {Tag, _}} -> true;
        #{} -> false
    end.

%% @doc Applies a finished sync to the links: the synced latches, and the
%% sources whose state starts afresh (the new ones, and those that now come
%% through a gate that inhibits them). A source that only moved between its
%% emitter and a gate that lets it through keeps its hold.
-spec finish_sync(sync(), links()) -> {links(), [{source(), latch()}], [source()]}.
finish_sync(#{ups := NewUps, old := OldUps, synced := Synced}, Links) ->
    L1 = lists:foldl(fun({S, Pid, _}, Acc) when is_pid(Pid) -> listen(S, Pid, Acc);
                        (_, Acc) -> Acc
                     end, Links#{ups := NewUps}, Synced),
    Reset = [S || {S, _, Latch} <- Synced, Latch =:= inhibited orelse not maps:is_key(S, OldUps)],
    {L1, [{S, latch(Latch)} || {S, _, Latch} <- Synced], Reset}.

%% A gate answers `inhibited' for a member it holds back: no latch gets through.
latch(inhibited) -> none;
latch(Latch) -> Latch.

%% @doc Unsubscribes from every upstream (the consumer is going away).
-spec detach_all(links(), address()) -> ok.
detach_all(#{ups := Ups}, Me) ->
    maps:foreach(fun(S, Up) -> unsubscribe(S, Up, Me) end, Ups).

%% @doc A new incarnation of an upstream announced itself: listen to it. Its
%% source starts with no latch and no hold (the caller applies an `unset').
-spec hello(emitter | gate, source(), pid(), links()) -> {ok, links()} | ignore.
hello(Tag, Src, Pid, Links = #{ups := Ups}) ->
    case Ups of
        #{Src := {Tag, _}} -> {ok, listen(Src, Pid, Links)};
        #{} -> ignore
    end.

%% @doc An answer to a subscription that came after the wait gave up on it
%% (or from the caller of the wiring change, which was not waited for).
-spec late_state(emitter | gate, source(), pid(), links()) -> {ok, links()} | ignore.
late_state(Tag, Src, Pid, Links = #{ups := Ups, pids := Pids}) ->
    case {Ups, Pids} of
        {#{Src := {Tag, _}}, #{Src := _}} -> ignore;
        {#{Src := {Tag, _}}, #{}} -> {ok, listen(Src, Pid, Links)};
        _ -> ignore
    end.

%% @doc An upstream process died (monitor `Ref'): the sources it carried,
%% and the links without it; `ignore' if it is not a monitor of the links.
-spec down(reference(), pid(), links()) -> {[source()], links()} | ignore.
down(Ref, Pid, Links = #{pids := Pids, mons := Mons}) ->
    case Mons of
        #{Pid := Ref} ->
            Srcs = [S || {S, P} <- maps:to_list(Pids), P =:= Pid],
            {Srcs, Links#{pids := maps:without(Srcs, Pids), mons := maps:remove(Pid, Mons)}};
        #{} ->
            ignore
    end.

%% @doc Whether an event tagged `Tag' (`emitter' for `WIRE_EVENT', `gate'
%% for `WIRE_GATED') for `Src' is one this consumer listens to; while a
%% source moves between its emitter and a gate, events from the side it
%% left are ignored.
-spec carries(emitter | gate, source(), links()) -> boolean().
carries(Tag, Src, #{ups := Ups}) ->
    case Ups of
        #{Src := {Tag, _}} -> true;
        #{} -> false
    end.

%% @doc A step handled (lockstep, see `toroco_lockstep'): the result of
%% handling `WIRE_STEP(Token, Msg)' with, after its own actions, the
%% internal event that says so, so that the events it inserts are handled
%% first. A process that stops says so by its death.
-spec step_done(toroco_lockstep:token(), gen_statem:event_handler_result(term())) ->
          gen_statem:event_handler_result(term()).
step_done(Token, R) ->
    Done = {next_event, internal, ?WIRE_STEP_DONE(Token)},
    case R of
        {keep_state, D} -> {keep_state, D, [Done]};
        {keep_state, D, A} -> {keep_state, D, then(A, Done)};
        keep_state_and_data -> {keep_state_and_data, [Done]};
        {keep_state_and_data, A} -> {keep_state_and_data, then(A, Done)};
        {next_state, S, D} -> {next_state, S, D, [Done]};
        {next_state, S, D, A} -> {next_state, S, D, then(A, Done)};
        {repeat_state, D} -> {repeat_state, D, [Done]};
        {repeat_state, D, A} -> {repeat_state, D, then(A, Done)};
        repeat_state_and_data -> {repeat_state_and_data, [Done]};
        {repeat_state_and_data, A} -> {repeat_state_and_data, then(A, Done)};
        Stop -> Stop
    end.

then(A, Done) when is_list(A) -> A ++ [Done];
then(A, Done) -> [A, Done].

listen(Src, Pid, Links) ->
    L1 = #{pids := Pids, mons := Mons} = forget(Src, Links),
    Mons1 = case Mons of
                #{Pid := _} -> Mons;
                #{} -> Mons#{Pid => monitor_up(Pid)}
            end,
    L1#{pids := Pids#{Src => Pid}, mons := Mons1}.

%% A monitor of an upstream on another node is told to a lockstep world
%% over several nodes, which fires it as `noconnection' when it cuts that
%% node off (toroco_lockstep_nodes).
monitor_up(Pid) ->
    Ref = erlang:monitor(process, Pid),
    _ = node(Pid) =/= node() andalso toroco_lockstep:monitored(Pid, Ref),
    Ref.

demonitor_up(Pid, Ref) ->
    erlang:demonitor(Ref, [flush]),
    _ = node(Pid) =/= node() andalso toroco_lockstep:demonitored(Ref),
    ok.

%% Drops a source's pid, and the monitor of that pid if no other source uses it.
forget(Src, Links = #{pids := Pids, mons := Mons}) ->
    case Pids of
        #{Src := Pid} ->
            Pids1 = maps:remove(Src, Pids),
            case lists:member(Pid, maps:values(Pids1)) of
                true -> Links#{pids := Pids1};
                false ->
                    case Mons of
                        #{Pid := Ref} -> demonitor_up(Pid, Ref);
                        #{} -> ok
                    end,
                    Links#{pids := Pids1, mons := maps:remove(Pid, Mons)}
            end;
        #{} -> Links
    end.

%% A subscription may be the first message to another node: it connects.
%% In a lockstep world over several nodes one to another node is a step.
subscribe(Src, {_Tag, Up}, Me) ->
    case {persistent_term:get(toroco_lockstep, none), address(Up)} of
        {none, To} -> subscribe_now(To, ?WIRE_SUB(Src, Me));
        {_, {_, Node} = To} when Node =:= node() -> subscribe_now(To, ?WIRE_SUB(Src, Me));
        {Lockstep, To} -> toroco_lockstep:send(Lockstep, To, ?WIRE_SUB(Src, Me))
    end.

subscribe_now(To, Msg) ->
    try erlang:send(To, Msg, [nosuspend]) of
        _ -> ok
    catch
        error:badarg -> ok
    end.

%% @doc The sources of remote upstreams that this consumer hears from no
%% incarnation (it died, its node is away, or it never answered): they are
%% subscribed to again, since a remote upstream that restarts cannot know
%% this consumer from its own node's wiring.
-spec orphans(links()) -> [source()].
orphans(#{ups := Ups, pids := Pids}) ->
    [S || {S, {_, {_, _}}} <- maps:to_list(Ups), not maps:is_key(S, Pids)].

%% @doc Subscribes again to the upstreams of `Srcs' (answers come as late
%% states).
-spec resubscribe([source()], links(), address()) -> ok.
resubscribe(Srcs, #{ups := Ups}, Me) ->
    _ = [subscribe(S, maps:get(S, Ups), Me) || S <- Srcs],
    ok.

unsubscribe(Src, {_Tag, Up}, Me) ->
    send(address(Up), ?WIRE_UNSUB(Src, Me)).

%%====================================================================
%% Settings
%%====================================================================

%% @doc Start options of the network's processes (behaviors, devices,
%% routers, gates). No `hibernate_after': it would set a timer on every wait
%% for a message, that is on every event (about a fifth of the closed loop's
%% CPU); idleness is checked by the idle tick instead (`idle_arm/0').
-spec start_opts() -> [gen_statem:start_opt()].
start_opts() ->
    [].

%% @doc Arms the idle tick of the calling process (behaviors, devices,
%% routers, gates): `WIRE_IDLE' comes back after half of `hibernate_after_ms'
%% (app env, default 5000; `infinity' never), and `idle_tick/1' then tells
%% whether the process did anything since. One that did nothing hibernates
%% (so within `hibernate_after_ms' of its last event), which shrinks an idle
%% behavior with its router to a few kilobytes; its next event arms the tick
%% again. One that is busy, even at 1 Hz, never hibernates.
-spec idle_arm() -> idle().
idle_arm() ->
    case application:get_env(toroco, hibernate_after_ms, 5000) of
        infinity ->
            never;
        Ms ->
            _ = erlang:send_after(max(1, Ms div 2), self(), ?WIRE_IDLE),
            {armed, reductions()}
    end.

%% @doc At `WIRE_IDLE': the process did nothing since the tick was armed
%% (its reductions grew by no more than the tick's own): `[hibernate]' to
%% do, and the tick off; else the tick armed again.
-spec idle_tick(idle()) -> {idle(), [hibernate]}.
idle_tick({armed, R0}) ->
    case reductions() - R0 =< ?IDLE_REDUCTIONS of
        true -> {off, [hibernate]};
        false -> {idle_arm(), []}
    end;
idle_tick(Idle) ->
    {Idle, []}.

reductions() ->
    {reductions, R} = erlang:process_info(self(), reductions),
    R.

%% @doc How often an upstream tells its remote consumers it is alive.
-spec keepalive_ms() -> pos_integer().
keepalive_ms() ->
    application:get_env(toroco, remote_keepalive_ms, 100).

%% @doc How long a consumer waits on a silent remote source by default.
-spec max_age_ms() -> pos_integer().
max_age_ms() ->
    application:get_env(toroco, remote_max_age_ms, 300).

%% @doc Whether an address is on another node.
-spec remote(address()) -> boolean().
remote({_, Node}) -> Node =/= node();
remote(Pid) when is_pid(Pid) -> node(Pid) =/= node().
