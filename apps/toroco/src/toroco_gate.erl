%% @doc The inhibition gate of one inhibited output (or of a same-layer pair
%% of outputs that inhibit each other): the process shell around
%% `toroco_gate_core'.
%%
%% It lives under `toroco_routers_sup' beside the routers, registered as
%% `toroco_names:gate(SmallestMember)'. Upstream it is a consumer like a router:
%% it subscribes to its members' emitters and to its inhibitors' upstreams.
%% Downstream it is an upstream like an emitter: routers and other gates that
%% list a member subscribe to it and receive `{'$toroco_gate', Src, Op}'. While
%% a member is inhibited nothing of it goes downstream; becoming inhibited sends
%% an `unset' (its holds end everywhere), becoming free again re-sends its latch
%% as a fresh `set'.
-module(toroco_gate).
-behaviour(gen_statem).

-export([start_link/2, child_spec/2, rewire/2, info/1]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).

-record(g, {key :: {atom(), atom()},
            reg :: atom(),
            core = toroco_gate_core:new() :: toroco_gate_core:core(),
            links = toroco_upstream:new_links() :: toroco_upstream:links(),
            subs = #{} :: #{{atom(), atom()} => [atom() | pid()]},
            timer = infinity :: infinity | integer()}).

%%====================================================================
%% API
%%====================================================================

-spec start_link({atom(), atom()}, pid() | none) -> gen_statem:start_ret().
start_link(Key, Caller) ->
    gen_statem:start_link({local, toroco_names:gate(Key)}, ?MODULE, {Key, Caller},
                          toroco_upstream:start_opts()).

-spec child_spec({atom(), atom()}, pid() | none) -> supervisor:child_spec().
child_spec(Key, Caller) ->
    #{id => {gate, Key}, start => {?MODULE, start_link, [Key, Caller]},
      restart => permanent, shutdown => 1000, type => worker, modules => [?MODULE]}.

-spec rewire({atom(), atom()}, pid()) -> ok.
rewire(Key, Caller) ->
    gen_statem:call(toroco_names:gate(Key), {rewire, Caller}, infinity).

