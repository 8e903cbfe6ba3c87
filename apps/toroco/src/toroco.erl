%% @doc Torocó's public API: build a subsumption network of behaviors and
%% devices, wire it, drive it and look inside it while it runs.
%%
%% <b>Nodes</b>: {@link add_behavior/3}, {@link add_device/3}, {@link
%% remove_behavior/1}, {@link remove_device/1}, {@link suspend_behavior/1},
%% {@link resume_behavior/1}, {@link reset_behavior/1}, {@link
%% restart_behavior/1}.
%%
%% <b>Wiring</b>: {@link set_inputs/2} (suppression: sources highest priority
%% first), {@link set_inhibitors/2} (inhibition), {@link set_reset/2}, {@link
%% load_wiring/1}.
%%
%% <b>Driving and looking</b>: {@link inject/2}, {@link inject/3}, {@link
%% inspect/0}, {@link inspect/1}, {@link top/0}, {@link watch/2}, {@link
%% unwatch/0}, {@link wiring_dot/0}, {@link reload/1}.
%%
%% <b>Observing the event path</b> (SPEC §10): {@link subscribe_events/1},
%% {@link unsubscribe_events/1}, {@link flush_events/1}.
%%
%% <b>The simulated world</b> (SPEC §10, §14): {@link publish_world/1},
%% {@link subscribe_world/0}, {@link unsubscribe_world/1}: a world publishes
%% its snapshots through the runtime and whoever draws them subscribes, so
%% neither knows the other's processes.
%%
%% <b>Several nodes</b> (SPEC §13): `#{node => Node}' in the options of
%% {@link add_behavior/3} and {@link add_device/3} (and of a wiring file's
%% `behavior' and `device' terms) places it on `Node'. Every call works from
%% any node of the robot and acts where the thing lives: the wiring server of
%% the receiver's node wires its inputs, that of the emitter's node its
%% inhibitors; `inspect/0' covers every connected node.
%%
%% The runtime's API is this module, `toroco_clock' (time: the simulated
%% lab's speed and lockstep, SPEC §14) and the behaviours a callback module
%% implements, `toroco_behavior' and `toroco_device' (with
%% `toroco_device:call/3' and `cast/2', a device module's way to its own
%% process wherever it runs), and `toroco_slots' (the connection bounds
%% every listener of the project applies). Every other module of the application is
%% private: the other applications use none of them (a test checks it).
%%
%% Every call returns `ok' or `{error, Reason}' with a reason naming the
%% offending behavior, device, input or output; a refused wiring change
%% changes nothing. The semantics are those of SPEC §4.
-module(toroco).

-export([whereis/1]).
-compile({no_auto_import, [whereis/1]}).
-export([add_behavior/3, add_device/3, remove_behavior/1, remove_device/1,
         suspend_behavior/1, resume_behavior/1, reset_behavior/1, restart_behavior/1,
         set_inputs/2, set_inhibitors/2, set_reset/2, load_wiring/1, read_wiring/1,
         inject/2, inject/3, inspect/0, inspect/1,
         top/0, watch/2, unwatch/0, wiring_dot/0, reload/1,
         subscribe_events/1, unsubscribe_events/1, flush_events/1,
         publish_world/1, subscribe_world/0, unsubscribe_world/1]).

-export_type([wiring_summary/0]).
-export_type([name/0, source/0, source_spec/0, input_spec/0, behavior_opts/0,
              hold/0, error_reason/0, world_snapshot/0]).

-type name() :: atom().
%% A simulated world's snapshot (SPEC §14; its keys in `toroco_live_world''s
%% module doc).
-type world_snapshot() :: #{run := term(), t_ms := non_neg_integer(), atom() => term()}.

