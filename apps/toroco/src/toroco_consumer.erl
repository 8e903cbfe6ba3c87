%% @doc The one process shell of the consumers of the event path: the
%% router of a wired input (`toroco_router') and the gate of an inhibited
%% output (`toroco_gate') are this gen_statem with a callback module each.
%%
%% The shell owns what both do the same way: the links to the upstreams
%% their sources come from (`toroco_wire'), the subscription handshake, the
%% one hold timer (`{timeout, hold}', moved only when the earliest deadline
%% changes), a new incarnation's hello, an upstream's death, and the calls
%% of the wiring server. The callback module owns its pure core and what
%% goes out: a router's deliveries to its receiver, a gate's forwarding to
%% its own subscribers. What every process of the event path does alike
%% (a lockstep step, the idle tick, the observer tap's batch, which a
%% callback taps into through `toroco_shell:tap/3', timeouts in simulated
%% time) is the shell's (`toroco_shell'). The callback module's `run/4', `settled/2' and
%% `deadline/1' are called through funs made at start (external funs: a
%% reload of the module takes effect at the next call).
%%
%% A consumer reads its configuration from the wiring table when it
%% (re)starts, and is handed the new one with the wiring server's `rewire'.
%% Re-wiring is asynchronous. On `rewire' (or at start) the shell subscribes
%% to the new upstreams and goes to state `syncing'; it keeps handling the
%% events of the sources it already had, and holds back (postpones) only
%% those of the sources being brought in, until every new upstream has
%% answered with its latch, or died, or `sync_timeout_ms' has passed. Then
%% the whole change enters the core at once, the wiring server's call is
%% answered, and the held-back events follow. Calls (the wiring server's
%% `rewire', `ready', `unwire', and inspection's `info') wait in the
%% mailbox meanwhile, so what they see has the change in.
%%
%% Remote sources (SPEC §13). A source whose upstream is on another node is
%% subscribed to again when no incarnation of it answers (it died, its node
%% is away, or it restarted and cannot know this consumer): at once when
%% the wiring server says its node is back, else with a backoff of 100 ms
%% doubling to 2 s, bounded to `resubscribe_tries' (30). Such a source is
%% also let go after `max_age' ms of silence (per wire, else app env
%% `remote_max_age_ms'): its holds end and its latch clears as if it had
%% died; the next word from it (an event, or the keep-alive with its latch)
%% takes it back.
-module(toroco_consumer).

-define(DOWN_WAIT_MS, 1000).
-behaviour(gen_statem).

-include("toroco_wire.hrl").

%% How the shell reaches this module's data and events (toroco_shell:host()):
%% external funs of a constant module, so the tuple is a literal.
-define(HOST, {fun ?MODULE:shell/1, fun ?MODULE:shell/2, fun ?MODULE:event/4}).

-export([start_link/3, rewire/4, ready/2, info/2, call/4]).
%% The shell's way into this module (toroco_shell:host()), not an API.
-export([shell/1, shell/2, event/4]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).
%% Steps of every event of the path, inlined: its calls are its cost.
-compile({inline, [settle/2, timer/1]}).

-type key() :: {atom(), atom()}.
-export_type([key/0]).
-type core_event() :: term().
-type kind_data() :: term().
-type shell() :: toroco_shell:shell().
%% What a kind does with an event of its own: core events to run, gen_statem
%% actions (a call's reply among them), its data and the shell.
-type handled() :: {[core_event()], [gen_statem:action()], kind_data(), shell()}.

%% The kind of consumer: `router' or `gate'.
-callback kind() -> router | gate.
%% Its registered name.
-callback reg(key()) -> atom().
%% Its data at start, from its configuration in the wiring table.
-callback init(key(), Cfg :: map()) -> kind_data().
%% One event into the core, and what comes out sent on. What it taps for
%% the observer it taps into the shell (`toroco_shell:tap/3'), which sends
%% it once the event is handled (toroco_tap:after_event/3).
-callback run(core_event(), Now :: integer(), kind_data(), shell()) -> {kind_data(), shell()}.
%% After a batch of events (a router reports its state to the tap here).
-callback settled(kind_data(), shell()) -> {kind_data(), shell()}.
%% The core's earliest hold deadline.
-callback deadline(kind_data()) -> infinity | integer().
%% A finished re-wiring, into the core at once.
-callback rewired(Cfg :: map(), Synced :: [{key(), toroco_router_core:latch()}],
                  Reset :: [key()], Now :: integer(), kind_data(), shell()) ->
    {kind_data(), shell()}.
%% The core events of an answer that came after the wait (or from the
%% caller of the wiring change).
-callback late(key(), toroco_router_core:latch() | inhibited) -> [core_event()].
%% Messages, calls (answered with a `reply' action) and timeouts of its
%% own, or `unknown'.
-callback handle(gen_statem:event_type(), term(), kind_data(), shell()) -> handled() | unknown.
%% The inspection view.
-callback info(Now :: integer(), kind_data()) -> term().

-record(c, {mod :: module(),
            key :: key(),
            data :: kind_data(),
            %% the kind's event path callbacks, made once at start: external
            %% funs, so a code reload of the kind takes effect at the next call
            run :: fun((core_event(), integer(), kind_data(), shell()) -> {kind_data(), shell()}),
            settled :: fun((kind_data(), shell()) -> {kind_data(), shell()}),
            deadline :: fun((kind_data()) -> infinity | integer()),
            %% lockstep, the idle tick, the tap's batch, the simulated hold timer
            shell :: toroco_shell:shell(),
            links = toroco_wire:new_links() :: toroco_wire:links(),
            timer = infinity :: infinity | integer(),
            %% remote sources: when each was last heard (monotonic ms), its
            %% max age, those let go as silent, and resubscription tries
            heard = #{} :: #{key() => integer()},
            ages = #{} :: #{key() => pos_integer()},
            stale = [] :: [key()],
            stale_at = infinity :: infinity | integer(),
            tries = 0 :: non_neg_integer(),
            sync = none :: none | {toroco_wire:sync(), gen_statem:from() | none, map()}}).

%%====================================================================
%% API
%%====================================================================

%% @doc Starts the consumer of `Key' run by `Mod'. `Caller' is the process
%% whose wiring call starts it (not waited for), or `none'.
-spec start_link(module(), key(), pid() | none) -> gen_statem:start_ret().
start_link(Mod, Key, Caller) ->
    gen_statem:start_link({local, Mod:reg(Key)}, ?MODULE, {Mod, Key, Caller},
                          toroco_wire:start_opts()).

%% @doc Takes configuration `Cfg' (the wiring server's, as it writes it to
%% the wiring table); returns once the change is in the core (every new
%% upstream answered, died, or was waited for `sync_timeout_ms').
-spec rewire(module(), key(), map(), pid() | none) -> ok | {error, term()}.
rewire(Mod, Key, Cfg, Caller) ->
    call(Mod, Key, {rewire, Cfg, Caller}, answer_timeout()).

%% @doc Returns once a just-started consumer has taken its sources in.
-spec ready(module(), key()) -> ok | {error, term()}.
ready(Mod, Key) ->
    call(Mod, Key, ready, answer_timeout()).

%% @doc The consumer's inspection view, or `none' if it is not running.
-spec info(module(), key()) -> term() | none.
info(Mod, Key) ->
    case call(Mod, Key, info, 1000) of
        {error, _} -> none;
        Info -> Info
    end.

%% @doc A call to the consumer; an error naming it if it is not there or
%% does not answer.
-spec call(module(), key(), term(), timeout()) -> term().
call(Mod, Key, Req, Timeout) ->
    toroco_wire:call(Mod:reg(Key), Req, Timeout, Key).

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init({module(), key(), pid() | none}) ->
          gen_statem:init_result(ready | syncing | gone).
init({Mod, Key, Caller}) ->
    process_flag(trap_exit, true),
    case toroco_wiring:lookup({Mod:kind(), Key}) of
        {ok, Cfg} ->
            ok = toroco_lockstep:up(Mod:reg(Key), consumer),
            C = #c{mod = Mod, key = Key, data = Mod:init(Key, Cfg), run = fun Mod:run/4,
                   settled = fun Mod:settled/2, deadline = fun Mod:deadline/1,
                   shell = toroco_shell:new()},
            {St, C1, Actions} = start_sync(Cfg, Caller, none, C),
            toroco_lockstep:ready(Mod:reg(Key)),
            {ok, St, C1, Actions};
        error ->
            %% Unwired while (re)starting: end at once, not to be restarted
            %% (`toroco_routers_sup').
            {ok, gone, none, [{next_event, internal, gone}]}
    end.

-spec handle_event(gen_statem:event_type(), term(), ready | syncing | gone, #c{} | none) ->
          gen_statem:event_handler_result(ready | syncing | gone).
%% Lockstep, the idle tick and the tap's batch are the shell's
%% (toroco_shell); the rest comes to event/4. In lockstep a death is handed
%% to toroco_lockstep, to come back as a step, and the deaths a step
%% caused are handed over before it is done.
handle_event(internal, gone, gone, none) ->
    {stop, normal};
handle_event(info, ?WIRE_EVENT(Src, Op) = Msg, ready, C = #c{heard = H, links = L, shell = Sh})
  when map_size(H) =:= 0 ->
    %% the event path's common case, as event/4 would take it, without
    %% the shell's dispatch (toroco_shell:awake/1)
    case toroco_shell:awake(Sh) andalso toroco_wire:carries(emitter, Src, L) of
        true -> toroco_shell:done(steps([{op, Src, Op}], C), C, ?HOST);
        false -> toroco_shell:handle_event(info, Msg, ready, C, ?HOST)
    end;
handle_event(info, {'DOWN', _, process, _, _} = Down, St, C) ->
    case toroco_lockstep:down(Down) of
        true -> keep_state_and_data;
        false -> toroco_shell:handle_event(info, Down, St, C, ?HOST)
    end;
handle_event(internal, ?WIRE_STEP_DONE(_) = Done, St, C) ->
    %% a monitor the step set on a process already gone has its DOWN here
    %% now: it is handed over before the step is done, not at a moment
    %% that depends on the schedulers
    hand_over_downs(),
    toroco_shell:handle_event(internal, Done, St, C, ?HOST);
handle_event(Type, Content, St, C) ->
    toroco_shell:handle_event(Type, Content, St, C, ?HOST).

%% @private
-spec shell(#c{}) -> toroco_shell:shell().
shell(#c{shell = Sh}) -> Sh.

%% @private
-spec shell(toroco_shell:shell(), #c{}) -> #c{}.
shell(Sh, C) -> C#c{shell = Sh}.

%% @private Every event the shell does not handle itself.
-spec event(gen_statem:event_type(), term(), ready | syncing | gone, #c{}) ->
          gen_statem:event_handler_result(ready | syncing | gone).

%% The event path, and the remote sources' keep-alives and timers.
event(info, ?WIRE_EVENT(Src, Op), St, C) ->
    path(emitter, Src, Op, St, C);
event(info, ?WIRE_GATED(Src, Op), St, C) ->
    path(gate, Src, Op, St, C);
event({timeout, hold}, expire, _, C) ->
    steps([tick], C#c{timer = infinity});
event(info, ?WIRE_ALIVE(Tag, Src, Latch), _, C) ->
    alive(Tag, Src, Latch, C);
event({timeout, stale}, check, _, C) ->
    silent(C#c{stale_at = infinity});
event({timeout, resub}, again, _, C) ->
    resubscribe(C);
event(info, ?WIRE_RESUBSCRIBE, _, C) ->
    resubscribe(C#c{tries = 0});
%% Upstreams: answers, new incarnations, deaths.
event(info, ?WIRE_STATE(Tag, Src, Pid, Latch), St, C) ->
    state(Tag, Src, Pid, Latch, St, C);
event(info, ?WIRE_HELLO(Tag, Src, Pid), St, C) ->
    hello(Tag, Src, Pid, St, C);
event(info, {'DOWN', _, process, _, _} = Down, _, C) ->
    down(Down, C);
event({timeout, sync}, expire, syncing, C = #c{sync = {Sync, From, Cfg}}) ->
    {ready, C1, Actions} = finish(C#c{sync = {toroco_wire:sync_expire(Sync), From, Cfg}}),
    {next_state, ready, C1, Actions};
%% The wiring server, and inspection.
event({call, From}, Req, St, C) ->
    called(Req, From, St, C);
%% The observer tap, and whatever is the kind's own.
event(Type, Content, _, C) ->
    kind(Type, Content, C).

%% An event of a source: a remote one is heard.
path(Tag, Src, Op, St, C = #c{heard = H}) when map_size(H) =:= 0 ->
    op(Tag, Src, Op, St, C);
path(Tag, Src, Op, St, C) ->
    with_heard(Src, fun(C1) -> op(Tag, Src, Op, St, C1) end, C).

alive(Tag, Src, Latch, C = #c{links = L, stale = Stale, mod = Mod}) ->
    case toroco_wire:carries(Tag, Src, L) andalso lists:member(Src, Stale) of
        %% Heard again after its silence: its latch comes back.
        true -> with_heard(Src, fun(C1) -> steps(Mod:late(Src, Latch), C1) end, C);
        false -> {keep_state, heard(Src, C)}
    end.

state(Tag, Src, Pid, Latch, St, C = #c{sync = {Sync, From, Cfg}}) ->
    case toroco_wire:sync_answer(Tag, Src, Pid, Latch, Sync) of
        {ok, Sync1} ->
            maybe_finish(C#c{sync = {Sync1, From, Cfg}});
        ignore ->
            %% The caller of the wiring change answers when it can; its
            %% source is not in the links until the change is applied.
            case toroco_wire:sync_fresh(Tag, Src, Sync) of
                true -> {keep_state_and_data, [postpone]};
                false -> late(Tag, Src, Pid, Latch, St, C)
            end
    end;
state(Tag, Src, Pid, Latch, St, C) ->
    late(Tag, Src, Pid, Latch, St, C).

hello(Tag, Src, Pid, St, C = #c{links = L}) ->
    case St =:= syncing andalso toroco_wire:sync_fresh(Tag, Src, element(1, C#c.sync)) of
        true ->
            {keep_state_and_data, [postpone]};
        false ->
            case toroco_wire:hello(Tag, Src, Pid, L) of
                {ok, L1} -> steps([{op, Src, unset}], C#c{links = L1});
                ignore -> keep_state_and_data
            end
    end.

down({'DOWN', Ref, process, Pid, _} = Down, C = #c{links = L, sync = Sync}) ->
    case Sync =/= none andalso toroco_wire:sync_down(Ref, element(1, Sync)) of
        {ok, Sync1} ->
            maybe_finish(C#c{sync = setelement(1, Sync, Sync1)});
        _ ->
            case toroco_wire:down(Ref, Pid, L) of
                %% An emitter's (or gate's) death ends its holds and clears
                %% its latches.
                {Srcs, L1} ->
                    remote(steps([{op, S, unset} || S <- Srcs], C#c{links = L1}));
                ignore -> kind(info, Down, C)
            end
    end.

%% Answered once the change is in (a consumer that just restarted answers
%% with its sources' state recovered); the kind's own calls too.
called(_Req, _From, syncing, _C) ->
    {keep_state_and_data, [postpone]};
called(info, From, ready, #c{mod = Mod, data = D}) ->
    {keep_state_and_data, [{reply, From, Mod:info(toroco_clock:now_ms(), D)}]};
called({rewire, Cfg, Caller}, From, ready, C) ->
    case start_sync(Cfg, Caller, From, C) of
        {syncing, C1, Actions} -> {next_state, syncing, C1, Actions};
        {ready, C1, Actions} -> {keep_state, C1, Actions}
    end;
called(ready, From, ready, _C) ->
    {keep_state_and_data, [{reply, From, ok}]};
called(Req, From, _St, C) ->
    kind({call, From}, Req, C).

hand_over_downs() ->
    {monitors, Mons} = erlang:process_info(self(), monitors),
    await_downs([P || {process, P} <- Mons, is_pid(P), node(P) =:= node(),
                      not is_process_alive(P)]),
    flush_downs().

%% A monitor on a process that is exiting gets its DOWN once the exit is
%% done: waited for (it comes), so that it is handed over now.
await_downs([]) ->
    ok;
await_downs([Pid | Pids]) ->
    receive
        {'DOWN', _, process, Pid, _} = Down ->
            true = toroco_lockstep:down(Down),
            await_downs(Pids)
    after ?DOWN_WAIT_MS ->
            await_downs(Pids)
    end.

flush_downs() ->
    receive
        {'DOWN', _, process, _, _} = Down ->
            true = toroco_lockstep:down(Down),
            flush_downs()
    after 0 ->
            ok
    end.

-spec terminate(term(), ready | syncing | gone, #c{} | none) -> ok.
terminate(_Reason, gone, none) ->
    ok;
terminate(_Reason, _, C = #c{links = L, shell = Sh}) ->
    _ = toroco_shell:flush(Sh),
    toroco_wire:detach_all(L, me(C)).

%%====================================================================
%% Events
%%====================================================================

op(Tag, Src, Op, St, C = #c{links = L, sync = Sync}) ->
    case toroco_wire:carries(Tag, Src, L) of
        true -> steps([{op, Src, Op}], C);
        false when St =:= syncing ->
            %% A source being brought in: its events wait for the change.
            case toroco_wire:sync_fresh(Tag, Src, element(1, Sync)) of
                true -> {keep_state_and_data, [postpone]};
                false -> keep_state_and_data
            end;
        false -> keep_state_and_data
    end.

late(Tag, Src, Pid, Latch, _St, C = #c{links = L, mod = Mod}) ->
    case toroco_wire:late_state(Tag, Src, Pid, L) of
        {ok, L1} ->
            C1 = C#c{links = L1, stale = lists:delete(Src, C#c.stale)},
            remote(steps(Mod:late(Src, Latch), C1));
        ignore -> keep_state_and_data
    end.

kind(Type, Content, C = #c{mod = Mod, data = D, shell = Sh}) ->
    case Mod:handle(Type, Content, D, Sh) of
        {Events, [], D1, Sh1} -> steps(Events, C#c{data = D1, shell = Sh1});
        {Events, Actions, D1, Sh1} ->
            add_actions(Actions, steps(Events, C#c{data = D1, shell = Sh1}));
        unknown ->
            logger:warning("toroco: ~p ~p: unexpected ~p event ~p",
                           [Mod:kind(), C#c.key, Type, Content], #{domain => [toroco, wire]}),
            keep_state_and_data
    end.

steps([Event], C = #c{run = Run, data = D0, shell = Sh}) ->
    %% the event path: one event at a time
    settle(Run(Event, toroco_clock:now_ms(), D0, Sh), C);
steps(Events, C = #c{run = Run, data = D0, shell = Sh}) ->
    Now = toroco_clock:now_ms(),
    settle(lists:foldl(fun(E, {D, Sh1}) -> Run(E, Now, D, Sh1) end, {D0, Sh}, Events), C).

settle({D0, Sh0}, C = #c{settled = Settled}) ->
    {D, Sh} = Settled(D0, Sh0),
    case timer(C#c{data = D, shell = Sh}) of
        {C1, []} -> {keep_state, C1};
        {C1, Actions} -> {keep_state, C1, Actions}
    end.

timer(C = #c{deadline = Deadline, data = D, timer = T, shell = Sh}) ->
    {T1, Actions, Sh1} = toroco_shell:hold(Deadline(D), T, Sh),
    {C#c{timer = T1, shell = Sh1}, Actions}.

add_actions(More, {keep_state, C}) -> {keep_state, C, More};
add_actions(More, {keep_state, C, Actions}) -> {keep_state, C, More ++ Actions}.

%%====================================================================
%% Re-wiring
%%====================================================================

start_sync(Cfg = #{upstreams := Ups}, Caller, From, C = #c{links = L}) ->
    {L1, Sync} = toroco_wire:start_sync(Ups, L, me(C), Caller),
    C1 = C#c{links = L1, sync = {Sync, From, Cfg}},
    case toroco_wire:sync_done(Sync) of
        true -> finish(C1);
        false -> {syncing, C1, [{{timeout, sync}, sync_timeout(), expire}]}
    end.

maybe_finish(C = #c{sync = {Sync, _, _}}) ->
    case toroco_wire:sync_done(Sync) of
        true ->
            {ready, C1, Actions} = finish(C),
            {next_state, ready, C1, Actions};
        false ->
            {keep_state, C}
    end.

%% The whole change enters the core at once; the wiring server's call is
%% answered; postponed events follow (leaving `syncing' replays them).
finish(C = #c{sync = {Sync, From, Cfg}, links = L, mod = Mod, data = D, shell = Sh}) ->
    {L1, Synced, Reset} = toroco_wire:finish_sync(Sync, L),
    {D1, Sh1} = Mod:rewired(Cfg, Synced, Reset, toroco_clock:now_ms(), D, Sh),
    {D2, Sh2} = (C#c.settled)(D1, Sh1),
    {C1, Actions} = timer(C#c{links = L1, data = D2, sync = none, shell = Sh2,
                              ages = ages(Cfg), stale = C#c.stale -- Reset}),
    Reply = case From of
                none -> [];
                _ -> [{reply, From, ok}]
            end,
    {C2, More} = track(C1),
    {ready, C2, [{{timeout, sync}, cancel} | Reply ++ Actions ++ More]}.

%% A consumer answers once its own wait is over, so the wiring server waits
%% a little longer than that, and never forever.
answer_timeout() ->
    sync_timeout() + 5000.

%% The consumer's own address, as its upstreams know it.
me(#c{mod = Mod, key = Key}) ->
    toroco_wire:address(Mod:reg(Key)).

%%====================================================================
%% Remote sources
%%====================================================================

ages(Cfg) -> maps:get(max_age, Cfg, #{}).

%% A word from a remote source: one that was let go as silent comes back.
with_heard(Src, Fun, C = #c{stale = Stale}) ->
    case lists:member(Src, Stale) of
        false -> Fun(heard(Src, C));
        true ->
            case Fun(heard(Src, C#c{stale = lists:delete(Src, Stale)})) of
                {keep_state, _} = R -> remote(R);
                {keep_state, _, _} = R -> remote(R);
                R -> R
            end
    end.

heard(Src, C = #c{heard = H}) ->
    case H of
        #{Src := _} -> C#c{heard = H#{Src := heard_now()}};
        #{} -> C
    end.

heard_now() -> toroco_clock:link_ms().

%% Adds the timers of remote sources to a handler's result.
remote({keep_state, C}) -> remote({keep_state, C, []});
remote({keep_state, C, Actions}) ->
    {C1, More} = track(C),
    {keep_state, C1, Actions ++ More}.

%% Which remote sources are listened to (their silence is timed) and which
%% are orphans (subscribed to again); the timers that follow.
track(C = #c{links = L, heard = H, tries = Tries}) ->
    Listened = [S || S <- remote_sources(L), not lists:member(S, toroco_wire:orphans(L))],
    Now = heard_now(),
    H1 = maps:from_list([{S, maps:get(S, H, Now)} || S <- Listened]),
    C1 = C#c{heard = H1},
    {C2, Resub} = case toroco_wire:orphans(L) of
                      [] -> {C1#c{tries = 0}, toroco_clock:link_timer({timeout, resub}, cancel, again)};
                      _ when Tries =:= 0 -> {C1, toroco_clock:link_timer({timeout, resub}, 100, again)};
                      _ -> {C1, []}
                  end,
    {C3, Stale} = stale_timer(C2),
    {C3, Resub ++ Stale}.

remote_sources(#{ups := Ups}) ->
    [S || {S, {_, {_, _}}} <- maps:to_list(Ups)].

stale_timer(C = #c{heard = H, ages = Ages, stale = Stale, stale_at = Old}) ->
    Due = [T + maps:get(S, Ages, toroco_wire:max_age_ms()) || {S, T} <- maps:to_list(H),
                                                              not lists:member(S, Stale)],
    case Due of
        [] when Old =:= infinity -> {C, []};
        [] -> {C#c{stale_at = infinity}, toroco_clock:link_timer({timeout, stale}, cancel, check)};
        _ ->
            At = lists:min(Due),
            case At of
                Old -> {C, []};
                _ -> {C#c{stale_at = At}, toroco_clock:link_timer({timeout, stale}, {at, At}, check)}
            end
    end.

%% The silence timer fired: sources silent for their max age are let go.
silent(C = #c{heard = H, ages = Ages, stale = Stale}) ->
    Now = heard_now(),
    Gone = [S || {S, T} <- maps:to_list(H), not lists:member(S, Stale),
                 Now >= T + maps:get(S, Ages, toroco_wire:max_age_ms())],
    _ = Gone =/= [] andalso
        logger:notice("toroco: ~p ~p let go of silent remote sources ~p",
                      [(C#c.mod):kind(), C#c.key, Gone], #{domain => [toroco, wire]}),
    remote(steps([{op, S, unset} || S <- Gone], C#c{stale = Stale ++ Gone})).

resubscribe(C = #c{links = L, tries = Tries}) ->
    case toroco_wire:orphans(L) of
        [] ->
            {keep_state, C#c{tries = 0}};
        Orphans ->
            toroco_wire:resubscribe(Orphans, L, me(C)),
            case Tries < resubscribe_tries() of
                true ->
                    Backoff = min(2000, 100 bsl min(Tries, 5)),
                    {keep_state, C#c{tries = Tries + 1},
                     toroco_clock:link_timer({timeout, resub}, Backoff, again)};
                false ->
                    {keep_state, C}
            end
    end.

resubscribe_tries() ->
    application:get_env(toroco, resubscribe_tries, 30).

sync_timeout() ->
    application:get_env(toroco, sync_timeout_ms, 5000).
