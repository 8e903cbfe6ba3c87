%% @doc The router of one wired input: the process shell around
%% `toroco_router_core'.
%%
%% It lives under `toroco_routers_sup', registered as
%% `toroco_names:router(Receiver, Input)', and reads its configuration from the
%% wiring table, so a restarted router finds its place again: it re-subscribes
%% to its sources' upstreams, which hand over their latches, and re-delivers
%% the winner (emitters are the authority for their latches; timed holds in
%% flight are lost).
%%
%% Messages on the event path: `{'$toroco', Src, Op}' from emitters and
%% `{'$toroco_gate', Src, Op}' from gates in, `{'$toroco_in', Input, Value}'
%% (or `{'$toroco_in', Input, Value, Router}' with `buffer => latest', acked by
%% `{'$toroco_ack', Input}') out to the receiver. The one timer is the
%% gen_statem timeout `{timeout, hold}', set only when the earliest hold
%% deadline changes.
-module(toroco_router).
-behaviour(gen_statem).

-export([start_link/2, child_spec/2, rewire/2, unwire/1, info/1]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).

-record(r, {key :: {atom(), atom()},
            reg :: atom(),
            input :: atom(),
            core = toroco_router_core:new() :: toroco_router_core:core(),
            links = toroco_upstream:new_links() :: toroco_upstream:links(),
            rx :: pid() | undefined,
            rx_mon :: reference() | undefined,
            buffer = all :: all | latest,
            inflight = false :: boolean(),
            pending = none :: none | {value, term()},
            timer = infinity :: infinity | integer(),
            %% the observer tap's sinks about this input's receiver, and
            %% what it last reported of the router's state
            tap = #{} :: toroco_tap:sinks(),
            view = none :: term()}).

%%====================================================================
%% API
%%====================================================================

%% `Caller' is the process whose wiring call started the router (see
%% `toroco_upstream:rewire/4'), or `none'.
-spec start_link({atom(), atom()}, pid() | none) -> gen_statem:start_ret().
start_link(Key = {R, I}, Caller) ->
    gen_statem:start_link({local, toroco_names:router(R, I)}, ?MODULE, {Key, Caller},
                          toroco_upstream:start_opts()).

-spec child_spec({atom(), atom()}, pid() | none) -> supervisor:child_spec().
child_spec(Key, Caller) ->
    #{id => {router, Key}, start => {?MODULE, start_link, [Key, Caller]},
      restart => permanent, shutdown => 1000, type => worker, modules => [?MODULE]}.

%% @doc Takes the configuration now in the wiring table; returns once the new
%% sources' latches are in and the winner is delivered.
-spec rewire({atom(), atom()}, pid()) -> ok.
rewire({R, I}, Caller) ->
    gen_statem:call(toroco_names:router(R, I), {rewire, Caller}, infinity).

%% @doc The input is being unwired as a whole: drop every source (delivering
%% `idle' if one held) before the router is stopped.
-spec unwire({atom(), atom()}) -> ok.
unwire({R, I}) ->
    try gen_statem:call(toroco_names:router(R, I), unwire, 5000)
    catch exit:_ -> ok
    end.

%% @doc The inspection view of the input (SPEC §6), or `none' if the router is
%% not running.
-spec info({atom(), atom()}) -> map() | none.
info({R, I}) ->
    try gen_statem:call(toroco_names:router(R, I), info, 1000)
    catch exit:_ -> none
    end.

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init({{atom(), atom()}, pid() | none}) -> gen_statem:init_result(routing) | ignore.
init({Key = {R, I}, Caller}) ->
    process_flag(trap_exit, true),
    case toroco_wiring:lookup({router, Key}) of
        {ok, Cfg} ->
            D0 = #r{key = Key, reg = toroco_names:router(R, I), input = I,
                    tap = tap(toroco_tap:current(), R)},
            D1 = case whereis(toroco_names:process(R)) of
                     undefined -> D0;
                     Pid -> attach_receiver(Pid, D0)
                 end,
            {D2, Actions} = configure(Cfg, Caller, D1),
            {ok, routing, D2, Actions};
        error ->
            ignore
    end.