%% The pg scope (a child of toroco_sup) whose group `world' holds this
%% node's subscribers to the world's snapshots.
-define(WORLD_SCOPE, toroco_world_pg).
%% What a wiring file adds ({@link read_wiring/1}).
-type wiring_summary() :: toroco_wiring_file:summary().

%% Whether the caller is the process of behavior or device `Name': a
%% callback that injects into its own output would wait on itself.
-define(IS_SELF(Name), (erlang:whereis(toroco_names:process(Name)) =:= self())).
-type source() :: {Emitter :: name(), Output :: atom()}.
-type hold() :: non_neg_integer() | infinity.
-type source_spec() :: source() | {Emitter :: name(), Output :: atom(), #{hold => hold()}}.
-type input_spec() :: [source_spec()]
                    | #{sources := [source_spec()], buffer => all | latest, idle => term()}.
%% A module with `interface/1' (toroco_behavior) takes options of its own
%% too, e.g. `toroco_lua''s `file'.
-type behavior_opts() :: #{layer => non_neg_integer(), params => map(), atom() => term()}.
%% What went wrong, and the culprit: the tag says what, the second element
%% names the behavior, device, input, output, source, option or file
%% (SPEC §4, "Errors"), e.g. `{unknown_output, {avoid_left, motors}}'.
-type error_reason() ::
        {unknown_name | unknown_input | unknown_output | not_a_behavior | not_running
         | nodedown | duplicate_name | name_taken | duplicate_source | hierarchy
         | inhibition_cycle | layer_removed | self_call | timeout | unknown_call
         | bad_name | bad_module | bad_interface | bad_layer | bad_params | bad_option
         | bad_options | bad_inputs | bad_input_spec | bad_inhibitors | bad_reset
         | bad_source | bad_sources | bad_buffer | bad_hold | bad_max_age | bad_kind
         | bad_kinds | bad_names | bad_watch | bad_wiring_term | wiring_file | file
         | start_failed | restart_failed | suspend_failed | code_change_failed
         | load_failed | no_object_code | old_code_in_use | unchanged | relay_failed
         | watch_failed | dot_failed | no_graphviz | unknown_subscription, term()}
      | {bad_option, term(), term()}
      | not_running | unknown_request.

%%====================================================================
%% Nodes
%%====================================================================

%% @doc Starts behavior `Name' running callback module `Module' in its layer.
-spec add_behavior(name(), module(), behavior_opts()) -> ok | {error, error_reason()}.
add_behavior(Name, Module, Opts) ->
    add(behavior, Name, Module, Opts).

%% @doc Starts device `Name' (a `toroco_device' module) with `Opts'.
-spec add_device(name(), module(), map()) -> ok | {error, error_reason()}.
add_device(Name, Module, Opts) ->
    add(device, Name, Module, Opts).

add(Kind, Name, Module, Opts = #{node := Node}) when is_atom(Node) ->
    toroco_wiring:call(Node, {add, Kind, Name, Module, maps:remove(node, Opts)});
add(_Kind, Name, _Module, #{node := Node}) ->
    {error, {bad_option, {Name, {node, Node}}}};
add(Kind, Name, Module, Opts) ->
    toroco_wiring:call({add, Kind, Name, Module, Opts}).

%% The node where `Name' lives, if it is known.
where(Name) ->
    toroco_wiring:call({where, Name}).

%% A wiring request to the server of the node where `Name' lives (the local
%% one answers for a name it does not know).
at(Name, Request) ->
    case where(Name) of
        {ok, Node} -> toroco_wiring:call(Node, Request);
        {error, _} -> toroco_wiring:call(Request)
    end.

%% `Fun' run on the node where `Name' lives, if it is another one.
on(Name, Local, Remote) ->
    case where(Name) of
        {ok, Node} when Node =/= node() ->
            try erpc:call(Node, Remote, 10000)
            catch error:{erpc, _} -> {error, {nodedown, Node}}
            end;
        _ -> Local()
    end.

%% @doc Stops a behavior and strips it from every input and inhibitor list.
-spec remove_behavior(name()) -> ok | {error, error_reason()}.
remove_behavior(Name) ->
    at(Name, {remove, behavior, Name}).

%% @doc Stops a device and strips it from every input and inhibitor list.
-spec remove_device(name()) -> ok | {error, error_reason()}.
remove_device(Name) ->
    at(Name, {remove, device, Name}).

%% @doc Stops input delivery and callbacks of a behavior; its latches and
%% holds stay. Inputs arriving while suspended are dropped.
-spec suspend_behavior(name()) -> ok | {error, error_reason()}.
suspend_behavior(Name) ->
    on(Name, fun() -> with_behavior(Name, fun toroco_behavior:suspend/1) end,
       fun() -> suspend_behavior(Name) end).

%% @doc The process of behavior or device `Name' on this node, or of the
%% router of input `{router, Receiver, Input}'; `undefined' if none runs.
-spec whereis(name() | {router, name(), atom()}) -> pid() | undefined.
whereis({router, Receiver, Input}) ->
    erlang:whereis(toroco_names:router(Receiver, Input));
whereis(Name) when is_atom(Name) ->
    erlang:whereis(toroco_names:process(Name)).

%% @doc Resumes a suspended behavior; each input's latched winner is
%% re-delivered to it.
-spec resume_behavior(name()) -> ok | {error, error_reason()}.
resume_behavior(Name) ->
    on(Name, fun() -> with_behavior(Name, fun toroco_behavior:resume/1) end,
       fun() -> resume_behavior(Name) end).

%% @doc Brooks' reset (SPEC §4): the behavior's latches and holds are
%% cleared and it starts again from `init/1' in the same process, as an
%% event on one of its `set_reset/2' sources does.
-spec reset_behavior(name()) -> ok | {error, error_reason()}.
reset_behavior(Name) ->
    on(Name, fun() -> with_behavior(Name, fun toroco_behavior:reset_behavior/1) end,
       fun() -> reset_behavior(Name) end).

%% @doc Stops the behavior's process and has its layer's supervisor start a
%% new one (a restart: counted in `inspect/1''s `restarts', not towards the
%% layer's restart intensity). Its latches are gone, as after a crash.
-spec restart_behavior(name()) -> ok | {error, error_reason()}.
restart_behavior(Name) ->
    on(Name, fun() ->
                     case toroco_wiring:call({node, Name}) of
                         {ok, #{kind := behavior, layer := L}} -> toroco_layers_sup:restart(L, Name);
                         {ok, #{kind := device}} -> {error, {not_a_behavior, Name}};
                         Err -> Err
                     end
             end,
       fun() -> restart_behavior(Name) end).

with_behavior(Name, Fun) ->
    case toroco_wiring:call({node, Name}) of
        {ok, #{kind := behavior}} -> Fun(Name);
        {ok, #{kind := device}} -> {error, {not_a_behavior, Name}};
        Err -> Err
    end.

%%====================================================================
%% Wiring
%%====================================================================

%% @doc Wires inputs of `Receiver', each to its sources in priority order
%% (highest first). Inputs not listed are left alone; `[]' unwires one.
%% Returns once every router involved has taken in its sources' state.
-spec set_inputs(name(), #{atom() => input_spec()}) -> ok | {error, error_reason()}.
set_inputs(Receiver, Inputs) ->
    at(Receiver, {set_inputs, Receiver, Inputs}).

%% @doc Sets the inhibitors of outputs of `Emitter'; `[]' removes them.
-spec set_inhibitors(name(), #{atom() => [source_spec()]}) -> ok | {error, error_reason()}.
set_inhibitors(Emitter, Outputs) ->
    at(Emitter, {set_inhibitors, Emitter, Outputs}).

%% @doc Each event on one of `Sources' restarts `Behavior' from `init/1'.
-spec set_reset(name(), [source_spec()]) -> ok | {error, error_reason()}.
set_reset(Behavior, Sources) ->
    at(Behavior, {set_reset, Behavior, Sources}).

%% @doc Applies a wiring file: `file:consult/1' terms among
%% `{behavior, Name, Module, Opts}', `{device, Name, Module, Opts}',
%% `{inputs, Receiver, Map}', `{inhibitors, Emitter, Map}' and
%% `{reset, Behavior, Sources}', validated as a whole before anything starts.
-spec load_wiring(file:name_all()) -> ok | {error, error_reason()}.
load_wiring(File) ->
    case file:consult(File) of
        {ok, Terms} -> load(Terms);
        {error, Reason} -> {error, {wiring_file, File, Reason}}
    end.

%% @doc What wiring file `File' adds, read without applying it: its
%% behaviors and devices (in the file's order), their modules, the inputs
%% it wires and the other nodes it places things on. A program that sets
%% up or takes down what a file loads (the simulated lab) asks this instead
%% of reading the file's terms itself.
-spec read_wiring(file:name_all()) ->
          {ok, wiring_summary()} | {error, error_reason()}.
read_wiring(File) ->
    case file:consult(File) of
        {ok, Terms} -> {ok, toroco_wiring_file:summary(Terms)};
        {error, Reason} -> {error, {wiring_file, {File, Reason}}}
    end.

%%====================================================================
%% Driving
%%====================================================================

%% @doc As if `Src' had sent `Value' (a momentary event, no hold).
%% A file whose every behavior and device is on this node is checked whole
%% and applied atomically; one that places some on other nodes is applied
%% term by term, in order, each where it acts, stopping at the first error.
load(Terms) ->
    Here = fun({K, _, _, #{node := N}}) when K =:= behavior; K =:= device -> N =:= node();
              (_) -> true
           end,
    Local = fun({K, Name, M, Opts = #{node := _}}) when K =:= behavior; K =:= device ->
                    {K, Name, M, maps:remove(node, Opts)};
               (T) -> T
            end,
    case lists:all(Here, Terms) of
        true -> toroco_wiring:call({load, [Local(T) || T <- Terms]});
        false -> load_each(Terms)
    end.

load_each([]) -> ok;
load_each([T | Ts]) ->
    case load_term(T) of
        ok -> load_each(Ts);
        Err -> Err
    end.

load_term({behavior, Name, M, Opts}) -> add_behavior(Name, M, Opts);
load_term({device, Name, M, Opts}) -> add_device(Name, M, Opts);
load_term({inputs, R, Map}) -> set_inputs(R, Map);
load_term({inhibitors, E, Map}) -> set_inhibitors(E, Map);
load_term({reset, B, Srcs}) -> set_reset(B, Srcs);
load_term(Other) -> {error, {bad_wiring_term, Other}}.

-spec inject(source(), term()) -> ok | {error, error_reason()}.
inject(Src, Value) ->
    inject(Src, Value, #{}).

%% @doc As if `Src' had emitted `Value': `#{latch => true}' is a `set',
%% `#{hold => H}' a `send' with that hold.
-spec inject(source(), term(), #{latch => boolean(), hold => hold()}) ->
          ok | {error, error_reason()}.
inject({E, _} = Src, Value, Opts) when is_atom(E), is_map(Opts) ->
    case erlang:whereis(toroco_names:process(E)) =:= undefined andalso where(E) of
        {ok, Node} when Node =/= node() ->
            on(E, fun() -> {error, {unknown_name, E}} end,
               fun() -> inject(Src, Value, Opts) end);
        _ -> inject_here(Src, Value, Opts)
    end;
inject(Src, _Value, Opts) when is_map(Opts) ->
    {error, {bad_source, Src}};
inject(Src, _Value, Opts) ->
    {error, {bad_option, {Src, Opts}}}.

inject_here({E, Out} = Src, Value, Opts) when is_atom(E), is_atom(Out), is_map(Opts) ->
    %% Straight to the emitter; the wiring table tells an unknown name from
    %% one that is not running.
    case {inject_op(Src, Value, Opts), ?IS_SELF(E)} of
        {{ok, _}, true} -> {error, {self_call, E}};
        {{ok, Op}, false} ->
            case toroco_behavior:inject(E, Out, Op) of
                {error, {not_running, E}} = NotRunning ->
                    case toroco_wiring:known(E) of
                        true -> NotRunning;
                        false -> {error, {unknown_name, E}}
                    end;
                Other -> Other
            end;
        {Err, _} -> Err
    end;
inject_here(Src, _Value, _Opts) ->
    {error, {bad_source, Src}}.

inject_op(Src, Value, Opts) ->
    case {maps:keys(maps:without([latch, hold], Opts)), Opts} of
        {[Bad | _], _} -> {error, {bad_option, {Src, Bad}}};
        {[], #{latch := true, hold := _}} -> {error, {bad_option, {Src, {latch, hold}}}};
        {[], #{latch := true}} -> {ok, {set, Value}};
        {[], #{hold := H}} when H =:= infinity; is_integer(H), H >= 0 -> {ok, {send, Value, H}};
        {[], #{hold := H}} -> {error, {bad_hold, {Src, H}}};
        {[], #{latch := L}} when L =/= false -> {error, {bad_option, {Src, {latch, L}}}};
        {[], _} -> {ok, {send, Value, default}}
    end.

%%====================================================================
%% Looking inside
%%====================================================================

%% @doc Names of behaviors and devices, the layers and the layers taken out.
-spec inspect() -> #{behaviors := [name()], devices := [name()],
                     layers := #{non_neg_integer() => [name()]},
                     removed_layers := [non_neg_integer()]}.
inspect() ->
    toroco_inspect:overview().

%% @doc One behavior or device: status, inputs with their winner, holds,
%% latches and last value, outputs with their inhibition and latch (SPEC §6).
-spec inspect(name()) -> map() | {error, error_reason()}.
inspect(Name) ->
    on(Name, fun() -> toroco_inspect:describe(Name) end,
       fun() -> toroco_inspect:describe(Name) end).

%% @doc Prints a table of the running network (for the remote shell).
-spec top() -> ok.
top() ->
    toroco_top:print().

%% @doc Prints deliveries to an input (`{Receiver, Input}') or to every input
%% of a behavior, live, until `max' events (default 100) or `seconds' (default
%% 60) or a rate above `rate' per second (default 50) stop it.
-spec watch(name() | {name(), atom()}, map()) -> ok | {error, error_reason()}.
watch(What, Opts) ->
    %% A thing on another node is watched there, printing here.
    Name = case What of
               {N, _} -> N;
               N -> N
           end,
    case is_atom(Name) andalso is_map(Opts) andalso where(Name) of
        {ok, Node} when Node =/= node() ->
            Io = maps:get(io, Opts, group_leader()),
            try erpc:call(Node, toroco_watch, start, [What, Opts#{io => Io}], 10000)
            catch error:{erpc, _} -> {error, {nodedown, Node}}
            end;
        _ -> toroco_watch:start(What, Opts)
    end.

%% @doc Stops a running watch.
-spec unwatch() -> ok.
unwatch() ->
    _ = erpc:multicall([N || N <- toroco_wiring:peers(), N =/= node()], toroco_watch, stop, [], 5000),
    toroco_watch:stop().

%% @doc The wiring as a Graphviz `dot' graph.
-spec wiring_dot() -> iodata().
wiring_dot() ->
    toroco_dot:wiring().

%% @doc Hot code reload of every behavior running `Module'; or, for the
%% name of a behavior whose module reloads its own code (a Lua behavior:
%% its file, all or nothing), that behavior's.
-spec reload(module() | name()) -> ok | {error, error_reason()}.
reload(What) when is_atom(What) ->
    case own_reload(What) of
        {ok, M} -> on(What, fun() -> M:reload(What) end, fun() -> M:reload(What) end);
        none -> toroco_reload:reload(What)
    end;
reload(What) ->
    toroco_reload:reload(What).

%% The module of behavior `Name' if it exports reload/1 (toroco_behavior's
%% optional callback).
own_reload(Name) ->
    case at(Name, {node, Name}) of
        {ok, #{kind := behavior, module := M}} ->
            _ = code:ensure_loaded(M),
            case erlang:function_exported(M, reload, 1) of
                true -> {ok, M};
                false -> none
            end;
        _ -> none
    end.

%%====================================================================
%% Observing the event path
%%====================================================================

%% @doc Subscribes the calling process to the event path: it receives
%% `{toroco_event, Ref, Event}' for the events of `kinds' (`emit',
%% `deliver', `router', `lifecycle'; default all) about `names' (default
%% `all'), with at most `buffer' (default 10000) pending; past that, events
%% are counted and reported as `{dropped, N}' (SPEC §10). A subscriber that
%% dies is unsubscribed. With `delivery => batch' the same events come
%% several to a message, in order, as `{toroco_events, Ref, [Event]}' (a
%% `{dropped, N}' among them): for a subscriber that takes many events,
%% one wake-up and one message per batch instead of one per event.
-spec subscribe_events(toroco_tap:opts()) -> {ok, reference()} | {error, error_reason()}.
subscribe_events(Opts) ->
    %% A robot on several nodes: the other nodes' events come through a
    %% relay on each (toroco_tap_relay).
    case toroco_tap:subscribe(Opts) of
        {ok, Ref} ->
            _ = case [N || N <- toroco_wiring:peers(), N =/= node()] of
                    [] -> ok;
                    Others -> erpc:multicall(Others, toroco_tap_relay, start,
                                             [toroco_tap:feeder(Ref), Ref, Opts], 6000)
                end,
            {ok, Ref};
        Err -> Err
    end.

%% @doc Ends a subscription. Every event this node's processes emitted
%% before the call is in the subscriber's mailbox (or counted in a
%% `{dropped, N}' there) when it returns, and none comes after.
-spec unsubscribe_events(reference()) -> ok.
unsubscribe_events(Ref) ->
    ok = toroco_tap:unsubscribe(Ref),
    toroco_tap_relay:stop(Ref).

%% @doc Returns once every event this node's processes emitted before the
%% call is in the subscriber's mailbox, or counted in a `{dropped, N}'
%% there: a subscriber that is about to stop, write or count what it got
%% takes the rest with a `receive ... after 0'. The calling process's own
%% events, if it is a behavior, are not waited for.
-spec flush_events(reference()) -> ok | {error, error_reason()}.
flush_events(Ref) ->
    toroco_tap:sync(Ref).

%% @doc Hands a simulated world's snapshot to every subscriber in this node
%% ({@link subscribe_world/0}), as `{toroco_world, Snapshot}': one plain
%% send each, so the world never waits. Given a fun, calls it for the
%% snapshot only when there is a subscriber. Nothing, and no error, without
%% subscribers or without the runtime in this node.
-spec publish_world(world_snapshot() | fun(() -> world_snapshot())) -> ok.
publish_world(Snapshot) when is_map(Snapshot); is_function(Snapshot, 0) ->
    case world_subscribers() of
        [] ->
            ok;
        Pids ->
            Message = {toroco_world, case Snapshot of
                                         _ when is_map(Snapshot) -> Snapshot;
                                         _ -> Snapshot()
                                     end},
            lists:foreach(fun(Pid) -> Pid ! Message end, Pids)
    end.

world_subscribers() ->
    case erlang:whereis(?WORLD_SCOPE) of
        undefined -> [];
        _ -> pg:get_local_members(?WORLD_SCOPE, world)
    end.

%% @doc The caller gets `{toroco_world, Snapshot}' for each snapshot a world
%% in this node publishes, until it unsubscribes or ends; subscribing twice
%% is subscribing once. `Ref' monitors the runtime's side of the
%% subscription: `{'DOWN', Ref, process, _, _}' says it is gone (the runtime
%% stopped or restarted), and a caller that still wants snapshots subscribes
%% again. `{error, {not_running, toroco}}' without the runtime.
-spec subscribe_world() -> {ok, reference()} | {error, error_reason()}.
subscribe_world() ->
    case erlang:whereis(?WORLD_SCOPE) of
        undefined ->
            {error, {not_running, toroco}};
        Scope ->
            Ref = monitor(process, Scope),
            ok = case lists:member(self(), world_subscribers()) of
                     true -> ok;
                     false -> pg:join(?WORLD_SCOPE, world, self())
                 end,
            {ok, Ref}
    end.

%% @doc No more snapshots for the caller (none that were published before
%% the call is taken back), and no `DOWN' for `Ref'.
-spec unsubscribe_world(reference()) -> ok.
unsubscribe_world(Ref) ->
    demonitor(Ref, [flush]),
    case erlang:whereis(?WORLD_SCOPE) of
        undefined ->
            ok;
        _ ->
            _ = pg:leave(?WORLD_SCOPE, world, self()),
            ok
    end.
