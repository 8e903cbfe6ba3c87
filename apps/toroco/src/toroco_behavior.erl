%% @doc Behaviors: the `toroco_behavior' callback contract, and the gen_statem
%% that runs a behavior (or a device) module.
%%
%% A behavior module declares its ports with `interface/0', starts with
%% `init/1' and reacts to inputs with `handle_input/4'; it emits by returning the
%% toroco actions `{send, #{Out => V}}', `{send, #{Out => V}, #{hold => H}}',
%% `{set, #{Out => V}}', `{unset, [Out]}' and `unset' among its gen_statem
%% actions (SPEC §4, §5). `{redeliver, [Input]}' asks those inputs' routers to
%% forget the last value delivered and deliver the current winner's latch
%% again (a device whose hardware came back uses it to catch up). The user's state is the gen_statem state, so
%% `state_timeout', `postpone' and the other gen_statem actions work as usual;
%% the user's data is kept inside this module's data.
%%
%% The process is the emitter end of every wire it feeds: it keeps, per output,
%% the registered names of the consumers (routers or a gate) to send to, and
%% the output's latch. Consumers subscribe with a handshake (see
%% `toroco_wire'), so the subscriber lists change without a central server
%% on the event path. On start it announces itself to its consumers (`hello':
%% nothing of the previous incarnation survives) and to its input routers
%% (which re-deliver each input's latched winner).
%%
%% Time: a callback module reads time only with `toroco_clock:now_ms/0' and
%% sets timers only with gen_statem's timeout actions (`state_timeout',
%% `{timeout, Name}', event timeouts, relative times): the engine turns them
%% into the runtime's clock, scaled by the simulated lab's speed, or kept by
%% `toroco_lockstep' in simulated time when a world is the clock (SPEC §14).
%% A module that reads the OS clock, calls `erlang:send_after' or sends
%% itself messages to time things cannot run in lockstep. Absolute timeouts
%% (`{abs, true}') stay in real time: they are for real hardware.
%%
%% Devices (`toroco_device') run on this same engine with `kind => device'.
-module(toroco_behavior).
-behaviour(gen_statem).

-include("toroco_wire.hrl").

-export([start_link/1, child_spec/1]).
-export([inject/3, info/1, suspend/1, resume/1, reset_behavior/1, interface/3, configured/1]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3, code_change/4]).
-export_type([spec/0, action/0, actions/0, result/0]).

-callback interface() -> #{inputs := [atom()], outputs := [atom()]}.
%% A behavior whose ports depend on its options exports `interface/1'
%% instead: it and `init/1' get the options of `toroco:add_behavior/3' but
%% `layer' (`params' among them), and any option is accepted. `open => true'
%% (a Lua behavior's) makes its ports open: see interface/3.
-callback interface(Opts :: map()) -> #{inputs := [atom()], outputs := [atom()],
                                          open => boolean()}.
%% `{error, Reason}' refuses to start: `add_behavior' answers
%% `{error, {start_failed, {Name, Reason}}}' (the library's bad parameters).
-callback init(Params :: map()) ->
    {ok, State :: term(), Data :: term()} |
    {ok, State :: term(), Data :: term(), Actions :: actions()} |
    {error, Reason :: term()}.
-callback handle_input(Input :: atom(), Value :: term(), State :: term(), Data :: term()) ->
    result().
-callback handle_event(gen_statem:event_type(), Content :: term(), State :: term(),
                       Data :: term()) ->
    result().
-callback code_change(OldVsn :: term(), State :: term(), Data :: term(), Extra :: term()) ->
    {ok, NewState :: term(), NewData :: term()}.
-callback terminate(Reason :: term(), State :: term(), Data :: term()) ->
    {emit, actions()} | term().
%% What `toroco:inspect(Name)' shows of the behavior's own workings, under
%% `behavior' (a Lua behavior's pending waits and triggers), as a device's
%% `info/2' under `device'. Called in the behavior's process.
-callback info(State :: term(), Data :: term()) -> map().
%% A behavior whose code is not the module's (a Lua file) re-reads it on
%% `toroco:reload(Name)'; called from the caller's process.
-callback reload(Name :: atom()) -> ok | {error, term()}.
-optional_callbacks([interface/0, interface/1, handle_event/4, code_change/4, terminate/3,
                     info/2, reload/1]).

-type action() :: {send, #{atom() => term()}}
                | {send, #{atom() => term()}, #{hold => non_neg_integer() | infinity}}
                | {set, #{atom() => term()}}
                | {unset, [atom()]}
                | unset
                | {redeliver, [atom()]}
                | gen_statem:action().
-type actions() :: [action()] | action().
%% What a callback returns: a gen_statem event handler result whose actions
%% may include the toroco actions.
-type result() :: {next_state, State :: term(), Data :: term()}
                | {next_state, State :: term(), Data :: term(), actions()}
                | {keep_state, Data :: term()}
                | {keep_state, Data :: term(), actions()}
                | keep_state_and_data
                | {keep_state_and_data, actions()}
                | {repeat_state, Data :: term()}
                | {repeat_state, Data :: term(), actions()}
                | repeat_state_and_data
                | {repeat_state_and_data, actions()}
                | {stop, Reason :: term()}
                | {stop, Reason :: term(), Data :: term()}
                | {stop_and_reply, Reason :: term(), [gen_statem:reply_action()] | gen_statem:reply_action()}
                | {stop_and_reply, Reason :: term(), [gen_statem:reply_action()] | gen_statem:reply_action(),
                   Data :: term()}.
-type spec() :: #{kind := behavior | device, name := atom(), module := module(),
                  layer := non_neg_integer(), args := term()}.

-define(RESET, '$reset').
-define(MAX_QUEUED, 1000).

-record(e, {name :: atom(),
            kind :: behavior | device,
            module :: module(),
            layer :: non_neg_integer(),
            args :: term(),
            user :: term(),
            %% declared output -> the addresses of its consumers
            outputs = #{} :: #{atom() => [toroco_wire:address()]},
            latches = #{} :: #{atom() => term()},
            inputs = [] :: [atom()],
            suspended = false :: boolean(),
            queued = [] :: [{gen_statem:event_type(), term()}],
            user_events = false :: boolean(),
            %% in lockstep, the timeouts set with toroco_lockstep and their
            %% simulated deadlines (gen_statem keeps none of them)
            vtimers = #{} :: #{term() => integer()},
            %% the observer tap's sinks that concern this process (SPEC §10)
            tap = #{} :: toroco_tap:sinks(),
            %% the tapped events not sent yet (toroco_tap:after_event/3)
            batch = [] :: toroco_tap:batch(),
            idle = off :: toroco_wire:idle(),
            %% names of the generic timeouts the callback module has set, so
            %% that a reset cancels them
            timers = [] :: [term()],
            %% emissions on undeclared outputs: when last logged, how many since
            undeclared = {never, 0} :: {never | integer(), non_neg_integer()},
            %% open ports (interface/1's `open'): an output comes into being
            %% when it is emitted on or subscribed to
            open = false :: boolean()}).

