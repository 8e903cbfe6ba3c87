%% @doc Torocó's public API: build a subsumption network of behaviors and
%% devices, wire it, drive it and look inside it while it runs.
%%
%% <b>Nodes</b>: {@link add_behavior/3}, {@link add_device/3}, {@link
%% remove_behavior/1}, {@link remove_device/1}, {@link suspend_behavior/1},
%% {@link resume_behavior/1}.
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
%% {@link unsubscribe_events/1}.
%%
%% Every call returns `ok' or `{error, Reason}' with a reason naming the
%% offending behavior, device, input or output; a refused wiring change
%% changes nothing. The semantics are those of SPEC §4.
-module(toroco).

-export([add_behavior/3, add_device/3, remove_behavior/1, remove_device/1,
         suspend_behavior/1, resume_behavior/1,
         set_inputs/2, set_inhibitors/2, set_reset/2, load_wiring/1,
         inject/2, inject/3, inspect/0, inspect/1,
         top/0, watch/2, unwatch/0, wiring_dot/0, reload/1,
         subscribe_events/1, unsubscribe_events/1]).

-export_type([name/0, source/0, source_spec/0, input_spec/0, behavior_opts/0,
              hold/0, error_reason/0]).

-type name() :: atom().

%% Whether the caller is the process of behavior or device `Name': a
%% callback that injects into its own output would wait on itself.
-define(IS_SELF(Name), (whereis(toroco_names:process(Name)) =:= self())).
-type source() :: {Emitter :: name(), Output :: atom()}.
-type hold() :: non_neg_integer() | infinity.
-type source_spec() :: source() | {Emitter :: name(), Output :: atom(), #{hold => hold()}}.
-type input_spec() :: [source_spec()]
                    | #{sources := [source_spec()], buffer => all | latest, idle => term()}.
-type behavior_opts() :: #{layer => non_neg_integer(), params => map()}.
-type error_reason() :: term().

%%====================================================================
%% Nodes
%%====================================================================

%% @doc Starts behavior `Name' running callback module `Module' in its layer.
-spec add_behavior(name(), module(), behavior_opts()) -> ok | {error, error_reason()}.
add_behavior(Name, Module, Opts) ->
    toroco_wiring:call({add, behavior, Name, Module, Opts}).

%% @doc Starts device `Name' (a `toroco_device' module) with `Opts'.
-spec add_device(name(), module(), map()) -> ok | {error, error_reason()}.
add_device(Name, Module, Opts) ->
    toroco_wiring:call({add, device, Name, Module, Opts}).

%% @doc Stops a behavior and strips it from every input and inhibitor list.
-spec remove_behavior(name()) -> ok | {error, error_reason()}.
remove_behavior(Name) ->
    toroco_wiring:call({remove, behavior, Name}).

%% @doc Stops a device and strips it from every input and inhibitor list.
-spec remove_device(name()) -> ok | {error, error_reason()}.
remove_device(Name) ->
    toroco_wiring:call({remove, device, Name}).

%% @doc Stops input delivery and callbacks of a behavior; its latches and
%% holds stay. Inputs arriving while suspended are dropped.
-spec suspend_behavior(name()) -> ok | {error, error_reason()}.
suspend_behavior(Name) ->
    with_behavior(Name, fun toroco_behavior:suspend/1).

%% @doc Resumes a suspended behavior; each input's latched winner is
%% re-delivered to it.
-spec resume_behavior(name()) -> ok | {error, error_reason()}.
resume_behavior(Name) ->
    with_behavior(Name, fun toroco_behavior:resume/1).

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
    toroco_wiring:call({set_inputs, Receiver, Inputs}).

%% @doc Sets the inhibitors of outputs of `Emitter'; `[]' removes them.
-spec set_inhibitors(name(), #{atom() => [source_spec()]}) -> ok | {error, error_reason()}.
set_inhibitors(Emitter, Outputs) ->
    toroco_wiring:call({set_inhibitors, Emitter, Outputs}).

%% @doc Each event on one of `Sources' restarts `Behavior' from `init/1'.
-spec set_reset(name(), [source_spec()]) -> ok | {error, error_reason()}.
set_reset(Behavior, Sources) ->
    toroco_wiring:call({set_reset, Behavior, Sources}).

%% @doc Applies a wiring file: `file:consult/1' terms among
%% `{behavior, Name, Module, Opts}', `{device, Name, Module, Opts}',
%% `{inputs, Receiver, Map}', `{inhibitors, Emitter, Map}' and
%% `{reset, Behavior, Sources}', validated as a whole before anything starts.
-spec load_wiring(file:name_all()) -> ok | {error, error_reason()}.
load_wiring(File) ->
    case file:consult(File) of
        {ok, Terms} -> toroco_wiring:call({load, Terms});
        {error, Reason} -> {error, {wiring_file, File, Reason}}
    end.

%%====================================================================
%% Driving
%%====================================================================

%% @doc As if `Src' had sent `Value' (a momentary event, no hold).
-spec inject(source(), term()) -> ok | {error, error_reason()}.
inject(Src, Value) ->
    inject(Src, Value, #{}).

%% @doc As if `Src' had emitted `Value': `#{latch => true}' is a `set',
%% `#{hold => H}' a `send' with that hold.
-spec inject(source(), term(), #{latch => boolean(), hold => hold()}) ->
          ok | {error, error_reason()}.
inject({E, Out} = Src, Value, Opts) when is_atom(E), is_atom(Out), is_map(Opts) ->
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
inject(Src, _Value, Opts) when is_map(Opts) ->
    {error, {bad_source, Src}};
inject(Src, _Value, Opts) ->
    {error, {bad_option, {Src, Opts}}}.

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
    toroco_inspect:describe(Name).

%% @doc Prints a table of the running network (for the remote shell).
-spec top() -> ok.
top() ->
    toroco_top:print().

%% @doc Prints deliveries to an input (`{Receiver, Input}') or to every input
%% of a behavior, live, until `max' events (default 100) or `seconds' (default
%% 60) or a rate above `rate' per second (default 50) stop it.
-spec watch(name() | {name(), atom()}, map()) -> ok | {error, error_reason()}.
watch(What, Opts) ->
    toroco_watch:start(What, Opts).

%% @doc Stops a running watch.
-spec unwatch() -> ok.
unwatch() ->
    toroco_watch:stop().

%% @doc The wiring as a Graphviz `dot' graph.
-spec wiring_dot() -> iodata().
wiring_dot() ->
    toroco_dot:wiring().

%% @doc Hot code reload of every behavior running `Module'.
-spec reload(module()) -> ok | {error, error_reason()}.
reload(Module) ->
    toroco_reload:reload(Module).

%%====================================================================
%% Observing the event path
%%====================================================================

%% @doc Subscribes the calling process to the event path: it receives
%% `{toroco_event, Ref, Event}' for the events of `kinds' (`emit',
%% `deliver', `router', `lifecycle'; default all) about `names' (default
%% `all'), with at most `buffer' (default 10000) pending; past that, events
%% are counted and reported as `{dropped, N}' (SPEC §10). A subscriber that
%% dies is unsubscribed.
-spec subscribe_events(toroco_tap:opts()) -> {ok, reference()} | {error, error_reason()}.
subscribe_events(Opts) ->
    toroco_tap:subscribe(Opts).

%% @doc Ends a subscription.
-spec unsubscribe_events(reference()) -> ok.
unsubscribe_events(Ref) ->
    toroco_tap:unsubscribe(Ref).
