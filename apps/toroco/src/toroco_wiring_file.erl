%% @doc The terms of a wiring file (`toroco:load_wiring/1'), and of the
%% requests of `toroco' that add one behavior or device, as the wiring
%% server takes them in: checked against a wiring, without starting
%% anything. `toroco_wiring' starts what they name once the whole is valid.
%%
%% A behavior or device term `{Kind, Name, Module, Opts}' gives the spec its
%% process is started from (`toroco_behavior:child_spec/1') and what its
%% module declares (the node's entry in `toroco_wiring_core'); the wiring
%% terms (`{inputs, R, Map}', `{inhibitors, E, Map}', `{reset, B, Srcs}')
%% are the changes of `toroco_wiring_core'.
-module(toroco_wiring_file).

-export([node/4, validate/2, summary/1]).
-export_type([summary/0]).

-compile({no_auto_import, [node/1]}).

-type spec() :: toroco_behavior:spec().

%% What a wiring file adds (`toroco:read_wiring/1'): its behaviors and
%% devices in the file's order, each one's module, the inputs it wires
%% (`{Receiver, Input}'), the nodes other than this one it places things
%% on (SPEC §13) and where each of those things goes (`placement').
-type summary() :: #{behaviors := [atom()], devices := [atom()],
                     modules := #{atom() => module()}, inputs := [{atom(), atom()}],
                     nodes := [node()], placement := #{atom() => node()}}.

%% @doc A behavior or device term: the spec its process is started from and
%% its entry in the wiring, or an error naming it.
-spec node(behavior | device, term(), term(), term()) ->
          {ok, spec(), toroco_wiring_core:node_info()} | {error, term()}.
node(Kind, Name, Module, Opts) ->
    case node_spec(Kind, Name, Module, Opts) of
        {ok, Spec = #{layer := L, args := Args}} ->
            case interface(Kind, Name, Module, Args) of
                {ok, Ports} -> {ok, Spec, Ports#{kind => Kind, module => Module, layer => L}};
                Err -> Err
            end;
        Err -> Err
    end.

%% @doc What a file's terms add, read from them alone (nothing checked
%% against a running wiring: `validate/2' does that as they load).
-spec summary([term()]) -> summary().
summary(Terms) ->
    Added = [{Kind, Name, Module, Opts} || {Kind, Name, Module, Opts} <- Terms,
                                           Kind =:= behavior orelse Kind =:= device,
                                           is_atom(Name)],
    #{behaviors => [N || {behavior, N, _, _} <- Added],
      devices => [N || {device, N, _, _} <- Added],
      modules => maps:from_list([{N, M} || {_, N, M, _} <- Added]),
      inputs => lists:usort([{R, I} || {inputs, R, M} <- Terms, is_map(M), I <- maps:keys(M)]),
      nodes => lists:usort([N || {_, _, _, #{node := N}} <- Added, N =/= node()]),
      placement => maps:from_list([{Name, N} || {_, Name, _, #{node := N}} <- Added,
                                                N =/= node()])}.

%% @doc A file's terms checked in order against `W': the wiring they make
%% and the specs of the behaviors and devices to start, in the file's order.
-spec validate([term()], toroco_wiring_core:wiring()) ->
          {ok, toroco_wiring_core:wiring(), [spec()]} | {error, term()}.
validate(Terms, W) ->
    validate(Terms, W, []).

validate([], W, Specs) ->
    {ok, W, lists:reverse(Specs)};
validate([{Kind, Name, Module, Opts} | Ts], W, Specs) when Kind =:= behavior; Kind =:= device ->
    case node(Kind, Name, Module, Opts) of
        {ok, Spec, Info} ->
            case toroco_wiring_core:add_node(W, Name, Info) of
                {ok, W1} -> validate(Ts, W1, [Spec | Specs]);
                Err -> Err
            end;
        Err -> Err
    end;
validate([T | Ts], W, Specs) ->
    case change(T, W) of
        {ok, W1} -> validate(Ts, W1, Specs);
        Err -> Err
    end.

change({inputs, R, Map}, W) -> toroco_wiring_core:set_inputs(W, R, Map);
change({inhibitors, E, Map}, W) -> toroco_wiring_core:set_inhibitors(W, E, Map);
change({reset, B, Srcs}, W) -> toroco_wiring_core:set_reset(W, B, Srcs);
change(Other, _W) -> {error, {bad_wiring_term, Other}}.

node_spec(_Kind, Name, _Module, _Opts) when not is_atom(Name) ->
    {error, {bad_name, Name}};
node_spec(_Kind, Name, Module, _Opts) when not is_atom(Module) ->
    {error, {bad_module, {Name, Module}}};
node_spec(_Kind, Name, _Module, Opts) when not is_map(Opts) ->
    {error, {bad_options, {Name, Opts}}};
node_spec(device, Name, Module, Opts) ->
    {ok, toroco_device:spec(Name, Module, Opts)};
node_spec(behavior, Name, Module, Opts) ->
    case toroco_behavior:configured(Module) of
        true -> configured_spec(Name, Module, Opts);
        false -> plain_spec(Name, Module, Opts)
    end.

%% A module whose ports depend on its options (`interface/1'): it gets them
%% all but the layer, `params' included.
configured_spec(Name, Module, Opts) ->
    case maps:get(layer, Opts, 0) of
        L when is_integer(L), L >= 0 ->
            {ok, #{kind => behavior, name => Name, module => Module, layer => L,
                   args => maps:remove(layer, Opts)}};
        L ->
            {error, {bad_layer, {Name, L}}}
    end.

plain_spec(Name, Module, Opts) ->
    case {maps:keys(maps:without([layer, params], Opts)), maps:get(layer, Opts, 0),
          maps:get(params, Opts, #{})} of
        {[Bad | _], _, _} -> {error, {bad_option, {Name, Bad}}};
        {[], L, _} when not is_integer(L); L < 0 -> {error, {bad_layer, {Name, L}}};
        {[], _, P} when not is_map(P) -> {error, {bad_params, {Name, P}}};
        {[], L, P} ->
            {ok, #{kind => behavior, name => Name, module => Module, layer => L, args => P}}
    end.

%% A module's interface, with the node named in the error if it has none.
interface(Kind, Name, Module, Args) ->
    case toroco_behavior:interface(Kind, Module, Args) of
        {error, {bad_interface, {Module, Detail}}} -> {error, {bad_interface, {Name, Module, Detail}}};
        Other -> Other
    end.
