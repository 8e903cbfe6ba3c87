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
%% The process is the emitter end of every wire it feeds (`toroco_emitter':
%% per output, its consumers and its latch). On start it announces itself to
%% its consumers (`hello': nothing of the previous incarnation survives) and
%% to its input routers (which re-deliver each input's latched winner).
%% Lockstep, the idle tick and the observer tap's batch are the shell's
%% (`toroco_shell', shared with the consumers); `event/4' dispatches the
%% rest by concern: the tap's subscriptions, inputs, wiring, the runtime's
%% calls, the callback module's own events. The callback module's
%% `handle_input/4' and `handle_event/4' are called through funs made at
%% start and again at a code change.
%%
%% Time: a callback module reads time only with `toroco_clock:now_ms/0' and
%% sets timers only with gen_statem's timeout actions (`state_timeout',
%% `{timeout, Name}', event timeouts, relative times): the engine turns them
%% (`toroco_timeouts') into the runtime's clock, scaled by the simulated
%% lab's speed, or kept by `toroco_lockstep' in simulated time when a world
%% is the clock (SPEC §14).
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
%% The shell's way into this module (toroco_shell:host()), not an API.
-export([shell/1, shell/2, event/4]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3, code_change/4]).
-export_type([spec/0, action/0, actions/0, result/0]).
%% Steps of every input of the path, inlined: its calls are its cost.
-compile({inline, [delivered/5, input/4, with_actions/3, emitted/2, actions/2]}).

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
            %% the callback module's handle_input/4 and handle_event/4 (or
            %% `none'), made once at start and again at a code change, so
            %% the event path calls no export looked up by name
            %% (what they return is checked: any term)
            on_input :: fun((atom(), term(), term(), term()) -> term()) | undefined,
            on_event = none :: fun((gen_statem:event_type(), term(), term(), term()) -> term())
                             | none,
            %% the outputs: their consumers and latches
            emitter :: toroco_emitter:emitter() | undefined,
            inputs = [] :: [atom()],
            suspended = false :: boolean(),
            queued = [] :: [{gen_statem:event_type(), term()}],
            %% the observer tap's sinks that concern this process (SPEC §10)
            tap = #{} :: toroco_tap:sinks(),
            %% lockstep, the idle tick, the tap's batch, simulated timeouts
            shell :: toroco_shell:shell() | undefined,
            %% names of the generic timeouts the callback module has set, so
            %% that a reset cancels them
            timers = [] :: [term()],
            %% open ports (interface/1's `open'): the wiring's inputs are its
            %% inputs too
            open = false :: boolean()}).

-define(LOG, #{domain => [toroco, engine]}).
%% The runtime's own calls (toroco:inject/3, info/1, suspend/1, resume/1,
%% reset_behavior/1).
-define(IS_CONTROL(Req), (Req =:= '$toroco_info' orelse Req =:= '$toroco_suspend'
                          orelse Req =:= '$toroco_resume' orelse Req =:= '$toroco_reset'
                          orelse (is_tuple(Req) andalso element(1, Req) =:= '$toroco_inject'))).