%% @doc Per member: inhibited, inhibitors, latch, inhibitor holds; `none' if the
%% gate is not running.
-spec info({atom(), atom()}) -> #{{atom(), atom()} => map()} | none.
info(Key) ->
    try gen_statem:call(toroco_names:gate(Key), info, 1000)
    catch exit:_ -> none
    end.

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init({{atom(), atom()}, pid() | none}) -> gen_statem:init_result(gating) | ignore.
init({Key, Caller}) ->
    process_flag(trap_exit, true),
    case toroco_wiring:lookup({gate, Key}) of
        {ok, Cfg = #{subs := Subs}} ->
            Reg = toroco_names:gate(Key),
            %% A restarted gate announces itself before anything else, so its
            %% subscribers listen to this incarnation from here on.
            maps:foreach(fun(M, Regs) ->
                                 [toroco_upstream:send(R, {'$toroco_hello', gate, M, self()})
                                  || R <- Regs]
                         end, Subs),
            {D, Actions} = configure(Cfg, Caller, #g{key = Key, reg = Reg}),
            {ok, gating, D, Actions};
        error ->
            ignore
    end.

-spec handle_event(gen_statem:event_type(), term(), gating, #g{}) ->
          gen_statem:event_handler_result(gating).
handle_event(info, {'$toroco', Src, Op}, _, D) ->
    op(emitter, Src, Op, D);
handle_event(info, {'$toroco_gate', Src, Op}, _, D) ->
    op(gate, Src, Op, D);
handle_event(info, {'$toroco_sub', Src, Reg}, _, D = #g{core = C, subs = Subs}) ->
    case lists:member(Src, toroco_gate_core:members(C)) of
        true ->
            State = case toroco_gate_core:is_inhibited(Src, C) of
                        true -> inhibited;
                        false -> toroco_gate_core:state_for(Src, C)
                    end,
            toroco_upstream:send(Reg, {'$toroco_state', gate, Src, self(), State}),
            Regs = lists:usort([Reg | maps:get(Src, Subs, [])]),
            {keep_state, D#g{subs = Subs#{Src => Regs}}};
        false ->
            toroco_upstream:send(Reg, {'$toroco_state', gate, Src, self(), none}),
            keep_state_and_data
    end;
handle_event(info, {'$toroco_unsub', Src, Reg}, _, D = #g{subs = Subs}) ->
    {keep_state, D#g{subs = Subs#{Src => lists:delete(Reg, maps:get(Src, Subs, []))}}};
handle_event({timeout, hold}, expire, _, D) ->
    step(tick, D#g{timer = infinity});
handle_event(info, {'$toroco_hello', Tag, Src, Pid}, _, D = #g{links = L}) ->
    case toroco_upstream:hello(Tag, Src, Pid, L) of
        {ok, L1} -> step({op, Src, unset}, D#g{links = L1});
        ignore -> keep_state_and_data
    end;
handle_event(info, {'$toroco_state', Tag, Src, Pid, Latch}, _, D = #g{links = L}) ->
    case {toroco_upstream:late_state(Tag, Src, Pid, Latch, L), Latch} of
        {{ok, L1}, {value, V}} -> step({op, Src, {set, V}}, D#g{links = L1});
        {{ok, L1}, _NoLatch} -> {keep_state, D#g{links = L1}};
        {ignore, _} -> keep_state_and_data
    end;
handle_event(info, {'DOWN', _, process, Pid, _}, _, D = #g{links = L}) ->
    {Srcs, L1} = toroco_upstream:down(Pid, L),
    steps([{op, S, unset} || S <- Srcs], D#g{links = L1});
handle_event({call, From}, {rewire, Caller}, _, D = #g{key = Key}) ->
    {ok, Cfg} = toroco_wiring:lookup({gate, Key}),
    {D1, Actions} = configure(Cfg, Caller, D),
    {keep_state, D1, [{reply, From, ok} | Actions]};
handle_event({call, From}, info, _, #g{core = C}) ->
    {keep_state_and_data, [{reply, From, toroco_gate_core:info(C, now_ms())}]};
handle_event(Type, Content, _, #g{reg = Reg}) ->
    logger:warning("gate ~p: unexpected ~p event ~p", [Reg, Type, Content]),
    keep_state_and_data.

-spec terminate(term(), gating, #g{}) -> ok.
terminate(_Reason, _, #g{links = L, reg = Reg}) ->
    toroco_upstream:detach_all(L, Reg).

%%====================================================================
%% Internals
%%====================================================================

configure(#{members := Members, entries := Entries, upstreams := Ups, subs := Subs}, Caller,
          D = #g{links = L, reg = Reg, subs = OldSubs}) ->
    {L1, Synced, Reset} = toroco_upstream:rewire(Ups, L, Reg, Caller),
    %% Keep subscribers that attached on their own; add the planned ones.
    Subs1 = maps:from_list([{M, lists:usort(maps:get(M, Subs, []) ++ maps:get(M, OldSubs, []))}
                            || M <- Members]),
    D1 = run({rewire, Members, Entries, Synced, Reset}, D#g{links = L1, subs = Subs1}),
    timer(D1).

op(Tag, Src, Op, D = #g{links = L}) ->
    case toroco_upstream:carries(Tag, Src, L) of
        true -> step({op, Src, Op}, D);
        false -> keep_state_and_data
    end.

step(Event, D) ->
    steps([Event], D).

steps(Events, D0) ->
    D = lists:foldl(fun run/2, D0, Events),
    case timer(D) of
        {D1, []} -> {keep_state, D1};
        {D1, Actions} -> {keep_state, D1, Actions}
    end.

run(Event, D = #g{core = C, subs = Subs}) ->
    {C1, Fwd} = toroco_gate_core:handle(Event, now_ms(), C),
    [toroco_upstream:send(R, {'$toroco_gate', M, Op}) || {M, Op} <- Fwd,
                                                          R <- maps:get(M, Subs, [])],
    D#g{core = C1}.

timer(D = #g{core = C, timer = T}) ->
    {T1, Actions} = toroco_upstream:hold_timer(toroco_gate_core:next_deadline(C), T),
    {D#g{timer = T1}, Actions}.

now_ms() -> toroco_clock:now_ms().