-define(LOG, #{domain => [toroco, engine]}).
-define(IS_TIMEOUT(K), (K =:= state_timeout orelse K =:= timeout orelse
                        (is_tuple(K) andalso tuple_size(K) =:= 2 andalso element(1, K) =:= timeout))).
-define(WARN_INTERVAL_MS, 1000).

%%====================================================================
%% API
%%====================================================================

-spec start_link(spec()) -> gen_statem:start_ret().
start_link(Spec = #{name := Name}) ->
    gen_statem:start_link({local, toroco_names:process(Name)}, ?MODULE, Spec, toroco_wire:start_opts()).

%% @doc Behaviors are `transient': one that stops with reason `normal' is done.
-spec child_spec(spec()) -> supervisor:child_spec().
child_spec(Spec = #{name := Name, kind := Kind}) ->
    #{id => Name, start => {?MODULE, start_link, [Spec]},
      restart => case Kind of behavior -> transient; device -> permanent end,
      shutdown => 2000, type => worker, modules => [?MODULE, maps:get(module, Spec)]}.

%% @doc The declared ports of a behavior (`Kind = behavior') or device module.
%% An interface with `open => true' (a Lua behavior's) has, besides those
%% it declares, every input its wiring names and every output its wiring
%% names or it emits on.
-spec interface(behavior | device, module(), term()) ->
          {ok, #{inputs := [atom()], outputs := [atom()], open => true}} | {error, term()}.
interface(Kind, Module, Args) ->
    try case Kind of
            behavior ->
                case configured(Module) of
                    true -> Module:interface(Args);
                    false -> Module:interface()
                end;
            device -> Module:interface(Args)
        end of
        #{inputs := Ins, outputs := Outs} = I when is_list(Ins), is_list(Outs) ->
            case lists:all(fun is_atom/1, Ins ++ Outs) of
                true when map_get(open, I) =:= true -> {ok, maps:with([inputs, outputs, open], I)};
                true -> {ok, maps:with([inputs, outputs], I)};
                false -> {error, {bad_interface, {Module, I}}}
            end;
        Other -> {error, {bad_interface, {Module, Other}}}
    catch
        error:undef -> {error, {bad_module, Module}};
        Class:Reason -> {error, {bad_interface, {Module, {Class, Reason}}}}
    end.

%% @doc Whether behavior module `Module' declares its ports from its options
%% (`interface/1') rather than once for all (`interface/0').
-spec configured(module()) -> boolean().
configured(Module) ->
    _ = code:ensure_loaded(Module),
    erlang:function_exported(Module, interface, 1)
        andalso not erlang:function_exported(Module, interface, 0).

%% @doc Makes the process emit `Op' on `Out' as if its callback had.
-spec inject(atom(), atom(), toroco_router_core:op()) -> ok | {error, term()}.
inject(Name, Out, Op) ->
    call(Name, {'$toroco_inject', Out, Op}).

%% @doc Status, latches and (for devices) the device's own counters.
-spec info(atom()) -> map() | {error, term()}.
info(Name) ->
    call(Name, '$toroco_info').

-spec suspend(atom()) -> ok | {error, term()}.
suspend(Name) -> call(Name, '$toroco_suspend').

-spec resume(atom()) -> ok | {error, term()}.
resume(Name) -> call(Name, '$toroco_resume').

%% @doc Brooks' reset of a running behavior (see `toroco:reset_behavior/1').
-spec reset_behavior(atom()) -> ok | {error, term()}.
reset_behavior(Name) -> call(Name, '$toroco_reset').

call(Name, Req) ->
    toroco_wire:call(toroco_names:process(Name), Req, 5000, Name).

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init(spec()) -> gen_statem:init_result(term()).
init(#{kind := Kind, name := Name, module := M, layer := Layer, args := Args}) ->
    process_flag(trap_exit, true),
    case interface(Kind, M, Args) of
        {ok, I = #{inputs := Ins0, outputs := Outs0}} ->
            ok = toroco_tap:join(),
            Planned = toroco_wiring:subs_of(Name),
            Open = maps:get(open, I, false),
            %% open ports: those the wiring named before this start too
            {Ins, Outs} = case Open of
                              true ->
                                  Wired = toroco_wiring:ports_of(Name),
                                  {lists:usort(Ins0 ++ maps:get(inputs, Wired, [])),
                                   lists:usort(Outs0 ++ maps:get(outputs, Wired, [])
                                               ++ maps:keys(Planned))};
                              false -> {Ins0, Outs0}
                          end,
            Subs = maps:from_list([{O, [toroco_wire:address(R) || R <- maps:get(O, Planned, [])]}
                                   || O <- Outs]),
            E = #e{name = Name, kind = Kind, module = M, layer = Layer, args = Args,
                   outputs = Subs, inputs = Ins, open = Open,
                   user_events = erlang:function_exported(M, handle_event, 4),
                   tap = tap(toroco_tap:current(), Name), idle = toroco_wire:idle_arm()},
            toroco_tap:lifecycle(E#e.tap, Name, toroco_restarts:started(Name)),
            ok = toroco_lockstep:up(Name, case Kind of
                                              behavior -> Layer;
                                              device -> none
                                          end),
            announce(E),
            case start_user(E) of
                {ok, S, E1} ->
                    toroco_lockstep:ready(Name),
                    {ok, S, E1#e{batch = toroco_tap:flush(E1#e.batch)}};
                {ok, S, E1, A} ->
                    toroco_lockstep:ready(Name),
                    {ok, S, E1#e{batch = toroco_tap:flush(E1#e.batch)}, A};
                Stop -> Stop
            end;
        {error, Reason} ->
            {stop, Reason}
    end.

%% Announces this incarnation: consumers drop whatever they had of the last
%% one; input routers re-deliver their latched winners.
announce(#e{name = Name, outputs = Outs, inputs = Ins, kind = Kind}) ->
    maps:foreach(fun(Out, Consumers) ->
                         [toroco_wire:send(C, ?WIRE_HELLO(emitter, {Name, Out}, self()))
                          || C <- Consumers]
                 end, Outs),
    receiver_up(Name, case Kind of behavior -> [?RESET | Ins]; device -> Ins end).

%% The inputs: declared, and for open ports those the wiring names now.
inputs(#e{inputs = Ins, open = false}) -> Ins;
inputs(#e{inputs = Ins, name = Name}) ->
    lists:usort(Ins ++ maps:get(inputs, toroco_wiring:ports_of(Name), [])).

receiver_up(Name, Inputs) ->
    [toroco_wire:send(toroco_wire:address(toroco_names:router(Name, I)), ?WIRE_RX(I, self()))
     || I <- Inputs],
    ok.

start_user(E = #e{kind = Kind, module = M, args = Args, name = Name}) ->
    try case Kind of
            behavior -> M:init(Args);
            device -> M:init(Name, Args)
        end of
        {ok, S, UD} ->
            {ok, S, E#e{user = UD}};
        {ok, S, UD, Actions} ->
            {Actions1, E1} = actions(Actions, E#e{user = UD}),
            {ok, S, E1, Actions1};
        {error, Reason} ->
            {stop, Reason};
        Other ->
            {stop, {bad_return_from_init, Other}}
    catch
        Class:Reason:Stack ->
            logger:error("toroco: ~p ~p crashed in init: ~p", [Kind, Name, {Class, Reason}],
                         ?LOG#{name => Name}),
            erlang:raise(Class, Reason, Stack)
    end.

-spec handle_event(gen_statem:event_type(), term(), term(), #e{}) ->
          gen_statem:event_handler_result(term()).
%% Every event, then what becomes of the observer tap's batch
%% (toroco_tap:after_event/3); a lockstep barrier is answered at once.
handle_event(info, ?WIRE_BARRIER(Ref), _S, _E) ->
    toroco_lockstep:synced(Ref),
    keep_state_and_data;
handle_event(Type, Content, S, E) ->
    tap_after(event(Type, Content, S, E), E).

%% Lockstep (toroco_lockstep): one message of the event path, or a timer,
%% handled as it would be in real time; the step is done once the events
%% it inserts are handled too.
event(info, ?WIRE_STEP(Token, Msg), S, E) ->
    toroco_wire:step_done(Token, step(Msg, S, E));
%% A step whose work is still out of the process (a Lua behavior's
%% activation, answered by a message): done once the callback module
%% leaves state `step_pending' (gen_statem retries a postponed event then).
event(internal, ?WIRE_STEP_DONE(_), step_pending, _E) ->
    {keep_state_and_data, [postpone]};
event(internal, ?WIRE_STEP_DONE(Token), _S, _E) ->
    toroco_lockstep:done(Token),
    keep_state_and_data;
%% The idle tick (toroco_wire:idle_arm/0), whatever the callback module's
%% state; the first event after hibernating arms it again.
event(info, ?WIRE_IDLE, _S, E = #e{idle = Idle}) ->
    {Idle1, Actions} = toroco_wire:idle_tick(Idle),
    {keep_state, E#e{idle = Idle1}, Actions};
event(Type, Content, S, E = #e{idle = off}) ->
    event(Type, Content, S, E#e{idle = toroco_wire:idle_arm()});
%% The observer tap's batch is due (toroco_tap:after_event/3).
event({timeout, '$toroco_tap'}, flush, _S, E = #e{batch = B}) ->
    {keep_state, E#e{batch = toroco_tap:flush(B)}};
%% The observer tap changed: keep the sinks that concern this process.
event(info, ?WIRE_TAP(Subs), _S, E = #e{name = Name}) ->
    {keep_state, E#e{tap = tap(Subs, Name)}};
%% A subscriber wants everything tapped so far (toroco_tap:sync/1).
event(info, ?WIRE_TAP_FLUSH(Feeder, Tag), _S, E = #e{batch = B}) ->
    {keep_state, E#e{batch = toroco_tap:flushed(Feeder, Tag, B)}};
%% The event path: one input delivered by a router.
event(info, ?WIRE_IN(Input, V), S, E = #e{suspended = false}) ->
    input(Input, V, S, E);
event(info, ?WIRE_IN(Input, V, Router), S, E = #e{suspended = false}) ->
    Result = input(Input, V, S, E),
    toroco_wire:send(Router, ?WIRE_ACK(Input)),
    Result;
event(info, ?WIRE_IN(_Input, _V), _S, _E) ->
    keep_state_and_data;                      % suspended: inputs are dropped
event(info, ?WIRE_IN(Input, _V, Router), _S, _E) ->
    toroco_wire:send(Router, ?WIRE_ACK(Input)),
    keep_state_and_data;
%% Wiring: consumers attach and detach (see toroco_wire).
event(info, ?WIRE_SUB({_, Out} = Src, Consumer), S, E = #e{outputs = Outs, open = true})
  when not is_map_key(Out, Outs) ->
    event(info, ?WIRE_SUB(Src, Consumer), S, E#e{outputs = Outs#{Out => []}});
event(info, ?WIRE_SUB({_, Out} = Src, Consumer), _S, E = #e{outputs = Outs}) ->
    case Outs of
        #{Out := Consumers} ->
            toroco_wire:send(Consumer, ?WIRE_STATE(emitter, Src, self(), latch(Out, E))),
            E1 = E#e{outputs = Outs#{Out := lists:usort([Consumer | Consumers])}},
            case toroco_wire:remote(Consumer) andalso not has_remote(E) of
                true -> {keep_state, E1, [alive_timer()]};
                false -> {keep_state, E1}
            end;
        #{} ->
            toroco_wire:send(Consumer, ?WIRE_STATE(emitter, Src, self(), none)),
            keep_state_and_data
    end;
event(info, ?WIRE_UNSUB({_, Out}, Consumer), _S, E = #e{outputs = Outs}) ->
    case Outs of
        #{Out := Consumers} ->
            {keep_state, E#e{outputs = Outs#{Out := lists:delete(Consumer, Consumers)}}};
        #{} -> keep_state_and_data
    end;
%% Consumers on other nodes hear from each output now and then, with its
%% latch, so they can tell a silent node from a quiet output (SPEC §13).
event({timeout, '$toroco_alive'}, beat, _S, E = #e{outputs = Outs, name = Name}) ->
    maps:foreach(fun(Out, Consumers) ->
                         Msg = ?WIRE_ALIVE(emitter, {Name, Out}, latch(Out, E)),
                         [toroco_wire:send(C, Msg) || C <- Consumers, toroco_wire:remote(C)]
                 end, Outs),
    case has_remote(E) of
        true -> {keep_state_and_data, [alive_timer()]};
        false -> keep_state_and_data
    end;
event({call, From}, {'$toroco_inject', Out, Op}, S, E = #e{outputs = Outs, open = true})
  when not is_map_key(Out, Outs), is_atom(Out) ->
    event({call, From}, {'$toroco_inject', Out, Op}, S, E#e{outputs = Outs#{Out => []}});
event({call, From}, {'$toroco_inject', Out, Op}, _S, E = #e{outputs = Outs, name = N}) ->
    case Outs of
        #{Out := _} -> {keep_state, emit(Out, Op, E), [{reply, From, ok}]};
        #{} -> {keep_state_and_data, [{reply, From, {error, {unknown_output, {N, Out}}}}]}
    end;
event({call, From}, '$toroco_reset', _S, E = #e{kind = behavior}) ->
    case reset(E) of
        {next_state, S1, E1, Actions} -> {next_state, S1, E1, [{reply, From, ok} | Actions]};
        {stop, Reason, E1} -> {stop_and_reply, Reason, [{reply, From, ok}], E1}
    end;
event({call, From}, '$toroco_info', S, E) ->
    {keep_state_and_data, [{reply, From, describe(S, E)}]};
event({call, From}, '$toroco_suspend', _S, E) ->
    {keep_state, lifecycle(suspended, E#e{suspended = true}), [{reply, From, ok}]};
event({call, From}, '$toroco_resume', _S, E = #e{suspended = false}) ->
    {keep_state, E, [{reply, From, ok}]};
event({call, From}, '$toroco_resume', _S, E = #e{name = Name, queued = Q}) ->
    %% Routers forget the last value and re-deliver each input's winner; the
    %% callbacks held back while suspended run now, in order.
    receiver_up(Name, inputs(E)),
    {keep_state, lifecycle(resumed, E#e{suspended = false, queued = []}),
     [{reply, From, ok} | [{next_event, T, C} || {T, C} <- lists:reverse(Q)]]};
%% Everything else belongs to the user module.
event(Type, Content, _S, E = #e{suspended = true, queued = Q, name = Name}) ->
    case length(Q) < ?MAX_QUEUED of
        true -> {keep_state, E#e{queued = [{Type, Content} | Q]}};
        false ->
            logger:warning("toroco: suspended ~p dropped ~p event ~p", [Name, Type, Content],
                           ?LOG#{name => Name}),
            keep_state_and_data
    end;
event(Type, Content, S, E = #e{user_events = true, module = M, user = UD}) ->
    %% A callback module's handle_event/4 with no clause for this event
    %% falls through to the engine's default below.
    try M:handle_event(Type, Content, S, UD) of
        R -> result(R, S, E)
    catch
        error:function_clause:Stack ->
            case Stack of
                [{M, handle_event, [Type, Content, S, UD], _} | _] -> default_event(Type, Content, E);
                _ -> erlang:raise(error, function_clause, Stack)
            end
    end;
event(Type, Content, _S, E) ->
    default_event(Type, Content, E).

%% What the engine does with an event nobody handles: a call is answered
%% with an error naming the process, anything else is logged and ignored.
default_event({call, From}, Request, #e{name = Name}) ->
    {keep_state_and_data, [{reply, From, {error, {unknown_call, {Name, Request}}}}]};
default_event(Type, Content, #e{name = Name}) ->
    logger:warning("toroco: ~p ignored ~p event ~p", [Name, Type, Content], ?LOG#{name => Name}),
    keep_state_and_data.

%% A user `terminate/3' may return `{emit, Actions}': its toroco actions are
%% carried out before the process goes (a device's last word, e.g. motors
%% reporting they stopped). Consumers drop the process's holds and latches
%% when it is gone, whatever it said last.
-spec terminate(term(), term(), #e{}) -> any().
terminate(Reason, S, E = #e{module = M, user = UD, name = Name}) ->
    case erlang:function_exported(M, terminate, 3) andalso M:terminate(Reason, S, UD) of
        {emit, Actions} -> {_, E1} = actions(Actions, E), toroco_tap:flush(E1#e.batch);
        _ -> toroco_tap:flush(E#e.batch)
    end,
    toroco_tap:lifecycle(E#e.tap, Name, stopped).

-spec code_change(term(), term(), #e{}, term()) -> {ok, term(), #e{}}.
code_change(OldVsn, S, E = #e{module = M, user = UD}, Extra) ->
    case erlang:function_exported(M, code_change, 4) of
        true ->
            {ok, S1, UD1} = M:code_change(OldVsn, S, UD, Extra),
            {ok, S1, E#e{user = UD1, user_events = erlang:function_exported(M, handle_event, 4)}};
        false ->
            {ok, S, E}
    end.

%%====================================================================
%% Inputs and results
%%====================================================================

input(?RESET, _V, _S, E) ->
    reset(E);
input(Input, V, S, E = #e{module = M, user = UD}) ->
    result(M:handle_input(Input, V, S, UD), S, E).

%% A step of lockstep: a simulated timer that is still set fires; any other
%% event ends an event timeout, as gen_statem's own would end.
step(?WIRE_TIMER(Kind, Msg), S, E = #e{vtimers = VT}) ->
    case VT of
        #{Kind := _} -> event(Kind, Msg, S, E#e{vtimers = maps:remove(Kind, VT)});
        #{} -> keep_state_and_data
    end;
step(Msg, S, E = #e{vtimers = #{timeout := _}}) ->
    {none, E1} = virtual({timeout, cancel}, E),
    event(info, Msg, S, E1);
step(Msg, S, E) ->
    event(info, Msg, S, E).

%% Brooks' reset: the behavior's latches and holds are cleared, then it starts
%% again from init/1 in the same process.
reset(E0 = #e{outputs = Outs}) ->
    E = lifecycle(reset, E0),
    E1 = lists:foldl(fun(Out, Acc) -> emit(Out, unset, Acc) end, E, maps:keys(Outs)),
    {Cancel, E1a} = actions([{state_timeout, cancel} | [{{timeout, T}, cancel} || T <- E1#e.timers]],
                            E1),
    case start_user(E1a#e{timers = []}) of
        {ok, S, E2} -> {next_state, S, E2, Cancel};
        {ok, S, E2, Actions} -> {next_state, S, E2, Cancel ++ Actions};
        {stop, Reason} -> {stop, Reason, E1}
    end.

result(R, S0, E) ->
    case R of
        {next_state, S, UD} -> {next_state, S, left(S0, S, E#e{user = UD})};
        {next_state, S, UD, A} -> with_actions(next_state, S, A, left(S0, S, E#e{user = UD}));
        {keep_state, UD} -> {keep_state, E#e{user = UD}};
        {keep_state, UD, A} -> with_actions(keep_state, A, E#e{user = UD});
        keep_state_and_data -> {keep_state, E};
        {keep_state_and_data, A} -> with_actions(keep_state, A, E);
        {repeat_state, UD} -> {repeat_state, E#e{user = UD}};
        {repeat_state, UD, A} -> with_actions(repeat_state, A, E#e{user = UD});
        repeat_state_and_data -> {repeat_state, E};
        {repeat_state_and_data, A} -> with_actions(repeat_state, A, E);
        {stop, Reason} -> {stop, Reason, E};
        {stop, Reason, UD} -> {stop, Reason, E#e{user = UD}};
        {stop_and_reply, Reason, Replies} -> {stop_and_reply, Reason, Replies, E};
        {stop_and_reply, Reason, Replies, UD} -> {stop_and_reply, Reason, Replies, E#e{user = UD}};
        Other -> {stop, {bad_return_from_callback, Other}, E}
    end.

%% Leaving a state ends its state timeout; gen_statem does it for its own,
%% the engine for a simulated one.
left(S, S, E) -> E;
left(_S0, _S, E = #e{vtimers = #{state_timeout := _}}) ->
    {none, E1} = virtual({state_timeout, cancel}, E),
    E1;
left(_S0, _S, E) -> E.

with_actions(next_state, S, A, E) ->
    {A1, E1} = actions(A, E),
    {next_state, S, E1, A1}.

with_actions(Kind, A, E) ->
    {A1, E1} = actions(A, E),
    {Kind, E1, A1}.

%% Toroco actions are carried out here, in order; gen_statem's pass through.
actions(A, E) when is_list(A) -> actions(A, E, []);
actions(A, E) -> actions([A], E, []).

actions([], E, Acc) ->
    {lists:reverse(Acc), E};
actions([{send, Map} | T], E, Acc) when is_map(Map) ->
    actions(T, emit_all(Map, default, E), Acc);
actions([{send, Map, Opts} = A | T], E, Acc) when is_map(Map), is_map(Opts) ->
    case maps:get(hold, Opts, default) of
        H when H =:= default; H =:= infinity; is_integer(H), H >= 0 ->
            actions(T, emit_all(Map, H, E), Acc);
        H ->
            logger:error("toroco: ~p emitted ~p with a bad hold ~p; dropped",
                         [E#e.name, A, H], ?LOG#{name => E#e.name}),
            actions(T, E, Acc)
    end;
actions([{set, Map} | T], E, Acc) when is_map(Map) ->
    actions(T, emit_each(maps:to_list(Map), set, E), Acc);
actions([{unset, Outs} | T], E, Acc) when is_list(Outs) ->
    actions(T, lists:foldl(fun(Out, EAcc) -> emit(Out, unset, EAcc) end, E, Outs), Acc);
actions([unset | T], E = #e{outputs = Outs}, Acc) ->
    actions(T, lists:foldl(fun(Out, EAcc) -> emit(Out, unset, EAcc) end, E,
                           maps:keys(Outs)), Acc);
actions([{redeliver, Ins} | T], E = #e{name = Name}, Acc) when is_list(Ins) ->
    Declared = inputs(E),
    receiver_up(Name, [I || I <- Ins, lists:member(I, Declared)]),
    actions(T, E, Acc);
actions([A | T], E, Acc) when element(1, A) =:= send; element(1, A) =:= set;
                             element(1, A) =:= unset ->
    logger:error("toroco: ~p returned a malformed action ~p; dropped", [E#e.name, A],
                 ?LOG#{name => E#e.name}),
    actions(T, E, Acc);
actions([{{timeout, Name}, _, _} = A | T], E, Acc) ->
    timer_action(A, T, timer_named(Name, E), Acc);
actions([{{timeout, Name}, _, _, _} = A | T], E, Acc) ->
    timer_action(A, T, timer_named(Name, E), Acc);
actions([A | T], E, Acc) ->
    timer_action(A, T, E, Acc).

timer_action(A, T, E, Acc) ->
    case toroco_clock:lockstep_server() of
        none -> actions(T, E, [clock(A) | Acc]);
        _ ->
            case virtual(A, E) of
                {none, E1} -> actions(T, E1, Acc);
                {A1, E1} -> actions(T, E1, [A1 | Acc])
            end
    end.

timer_named(Name, E = #e{timers = Ts}) ->
    case lists:member(Name, Ts) of
        true -> E;
        false -> E#e{timers = [Name | Ts]}
    end.

%% A callback module's timeouts count simulated milliseconds (toroco_clock):
%% relative times are turned into real ones; absolute ones and cancels pass.
clock({Kind, T, Msg}) when ?IS_TIMEOUT(Kind), is_integer(T) ->
    {Kind, toroco_clock:real_ms(T), Msg};
clock({Kind, T, Msg, Opts}) when ?IS_TIMEOUT(Kind), is_integer(T), is_list(Opts) ->
    case proplists:get_value(abs, Opts, false) of
        false -> {Kind, toroco_clock:real_ms(T), Msg, Opts};
        true -> {Kind, T, Msg, Opts}
    end;
clock(T) when is_integer(T) -> toroco_clock:real_ms(T);
clock(A) -> A.

%% In lockstep a callback module's timeouts are set with toroco_lockstep,
%% in simulated time, and gen_statem sees none of them (`none'); absolute
%% ones stay gen_statem's, in real time (the servos' keepalive).
virtual({Kind, T, Msg}, E) when ?IS_TIMEOUT(Kind), is_integer(T) ->
    vset(Kind, T, Msg, E);
virtual({Kind, infinity, _Msg}, E) when ?IS_TIMEOUT(Kind) ->
    virtual({Kind, cancel}, E);
virtual({Kind, T, Msg, Opts} = A, E) when ?IS_TIMEOUT(Kind), is_integer(T), is_list(Opts) ->
    case proplists:get_value(abs, Opts, false) of
        false -> vset(Kind, T, Msg, E);
        true -> {A, E}
    end;
virtual({Kind, cancel}, E = #e{vtimers = VT}) when ?IS_TIMEOUT(Kind) ->
    case VT of
        #{Kind := _} ->
            toroco_clock:cancel_timer(Kind),
            {none, E#e{vtimers = maps:remove(Kind, VT)}};
        #{} ->
            {none, E}
    end;
virtual({Kind, update, Msg}, E = #e{vtimers = VT}) when ?IS_TIMEOUT(Kind) ->
    case VT of
        #{Kind := Deadline} -> toroco_clock:set_timer(Kind, Deadline, Msg);
        #{} -> ok
    end,
    {none, E};
virtual(T, E) when is_integer(T) ->
    vset(timeout, T, T, E);
virtual(A, E) ->
    {A, E}.

vset(Kind, T, Msg, E = #e{vtimers = VT}) ->
    Deadline = toroco_clock:now_ms() + T,
    toroco_clock:set_timer(Kind, Deadline, Msg),
    {none, E#e{vtimers = VT#{Kind => Deadline}}}.

%% A list of the map's pairs, walked without a fun: an action's map has one
%% or two outputs, where an iterator costs more than the walk.
emit_all(Map, Hold, E) ->
    emit_each(maps:to_list(Map), Hold, E).

emit_each([], _How, E) -> E;
emit_each([{Out, V} | T], set, E) -> emit_each(T, set, emit(Out, {set, V}, E));
emit_each([{Out, V} | T], Hold, E) -> emit_each(T, Hold, emit(Out, {send, V, Hold}, E)).

%% One emission on one output: to every consumer, in order; the latch follows.
emit(Out, Op, E = #e{outputs = Outs, name = Name}) ->
    case Outs of
        #{Out := Consumers} ->
            send_all(Consumers, ?WIRE_EVENT({Name, Out}, Op)),
            case E#e.tap of
                #{emit := Sinks} ->
                    relatch(Out, Op, E#e{batch = toroco_tap:tap(Sinks, emit_event(Name, Out, Op),
                                                                E#e.batch)});
                #{} ->
                    relatch(Out, Op, E)
            end;
        #{} when E#e.open, is_atom(Out) ->
            emit(Out, Op, E#e{outputs = Outs#{Out => []}});
        #{} ->
            undeclared(Out, E)
    end.

%% An emission on an undeclared output is dropped, and said at most once a
%% second per behavior, with how many were held back since.
undeclared(Out, E = #e{name = Name, undeclared = {Last, Held}}) ->
    Now = erlang:monotonic_time(millisecond),
    case Last =:= never orelse Now - Last >= ?WARN_INTERVAL_MS of
        true ->
            logger:warning("toroco: ~p emitted on undeclared output ~p; dropped~ts",
                           [Name, Out, case Held of
                                           0 -> "";
                                           _ -> io_lib:format(" (~b more since the last warning)", [Held])
                                       end], ?LOG#{name => Name}),
            E#e{undeclared = {Now, 0}};
        false ->
            E#e{undeclared = {Last, Held + 1}}
    end.

emit_event(Name, Out, {send, V, _Hold}) -> {emit, toroco_tap:timestamp(), {Name, Out}, send, V};
emit_event(Name, Out, {set, V}) -> {emit, toroco_tap:timestamp(), {Name, Out}, set, V};
emit_event(Name, Out, unset) -> {emit, toroco_tap:timestamp(), {Name, Out}, unset, none}.

tap(Subs, Name) ->
    toroco_tap:select(Subs, [emit, lifecycle], Name).

%% A lifecycle event of this process into its batch.
lifecycle(What, E = #e{tap = Tap, name = Name, batch = B}) ->
    E#e{batch = toroco_tap:lifecycle(Tap, Name, What, B)}.

%% After an event, with the data the result carries (or the data before
%% the event if it carries none): what becomes of the batch
%% (toroco_tap:after_event/3).
tap_after(R, E0) ->
    case R of
        {keep_state, E} -> tapped(keep_state, none, E, [], E0, R);
        {keep_state, E, A} -> tapped(keep_state, none, E, A, E0, R);
        {next_state, S, E} -> tapped(next_state, S, E, [], E0, R);
        {next_state, S, E, A} -> tapped(next_state, S, E, A, E0, R);
        {repeat_state, E} -> tapped(repeat_state, none, E, [], E0, R);
        {repeat_state, E, A} -> tapped(repeat_state, none, E, A, E0, R);
        keep_state_and_data -> tapped(keep_state, none, E0, [], E0, R);
        {keep_state_and_data, A} -> tapped(keep_state, none, E0, A, E0, R);
        repeat_state_and_data -> tapped(repeat_state, none, E0, [], E0, R);
        {repeat_state_and_data, A} -> tapped(repeat_state, none, E0, A, E0, R);
        _ -> R                                  % stopping: terminate/3 sends it
    end.

tapped(_How, _S, #e{batch = []}, _A, _E0, R) ->
    R;
tapped(How, S, E = #e{batch = B}, A0, #e{batch = B0}, R) ->
    A = case is_list(A0) of true -> A0; false -> [A0] end,
    case toroco_tap:after_event(B0 =/= [], B, lists:any(fun event_timeout/1, A)) of
        keep -> R;
        {B1, More} when How =:= next_state -> {next_state, S, E#e{batch = B1}, More ++ A};
        {B1, More} -> {How, E#e{batch = B1}, More ++ A}
    end.

event_timeout(T) when is_integer(T) -> true;
event_timeout({timeout, _, _}) -> true;
event_timeout({timeout, _, _, _}) -> true;
event_timeout(_) -> false.

send_all([], _Msg) -> ok;
send_all([C | Cs], Msg) ->
    toroco_wire:send(C, Msg),
    send_all(Cs, Msg).

has_remote(#e{outputs = Outs}) ->
    lists:any(fun toroco_wire:remote/1, lists:append(maps:values(Outs))).

alive_timer() ->
    {{timeout, '$toroco_alive'}, toroco_wire:keepalive_ms(), beat}.

relatch(Out, {set, V}, E = #e{latches = L}) ->
    E#e{latches = L#{Out => V}};
relatch(Out, _, E = #e{latches = L}) ->
    case L of
        #{Out := _} -> E#e{latches = maps:remove(Out, L)};
        #{} -> E
    end.

latch(Out, #e{latches = L}) ->
    case L of
        #{Out := V} -> {value, V};
        #{} -> none
    end.

describe(S, #e{kind = Kind, module = M, layer = L, latches = Latches, suspended = Susp,
               user = UD, open = Open, outputs = Outs}) ->
    {message_queue_len, Q} = erlang:process_info(self(), message_queue_len),
    Base0 = #{kind => Kind, module => M, layer => L, latches => Latches,
              status => case Susp of true -> suspended; false -> running end,
              state => S, mailbox => Q},
    %% open ports: the outputs it has come to have
    Base = case Open of
               true -> Base0#{outputs => maps:keys(Outs)};
               false -> Base0
           end,
    case erlang:function_exported(M, info, 2) of
        true -> Base#{Kind => M:info(S, UD)};
        false -> Base
    end.