%% How the shell reaches this module's data and events (toroco_shell:host()):
%% external funs of a constant module, so the tuple is a literal.
-define(HOST, {fun ?MODULE:shell/1, fun ?MODULE:shell/2, fun ?MODULE:event/4}).

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
        {ok, I} ->
            ok = toroco_tap:join(),
            Planned = toroco_wiring:subs_of(Name),
            {Ins, Outs} = ports(Name, I, Planned),
            Subs = maps:from_list([{O, [toroco_wire:address(R) || R <- maps:get(O, Planned, [])]}
                                   || O <- Outs]),
            Open = maps:get(open, I, false),
            Tap = tap(toroco_tap:current(), Name),
            E = bind(#e{name = Name, kind = Kind, module = M, layer = Layer, args = Args,
                        emitter = toroco_emitter:tap(Tap, toroco_emitter:new(Name, Subs, Open)),
                        inputs = Ins, open = Open, tap = Tap, shell = toroco_shell:new()}),
            toroco_tap:lifecycle(E#e.tap, Name, toroco_restarts:started(Name)),
            ok = toroco_lockstep:up(Name, case Kind of
                                              behavior -> Layer;
                                              device -> none
                                          end),
            announce(E),
            case start_user(E) of
                {ok, S, E1} ->
                    toroco_lockstep:ready(Name),
                    {ok, S, flushed(E1)};
                {ok, S, E1, A} ->
                    toroco_lockstep:ready(Name),
                    {ok, S, flushed(E1), A};
                Stop -> Stop
            end;
        {error, Reason} ->
            {stop, Reason}
    end.

%% The ports: declared, and with open ports those the wiring named before
%% this start too.
ports(Name, I = #{inputs := Ins, outputs := Outs}, Planned) ->
    case maps:get(open, I, false) of
        true ->
            Wired = toroco_wiring:ports_of(Name),
            {lists:usort(Ins ++ maps:get(inputs, Wired, [])),
             lists:usort(Outs ++ maps:get(outputs, Wired, []) ++ maps:keys(Planned))};
        false ->
            {Ins, Outs}
    end.

%% The callback module's event path functions, as funs (see `on_input').
bind(E = #e{module = M}) ->
    E#e{on_input = fun M:handle_input/4,
        on_event = case erlang:function_exported(M, handle_event, 4) of
                       true -> fun M:handle_event/4;
                       false -> none
                   end}.

%% Announces this incarnation: consumers drop whatever they had of the last
%% one; input routers re-deliver their latched winners.
announce(#e{name = Name, emitter = Em, inputs = Ins, kind = Kind}) ->
    toroco_emitter:announce(Em),
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
%% Lockstep, the idle tick and the tap's batch are the shell's
%% (toroco_shell); the rest comes to event/4.
handle_event(info, ?WIRE_IN(Input, V) = Msg, S, E = #e{shell = Sh}) ->
    %% the event path's common case, as event/4 would take it, without
    %% the shell's dispatch (toroco_shell:awake/1)
    case toroco_shell:awake(Sh) of
        true -> toroco_shell:done(delivered(Input, V, none, S, E), E, ?HOST);
        false -> toroco_shell:handle_event(info, Msg, S, E, ?HOST)
    end;
handle_event(Type, Content, S, E) ->
    toroco_shell:handle_event(Type, Content, S, E, ?HOST).

%% @private
-spec shell(#e{}) -> toroco_shell:shell().
shell(#e{shell = Sh}) -> Sh.

%% @private
-spec shell(toroco_shell:shell(), #e{}) -> #e{}.
shell(Sh, E) -> E#e{shell = Sh}.

%% @private Every event the shell does not handle itself.
-spec event(gen_statem:event_type(), term(), term(), #e{}) ->
          gen_statem:event_handler_result(term()).

%% The observer tap changed: keep the sinks that concern this process.
event(info, ?WIRE_TAP(Subs), _S, E = #e{name = Name, emitter = Em}) ->
    Tap = tap(Subs, Name),
    {keep_state, E#e{tap = Tap, emitter = toroco_emitter:tap(Tap, Em)}};
%% The event path: one input delivered by a router.
event(info, ?WIRE_IN(Input, V), S, E) ->
    delivered(Input, V, none, S, E);
event(info, ?WIRE_IN(Input, V, Router), S, E) ->
    delivered(Input, V, Router, S, E);
%% Wiring: consumers attach and detach (see toroco_wire); those on other
%% nodes hear from each output now and then.
event(info, ?WIRE_SUB(Src, Consumer), _S, E = #e{emitter = Em}) ->
    {Em1, Actions} = toroco_emitter:subscribed(Src, Consumer, Em),
    {keep_state, E#e{emitter = Em1}, Actions};
event(info, ?WIRE_UNSUB(Src, Consumer), _S, E = #e{emitter = Em}) ->
    {keep_state, E#e{emitter = toroco_emitter:unsubscribed(Src, Consumer, Em)}};
event({timeout, '$toroco_alive'}, beat, _S, #e{emitter = Em}) ->
    {keep_state_and_data, toroco_emitter:beat(Em)};
%% The runtime's calls.
event({call, From}, Req, S, E) when ?IS_CONTROL(Req) ->
    control(Req, From, S, E);
%% Everything else belongs to the callback module.
event(Type, Content, S, E) ->
    user(Type, Content, S, E).

%% An input, unless suspended (then it is dropped); a `latest' one is acked.
delivered(Input, V, Router, S, E = #e{suspended = Suspended}) ->
    R = case Suspended of
            false -> input(Input, V, S, E);
            true -> keep_state_and_data
        end,
    _ = Router =:= none orelse toroco_wire:send(Router, ?WIRE_ACK(Input)),
    R.

control({'$toroco_inject', Out, Op}, From, _S, E = #e{emitter = Em, name = N}) ->
    case toroco_emitter:has(Out, Em) of
        true -> {keep_state, emit(Out, Op, E), [{reply, From, ok}]};
        false -> {keep_state_and_data, [{reply, From, {error, {unknown_output, {N, Out}}}}]}
    end;
control('$toroco_reset', From, _S, E = #e{kind = behavior}) ->
    case reset(E) of
        {next_state, S1, E1, Actions} -> {next_state, S1, E1, [{reply, From, ok} | Actions]};
        {stop, Reason, E1} -> {stop_and_reply, Reason, [{reply, From, ok}], E1}
    end;
control('$toroco_info', From, S, E) ->
    {keep_state_and_data, [{reply, From, describe(S, E)}]};
control('$toroco_suspend', From, _S, E) ->
    {keep_state, lifecycle(suspended, E#e{suspended = true}), [{reply, From, ok}]};
control('$toroco_resume', From, _S, E = #e{suspended = false}) ->
    {keep_state, E, [{reply, From, ok}]};
control('$toroco_resume', From, _S, E = #e{name = Name, queued = Q}) ->
    %% Routers forget the last value and re-deliver each input's winner; the
    %% callbacks held back while suspended run now, in order.
    receiver_up(Name, inputs(E)),
    {keep_state, lifecycle(resumed, E#e{suspended = false, queued = []}),
     [{reply, From, ok} | [{next_event, T, C} || {T, C} <- lists:reverse(Q)]]};
control(Req, From, S, E) ->
    user({call, From}, Req, S, E).              % a device's reset is its module's

%% The callback module's events: held back while suspended; a module
%% without handle_event/4, or whose handle_event/4 has no clause for the
%% event, gets the engine's default.
user(Type, Content, _S, E = #e{suspended = true, queued = Q, name = Name}) ->
    case length(Q) < ?MAX_QUEUED of
        true -> {keep_state, E#e{queued = [{Type, Content} | Q]}};
        false ->
            logger:warning("toroco: suspended ~p dropped ~p event ~p", [Name, Type, Content],
                           ?LOG#{name => Name}),
            keep_state_and_data
    end;
user(Type, Content, _S, E = #e{on_event = none}) ->
    default_event(Type, Content, E);
user(Type, Content, S, E = #e{on_event = Handle, module = M, user = UD}) ->
    try Handle(Type, Content, S, UD) of
        R -> result(R, S, E)
    catch
        error:function_clause:Stack ->
            case Stack of
                [{M, handle_event, [Type, Content, S, UD], _} | _] -> default_event(Type, Content, E);
                _ -> erlang:raise(error, function_clause, Stack)
            end
    end.

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
    _ = case erlang:function_exported(M, terminate, 3) andalso M:terminate(Reason, S, UD) of
            {emit, Actions} -> {_, E1} = actions(Actions, E), flushed(E1);
            _ -> flushed(E)
        end,
    toroco_tap:lifecycle(E#e.tap, Name, stopped).

-spec code_change(term(), term(), #e{}, term()) -> {ok, term(), #e{}}.
code_change(OldVsn, S, E = #e{module = M, user = UD}, Extra) ->
    case erlang:function_exported(M, code_change, 4) of
        true ->
            {ok, S1, UD1} = M:code_change(OldVsn, S, UD, Extra),
            {ok, S1, bind(E#e{user = UD1})};
        false ->
            {ok, S, bind(E)}
    end.

%%====================================================================
%% Inputs and results
%%====================================================================

input(?RESET, _V, _S, E) ->
    reset(E);
input(Input, V, S, E = #e{on_input = Handle, user = UD}) ->
    result(Handle(Input, V, S, UD), S, E).

%% Brooks' reset: the behavior's latches and holds are cleared, then it starts
%% again from init/1 in the same process.
reset(E0) ->
    E = #e{emitter = Em, shell = Sh} = lifecycle(reset, E0),
    E1 = emitted(toroco_emitter:unset(all, Em, Sh), E),
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
left(_S0, _S, E = #e{shell = Sh}) -> E#e{shell = toroco_shell:left(Sh)}.

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
actions([{send, Map} | T], E = #e{emitter = Em, shell = Sh}, Acc) when is_map(Map) ->
    actions(T, emitted(toroco_emitter:send(Map, default, Em, Sh), E), Acc);
actions([{send, Map, Opts} = A | T], E, Acc) when is_map(Map), is_map(Opts) ->
    case maps:get(hold, Opts, default) of
        H when H =:= default; H =:= infinity; is_integer(H), H >= 0 ->
            actions(T, emitted(toroco_emitter:send(Map, H, E#e.emitter, E#e.shell), E), Acc);
        H ->
            logger:error("toroco: ~p emitted ~p with a bad hold ~p; dropped",
                         [E#e.name, A, H], ?LOG#{name => E#e.name}),
            actions(T, E, Acc)
    end;
actions([{set, Map} | T], E = #e{emitter = Em, shell = Sh}, Acc) when is_map(Map) ->
    actions(T, emitted(toroco_emitter:set(Map, Em, Sh), E), Acc);
actions([{unset, Outs} | T], E = #e{emitter = Em, shell = Sh}, Acc) when is_list(Outs) ->
    actions(T, emitted(toroco_emitter:unset(Outs, Em, Sh), E), Acc);
actions([unset | T], E = #e{emitter = Em, shell = Sh}, Acc) ->
    actions(T, emitted(toroco_emitter:unset(all, Em, Sh), E), Acc);
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

%% A timeout counts simulated milliseconds (toroco_timeouts); the other
%% gen_statem actions pass.
timer_action(A, T, E = #e{shell = Sh}, Acc) ->
    {As, Sh1} = toroco_shell:timeout(A, Sh),
    actions(T, E#e{shell = Sh1}, lists:reverse(As, Acc)).

timer_named(Name, E = #e{timers = Ts}) ->
    case lists:member(Name, Ts) of
        true -> E;
        false -> E#e{timers = [Name | Ts]}
    end.

%% Emissions go through the emitter (toroco_emitter), their observer's
%% events into the shell.
emit(Out, Op, E = #e{emitter = Em, shell = Sh}) ->
    emitted(toroco_emitter:emit(Out, Op, Em, Sh), E).

emitted({Em, Sh}, E) ->
    E#e{emitter = Em, shell = Sh}.

tap(Subs, Name) ->
    toroco_tap:select(Subs, [emit, lifecycle], Name).

%% A lifecycle event of this process into its batch.
lifecycle(What, E = #e{tap = Tap, name = Name, shell = Sh}) ->
    E#e{shell = toroco_shell:lifecycle(Tap, Name, What, Sh)}.

%% The tap's batch sent now.
flushed(E = #e{shell = Sh}) ->
    E#e{shell = toroco_shell:flush(Sh)}.

describe(S, #e{kind = Kind, module = M, layer = L, emitter = Em, suspended = Susp,
               user = UD, open = Open}) ->
    {message_queue_len, Q} = erlang:process_info(self(), message_queue_len),
    Base0 = #{kind => Kind, module => M, layer => L, latches => toroco_emitter:latches(Em),
              status => case Susp of true -> suspended; false -> running end,
              state => S, mailbox => Q},
    %% open ports: the outputs it has come to have
    Base = case Open of
               true -> Base0#{outputs => toroco_emitter:outputs(Em)};
               false -> Base0
           end,
    case erlang:function_exported(M, info, 2) of
        true -> Base#{Kind => M:info(S, UD)};
        false -> Base
    end.