-spec handle_event(gen_statem:event_type(), term(), routing, #r{}) ->
          gen_statem:event_handler_result(routing).
handle_event(info, {'$toroco', Src, Op}, _, D) ->
    op(emitter, Src, Op, D);
handle_event(info, {'$toroco_tap', Subs}, _, D = #r{key = {R, _}}) ->
    {keep_state, D#r{tap = tap(Subs, R), view = none}};
handle_event(info, {'$toroco_gate', Src, Op}, _, D) ->
    op(gate, Src, Op, D);
handle_event(info, {'$toroco_ack', _Input}, _, D = #r{pending = {value, V}, rx = Rx})
  when is_pid(Rx) ->
    Rx ! {'$toroco_in', D#r.input, V, self()},
    delivered(D, V),
    {keep_state, D#r{pending = none}};
handle_event(info, {'$toroco_ack', _Input}, _, D) ->
    {keep_state, D#r{inflight = false}};
handle_event({timeout, hold}, expire, _, D) ->
    step(tick, D#r{timer = infinity});
handle_event(info, {'$toroco_rx', _Input, Pid}, _, D) ->
    step(receiver_up, attach_receiver(Pid, D));
handle_event(info, {'$toroco_hello', Tag, Src, Pid}, _, D = #r{links = L}) ->
    case toroco_upstream:hello(Tag, Src, Pid, L) of
        {ok, L1} -> step({op, Src, unset}, D#r{links = L1});
        ignore -> keep_state_and_data
    end;
handle_event(info, {'$toroco_state', Tag, Src, Pid, Latch}, _, D = #r{links = L}) ->
    case toroco_upstream:late_state(Tag, Src, Pid, Latch, L) of
        {ok, L1} when Latch =:= inhibited -> {keep_state, D#r{links = L1}};
        {ok, L1} -> step({sync, [{Src, Latch}]}, D#r{links = L1});
        ignore -> keep_state_and_data
    end;
handle_event(info, {'DOWN', Ref, process, _, _}, _, D = #r{rx_mon = Ref}) ->
    {keep_state, D#r{rx = undefined, rx_mon = undefined, inflight = false, pending = none}};
handle_event(info, {'DOWN', _, process, Pid, _}, _, D = #r{links = L}) ->
    %% An emitter's (or gate's) death ends its holds and clears its latches.
    {Srcs, L1} = toroco_upstream:down(Pid, L),
    steps([{op, S, unset} || S <- Srcs], D#r{links = L1});
handle_event({call, From}, {rewire, Caller}, _, D = #r{key = Key}) ->
    {ok, Cfg} = toroco_wiring:lookup({router, Key}),
    {D1, Actions} = configure(Cfg, Caller, D),
    {keep_state, D1, [{reply, From, ok} | Actions]};
handle_event({call, From}, unwire, _, D) ->
    {D1, Actions} = timer(observed(run(unwire, D))),
    {keep_state, D1, [{reply, From, ok} | Actions]};
handle_event({call, From}, info, _, D = #r{core = C, buffer = B}) ->
    Info = toroco_router_core:info(C, now_ms()),
    {keep_state_and_data, [{reply, From, Info#{buffer => B, receiver => D#r.rx}}]};
handle_event(info, {'$toroco_unsub', _, _}, _, _D) ->
    keep_state_and_data;
handle_event(Type, Content, _, #r{reg = Reg}) ->
    logger:warning("router ~p: unexpected ~p event ~p", [Reg, Type, Content]),
    keep_state_and_data.

-spec terminate(term(), routing, #r{}) -> ok.
terminate(_Reason, _, #r{links = L, reg = Reg}) ->
    toroco_upstream:detach_all(L, Reg).

%%====================================================================
%% Internals
%%====================================================================

configure(#{sources := Srcs, upstreams := Ups, buffer := B, idle := Idle}, Caller,
          D = #r{links = L, reg = Reg}) ->
    {L1, Synced, Reset} = toroco_upstream:rewire(Ups, L, Reg, Caller),
    D1 = D#r{links = L1, buffer = B},
    timer(observed(run({rewire, Srcs, #{idle => Idle}, Synced, Reset}, D1))).

op(Tag, Src, Op, D = #r{links = L}) ->
    case toroco_upstream:carries(Tag, Src, L) of
        true -> step({op, Src, Op}, D);
        false -> keep_state_and_data
    end.

step(Event, D) ->
    steps([Event], D).

steps(Events, D0) ->
    D = observed(lists:foldl(fun run/2, D0, Events)),
    case timer(D) of
        {D1, []} -> {keep_state, D1};
        {D1, Actions} -> {keep_state, D1, Actions}
    end.

%% Feeds one event to the core and delivers what comes out.
run(Event, D = #r{core = C}) ->
    {C1, Out} = toroco_router_core:handle(Event, now_ms(), C),
    deliver(Out, D#r{core = C1}).

%% Moves the one timer only if the earliest deadline changed.
timer(D = #r{core = C, timer = T}) ->
    {T1, Actions} = toroco_upstream:hold_timer(toroco_router_core:next_deadline(C), T),
    {D#r{timer = T1}, Actions}.

deliver([], D) ->
    D;
deliver(_Values, D = #r{rx = undefined}) ->
    D;                                          % receiver down: lost, as specified
deliver(Values, D = #r{buffer = all, rx = Rx, input = I}) ->
    _ = [begin Rx ! {'$toroco_in', I, V}, delivered(D, V) end || V <- Values],
    D;
deliver(Values, D = #r{buffer = latest, inflight = true}) ->
    D#r{pending = {value, lists:last(Values)}};
deliver(Values, D = #r{buffer = latest, rx = Rx, input = I}) ->
    V = lists:last(Values),
    Rx ! {'$toroco_in', I, V, self()},
    delivered(D, V),
    D#r{inflight = true}.

%% The observer tap: what the receiver got, and the router's state each time
%% its winner, holds or latches change.
tap(Subs, Receiver) ->
    toroco_tap:select(Subs, [deliver, router], Receiver).

delivered(#r{tap = #{deliver := Sinks}, key = Key}, V) ->
    toroco_tap:notify(Sinks, {deliver, toroco_tap:timestamp(), Key, V});
delivered(#r{}, _V) ->
    ok.

observed(D = #r{tap = #{router := Sinks}, core = C, view = Old, key = Key}) ->
    case toroco_router_core:view(C) of
        Old -> D;
        View ->
            Info = toroco_router_core:info(C, now_ms()),
            toroco_tap:notify(Sinks, {router, toroco_tap:timestamp(), Key,
                                      maps:with([winner, holds, latches], Info)}),
            D#r{view = View}
    end;
observed(D) ->
    D.

attach_receiver(Pid, D = #r{rx_mon = Old}) ->
    _ = Old =/= undefined andalso erlang:demonitor(Old, [flush]),
    D#r{rx = Pid, rx_mon = erlang:monitor(process, Pid), inflight = false, pending = none}.

now_ms() -> toroco_clock:now_ms().
