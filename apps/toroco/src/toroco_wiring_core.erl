%% @doc The wiring as data: validation of every change and the plan of
%% processes it implies. Pure; `toroco_wiring' is the server that holds one
%% value of this and applies the plans.
%%
%% A wiring knows the nodes (behaviors and devices, with their layer and
%% declared inputs and outputs), each wired input's sources in priority order,
%% each inhibited output's inhibitors and each behavior's reset sources. A change
%% ({@link set_inputs/3}, {@link set_inhibitors/3}, {@link set_reset/3}, {@link
%% add_node/3}, {@link remove_node/2}) is validated completely and returns
%% `{ok, Wiring}' or `{error, Reason}' naming the culprit; nothing is half-done.
%%
%% {@link plan/1} turns a wiring into the processes that carry it: one router
%% per wired input, one gate per group of inhibited outputs (a group is two
%% outputs of one layer that inhibit each other, or a single output), and for
%% every emitter the consumers each of its outputs must be sent to.
%%
%% Open ports: a node whose info has `open => true' (a Lua behavior, as in
%% the original Torocó) has every input a change names and every output a
%% source names; the change adds them to its declared ones.
%%
%% Several nodes (SPEC §13): a wiring holds the behaviors and devices of its
%% own node (`nodes') and what it was told of the other nodes' (`remote',
%% each with its `node' and the gates of its outputs, `gated'). Remote names
%% count for validation (a name is unique across nodes, hierarchy uses
%% remote layers) and for the plan (a remote source's upstream is addressed
%% `{Reg, Node}'); only local ones are started here. A remote name stays
%% known while its node is away, so the wiring survives a partition; it is
%% forgotten when its node removes it.
-module(toroco_wiring_core).

-compile({no_auto_import, [node/2]}).
-export([new/0, add_node/3, remove_node/2, node/2, nodes/1,
         set_inputs/3, set_inhibitors/3, set_reset/3,
         inputs_of/2, inhibitors_of/2, gates/1, plan/1,
         remote/1, set_remote/3, directory/1, restore/4]).
-export_type([wiring/0, node_info/0, plan/0, router_config/0, gate_config/0]).

-type name() :: atom().
-type source() :: {name(), atom()}.
-type default() :: non_neg_integer() | infinity.
-type node_info() :: #{kind := behavior | device, module := module(), layer := non_neg_integer(),
                       inputs := [atom()], outputs := [atom()], open => boolean()}.
-type input_spec() :: #{sources := [{source(), default()}], buffer := all | latest,
                        idle := toroco_router_core:latch()}.
-type remote_info() :: #{kind := behavior | device, module := module(), layer := non_neg_integer(),
                         inputs := [atom()], outputs := [atom()], node := node(),
                         gated := #{atom() => source()}}.
-opaque wiring() :: #{nodes := #{name() => node_info()},
                    remote => #{name() => remote_info()},
                    inputs := #{{name(), atom()} => input_spec()},
                    inhibitors := #{source() => [{source(), default()}]}}.
-type upstream() :: {emitter | gate, atom() | {atom(), node()}}.
-type router_config() :: #{reg := atom(), receiver := name(), input := atom(),
                           receiver_reg := atom(), sources := [{source(), default()}],
                           upstreams := #{source() => upstream()},
                           buffer := all | latest, idle := toroco_router_core:latch(),
                           max_age => #{source() => pos_integer()}}.
-type gate_config() :: #{reg := atom(), members := [source()],
                         entries := #{source() => [{source(), default()}]},
                         upstreams := #{source() => upstream()},
                         subs := #{source() => [atom()]}}.
-type plan() :: #{routers := #{{name(), atom()} => router_config()},
                  gates := #{source() => gate_config()},
                  subs := #{name() => #{atom() => [atom()]}}}.

-define(RESET, '$reset').

%%====================================================================
%% Nodes
%%====================================================================

-spec new() -> wiring().
new() -> #{nodes => #{}, inputs => #{}, inhibitors => #{}, remote => #{}}.

%% @doc A wiring read back from what was kept of it: its nodes, the
%% configurations of its routers and gates as {@link plan/1} made them
%% (the keys a consumer keeps of them are enough) and what the other nodes
%% told of theirs.
-spec restore(#{name() => node_info()}, [{{name(), atom()}, map()}], [map()],
              #{name() => remote_info()}) -> wiring().
restore(Nodes, Routers, Gates, Remote) ->
    #{nodes => Nodes,
      inputs => maps:from_list([{K, maps:with([sources, buffer, idle, max_age], Cfg)}
                                || {K, Cfg} <- Routers]),
      inhibitors => lists:foldl(fun(#{entries := Es}, Acc) -> maps:merge(Acc, Es) end,
                                #{}, Gates),
      remote => Remote}.

-spec add_node(wiring(), name(), node_info()) -> {ok, wiring()} | {error, term()}.
add_node(W = #{nodes := Nodes}, Name, Info) ->
    case {Nodes, remote(W)} of
        {#{Name := _}, _} -> {error, {duplicate_name, Name}};
        {_, #{Name := #{node := N}}} -> {error, {name_taken, Name, N}};
        _ -> {ok, W#{nodes := Nodes#{Name => Info}}}
    end.

%%====================================================================
%% Other nodes
%%====================================================================

%% @doc The behaviors and devices known on other nodes.
-spec remote(wiring()) -> #{name() => remote_info()}.
remote(W) -> maps:get(remote, W, #{}).

%% @doc What node `Node' says it runs: its names with their ports, layers and
%% gates; `removed' lists the names it removed, which leave every input and
%% inhibitor list here. A name of this node that it also claims is not taken
%% in: it is returned as a clash.
-spec set_remote(wiring(), node(), #{nodes := #{name() => map()}, removed := [name()]}) ->
          {wiring(), [name()]}.
set_remote(W = #{nodes := Local}, Node, #{nodes := Infos, removed := Removed}) ->
    Clashes = [N || N <- maps:keys(Infos), maps:is_key(N, Local)],
    R0 = maps:filter(fun(N, #{node := At}) -> not (At =:= Node andalso lists:member(N, Removed)) end,
                     remote(W)),
    R1 = maps:merge(R0, maps:map(fun(_, I) -> I#{node => Node} end, maps:without(Clashes, Infos))),
    W1 = lists:foldl(fun(N, Acc) ->
                             case remote(W) of
                                 #{N := #{node := Node}} -> strip(Acc, N);
                                 #{} -> Acc
                             end
                     end, W#{remote => R1}, Removed),
    {W1, Clashes}.

%% @doc What this node tells the others of itself: its names with ports,
%% layers and the gates of their outputs.
-spec directory(wiring()) -> #{name() => map()}.
directory(W = #{nodes := Nodes}) ->
    Gates = gates(W),
    maps:map(fun(N, Info) ->
                     Info#{gated => maps:from_list([{O, K} || {{E, O}, K} <- maps:to_list(Gates),
                                                              E =:= N])}
             end, Nodes).

%% @doc Forgets a node and strips it from every input and inhibitor list;
%% inputs and inhibited outputs left without sources are unwired.
-spec remove_node(wiring(), name()) -> {ok, wiring()} | {error, term()}.
remove_node(W = #{nodes := Nodes}, Name) ->
    case Nodes of
        #{Name := _} -> {ok, (strip(W, Name))#{nodes := maps:remove(Name, Nodes)}};
        #{} -> {error, {unknown_name, Name}}
    end.

%% Strips a name from every input and inhibitor list.
strip(W = #{inputs := Inputs, inhibitors := Inhs}, Name) ->
            Strip = fun(Srcs) -> [E || E = {{N, _}, _} <- Srcs, N =/= Name] end,
            Inputs1 = maps:filtermap(
                        fun({R, _}, _) when R =:= Name -> false;
                           (_, Spec = #{sources := Srcs}) ->
                                case Strip(Srcs) of
                                    [] -> false;
                                    Srcs1 -> {true, Spec#{sources := Srcs1}}
                                end
                        end, Inputs),
            Inhs1 = maps:filtermap(
                      fun({E, _}, _) when E =:= Name -> false;
                         (_, Srcs) ->
                              case Strip(Srcs) of
                                  [] -> false;
                                  Srcs1 -> {true, Srcs1}
                              end
                      end, Inhs),
            W#{inputs := Inputs1, inhibitors := Inhs1,
               remote => maps:remove(Name, remote(W))}.

-spec node(wiring(), name()) -> {ok, node_info()} | {error, term()}.
node(W = #{nodes := Nodes}, Name) ->
    case {Nodes, remote(W)} of
        {#{Name := Info}, _} -> {ok, Info};
        {_, #{Name := Info}} -> {ok, Info};
        _ -> {error, {unknown_name, Name}}
    end.

-spec nodes(wiring()) -> #{name() => node_info()}.
nodes(#{nodes := Nodes}) -> Nodes.

%% @doc The wired inputs of a receiver (the reset input included).
-spec inputs_of(wiring(), name()) -> #{atom() => input_spec()}.
inputs_of(#{inputs := Inputs}, R) ->
    maps:from_list([{I, Spec} || {{R1, I}, Spec} <- maps:to_list(Inputs), R1 =:= R]).

-spec inhibitors_of(wiring(), source()) -> [{source(), default()}].
inhibitors_of(#{inhibitors := Inhs}, Src) -> maps:get(Src, Inhs, []).

%%====================================================================
%% Changes
%%====================================================================

%% @doc Replaces the listed inputs of `R'; `[]' unwires an input.
-spec set_inputs(wiring(), name(), term()) -> {ok, wiring()} | {error, term()}.
set_inputs(W0, R, Map) when is_map(Map) ->
    W = open_ports(W0, [{R, inputs, maps:keys(Map)}
                        | [{E, outputs, [O]} || Spec <- maps:values(Map), {E, O} <- named(Spec)]]),
    maybe_all(W, R, fun(Info) ->
        fold_ok(fun({Input, Spec}, Acc) ->
                        case lists:member(Input, maps:get(inputs, Info)) of
                            true -> wire_input(Acc, R, Input, Spec);
                            false -> {error, {unknown_input, {R, Input}}}
                        end
                end, W, lists:sort(maps:to_list(Map)))
    end);
set_inputs(_W, R, Other) ->
    {error, {bad_inputs, {R, Other}}}.

%% @doc Replaces the inhibitor lists of the listed outputs of `E'.
-spec set_inhibitors(wiring(), name(), term()) -> {ok, wiring()} | {error, term()}.
set_inhibitors(W0, E, Map) when is_map(Map) ->
    W = open_ports(W0, [{E, outputs, maps:keys(Map)}
                        | [{I, outputs, [O]} || Spec <- maps:values(Map), {I, O} <- named(Spec)]]),
    maybe_all(W, E, fun(Info) ->
        Changed = fold_ok(
                    fun({Out, Spec}, Acc = #{inhibitors := Inhs}) ->
                            case lists:member(Out, maps:get(outputs, Info)) of
                                false -> {error, {unknown_output, {E, Out}}};
                                true ->
                                    case sources({E, Out}, Spec, W) of
                                        {ok, []} ->
                                            {ok, Acc#{inhibitors := maps:remove({E, Out}, Inhs)}};
                                        {ok, Srcs} ->
                                            case inhibitor_hierarchy(W, {E, Out}, Srcs) of
                                                ok -> {ok, Acc#{inhibitors := Inhs#{{E, Out} => Srcs}}};
                                                Err -> Err
                                            end;
                                        Err -> Err
                                    end
                            end
                    end, W, lists:sort(maps:to_list(Map))),
        case Changed of
            {ok, W1} ->
                case check_cycles(W1) of
                    ok -> {ok, W1};
                    Err -> Err
                end;
            Err -> Err
        end
    end);
set_inhibitors(_W, E, Other) ->
    {error, {bad_inhibitors, {E, Other}}}.

%% @doc Brooks' reset: each event on one of `Srcs' restarts behavior `B'.
-spec set_reset(wiring(), name(), term()) -> {ok, wiring()} | {error, term()}.
set_reset(W0, B, Srcs) when is_list(Srcs) ->
    W = open_ports(W0, [{E, outputs, [O]} || {E, O} <- named(Srcs)]),
    maybe_all(W, B, fun(#{kind := behavior}) -> wire_input(W, B, ?RESET, Srcs);
                       (#{kind := device}) -> {error, {not_a_behavior, B}}
                    end);
set_reset(_W, B, Other) ->
    {error, {bad_reset, {B, Other}}}.

%% The ports a change names, added to the open nodes that lack them (other
%% nodes are left to the checks that follow).
open_ports(W = #{nodes := Nodes}, Named) ->
    Nodes1 = lists:foldl(
               fun({Name, Kind, Ports}, Acc) ->
                       case Acc of
                           #{Name := Info = #{open := true}} ->
                               Have = maps:get(Kind, Info),
                               New = [P || P <- Ports, is_atom(P), not lists:member(P, Have)],
                               Acc#{Name := Info#{Kind := Have ++ lists:usort(New)}};
                           #{} -> Acc
                       end
               end, Nodes, Named),
    W#{nodes := Nodes1}.

%% The sources an input or inhibitor spec names, well formed or not.
named(#{sources := Srcs}) -> named(Srcs);
named(Srcs) when is_list(Srcs) ->
    [{E, O} || S <- Srcs, {E, O} <- [source_name(S)]];
named(_) -> [].

source_name({E, O}) when is_atom(E), is_atom(O) -> {E, O};
source_name({E, O, _}) when is_atom(E), is_atom(O) -> {E, O};
source_name(_) -> none.

maybe_all(W, Name, Fun) ->
    case node(W, Name) of
        {ok, Info} -> Fun(Info);
        Err -> Err
    end.

wire_input(W = #{inputs := Inputs}, R, Input, Spec) ->
    case input_spec({R, Input}, Spec, W) of
        {ok, #{sources := []}} ->
            {ok, W#{inputs := maps:remove({R, Input}, Inputs)}};
        {ok, Norm = #{sources := Srcs}} ->
            case input_hierarchy(W, {R, Input}, Srcs) of
                ok -> {ok, W#{inputs := Inputs#{{R, Input} => Norm}}};
                Err -> Err
            end;
        Err -> Err
    end.

input_spec(Where, Srcs, W) when is_list(Srcs) ->
    input_spec(Where, #{sources => Srcs}, W);
input_spec(Where, Spec, W) when is_map(Spec) ->
    case maps:keys(maps:without([sources, buffer, idle], Spec)) of
        [Bad | _] -> {error, {bad_option, {Where, Bad}}};
        [] ->
            Buffer = maps:get(buffer, Spec, all),
            case lists:member(Buffer, [all, latest]) of
                false -> {error, {bad_option, {Where, {buffer, Buffer}}}};
                true ->
                    case sources(Where, maps:get(sources, Spec, []), W) of
                        {ok, Srcs} ->
                            Idle = case Spec of
                                       #{idle := V} -> {value, V};
                                       #{} -> none
                                   end,
                            Ages = maps:from_list([{{E, O}, A} || {E, O, #{max_age := A}}
                                                                      <- maps:get(sources, Spec, [])]),
                            {ok, with_ages(#{sources => Srcs, buffer => Buffer, idle => Idle},
                                           Ages)};
                        Err -> Err
                    end
            end
    end;
input_spec(Where, Other, _W) ->
    {error, {bad_input_spec, {Where, Other}}}.

%% Normalises a source list to [{Src, DefaultHold}] and checks each entry.
sources(Where, Srcs, W) when is_list(Srcs) ->
    case fold_ok(fun(Entry, Acc) ->
                         case source(Entry, W) of
                             {ok, {Src, _} = E} ->
                                 case lists:keymember(Src, 1, Acc) of
                                     true -> {error, {duplicate_source, {Where, Src}}};
                                     false -> {ok, [E | Acc]}
                                 end;
                             Err -> Err
                         end
                 end, [], Srcs) of
        {ok, Rev} -> {ok, lists:reverse(Rev)};
        Err -> Err
    end;
sources(Where, Other, _W) ->
    {error, {bad_sources, {Where, Other}}}.

source({E, Out}, W) when is_atom(E), is_atom(Out) ->
    source({E, Out, #{}}, W);
source({E, Out, Opts}, W) when is_atom(E), is_atom(Out), is_map(Opts) ->
    case node(W, E) of
        {error, _} = Err -> Err;
        {ok, #{outputs := Outs}} ->
            case {lists:member(Out, Outs), maps:keys(maps:without([hold, max_age], Opts)),
                  maps:get(max_age, Opts, 1)} of
                {false, _, _} -> {error, {unknown_output, {E, Out}}};
                {true, [Bad | _], _} -> {error, {bad_option, {{E, Out}, Bad}}};
                {true, [], A} when not is_integer(A); A =< 0 ->
                    {error, {bad_max_age, {{E, Out}, A}}};
                {true, [], _} ->
                    case maps:get(hold, Opts, 0) of
                        H when (is_integer(H) andalso H >= 0) orelse H =:= infinity ->
                            {ok, {{E, Out}, H}};
                        H -> {error, {bad_hold, {{E, Out}, H}}}
                    end
            end
    end;
source(Other, _W) ->
    {error, {bad_source, Other}}.

%% Max ages are kept only where a wire has one (most have none).
with_ages(Spec, Ages) when map_size(Ages) =:= 0 -> Spec;
with_ages(Spec, Ages) -> Spec#{max_age => Ages}.

fold_ok(_Fun, Acc, []) -> {ok, Acc};
fold_ok(Fun, Acc, [X | Xs]) ->
    case Fun(X, Acc) of
        {ok, Acc1} -> fold_ok(Fun, Acc1, Xs);
        Err -> Err
    end.

%%====================================================================
%% Hierarchy and cycles
%%====================================================================

layer(W, {E, _}) ->
    {ok, #{layer := L}} = node(W, E),
    L.

%% Highest priority first: a source may not sit above one of a higher layer.
input_hierarchy(_W, _Where, []) -> ok;
input_hierarchy(W, Where, [{Si, _} | Rest]) ->
    Li = layer(W, Si),
    case [{Sj, Lj} || {Sj, _} <- Rest, (Lj = layer(W, Sj)) > Li] of
        [] -> input_hierarchy(W, Where, Rest);
        [{Sj, Lj} | _] -> {error, {hierarchy, {Where, {Si, Li}, {Sj, Lj}}}}
    end.

inhibitor_hierarchy(W, Out, Srcs) ->
    LE = layer(W, Out),
    case [{I, LI} || {I, _} <- Srcs, (LI = layer(W, I)) < LE] of
        [] -> ok;
        [{I, LI} | _] -> {error, {hierarchy, {Out, {inhibitor, I, LI}, {emitter, Out, LE}}}}
    end.

%% Any cycle of inhibitions is refused, except outputs of one layer that inhibit
%% each other in pairs (every edge mutual, no ring of three or more).
check_cycles(W = #{inhibitors := Inhs}) ->
    Edges = [{I, O} || {O, Srcs} <- maps:to_list(Inhs), {I, _} <- Srcs],
    G = digraph:new(),
    try
        _ = [digraph:add_vertex(G, V) || {A, B} <- Edges, V <- [A, B]],
        _ = [digraph:add_edge(G, A, B) || {A, B} <- Edges],
        Bad = [C || C <- digraph_utils:cyclic_strong_components(G),
                    not allowed_component(W, lists:sort(C), Edges)],
        case Bad of
            [] -> ok;
            [C | _] -> {error, {inhibition_cycle, lists:sort(C)}}
        end
    after
        digraph:delete(G)
    end.

allowed_component(_W, [_], _Edges) -> false;  % an output inhibiting itself
allowed_component(W, Members, Edges) ->
    Inside = lists:usort([{A, B} || {A, B} <- Edges, lists:member(A, Members),
                                    lists:member(B, Members)]),
    Mutual = lists:all(fun({A, B}) -> lists:member({B, A}, Inside) end, Inside),
    [L | Ls] = [layer(W, M) || M <- Members],
    Mutual andalso lists:all(fun(X) -> X =:= L end, Ls)
        andalso length(Inside) div 2 =:= length(Members) - 1.

%%====================================================================
%% Plan
%%====================================================================

%% @doc The processes a wiring needs and what each emitter sends where.
-spec plan(wiring()) -> plan().
plan(W = #{inputs := Inputs, inhibitors := Inhs}) ->
    Groups = groups(Inhs),
    GateOf = maps:from_list([{M, Key} || {Key, Ms} <- maps:to_list(Groups), M <- Ms]),
    Remote = remote(W),
    Upstream = fun(Src = {E, Out}, Self) ->
                       case {GateOf, Remote} of
                           {#{Src := Key}, _} when Key =/= Self -> {gate, toroco_names:gate(Key)};
                           {_, #{E := #{node := N, gated := #{Out := Key}}}} ->
                               {gate, {toroco_names:gate(Key), N}};
                           {_, #{E := #{node := N}}} -> {emitter, {toroco_names:process(E), N}};
                           _ -> {emitter, toroco_names:process(E)}
                       end
               end,
    Routers = maps:map(
                fun({R, I}, Spec = #{sources := Srcs, buffer := B, idle := Idle}) ->
                        with_ages(#{reg => toroco_names:router(R, I), receiver => R, input => I,
                                    receiver_reg => toroco_names:process(R), sources => Srcs,
                                    upstreams => maps:from_list([{S, Upstream(S, none)}
                                                                 || {S, _} <- Srcs]),
                                    buffer => B, idle => Idle},
                                  maps:get(max_age, Spec, #{}))
                end, Inputs),
    Gates0 = maps:map(
               fun(Key, Members) ->
                       Entries = maps:from_list([{M, maps:get(M, Inhs)} || M <- Members]),
                       Srcs = lists:usort(Members ++ [I || {_, L} <- maps:to_list(Entries),
                                                           {I, _} <- L]),
                       #{reg => toroco_names:gate(Key), members => Members, entries => Entries,
                         upstreams => maps:from_list([{S, Upstream(S, Key)} || S <- Srcs]),
                         subs => #{}}
               end, Groups),
    Consumers = [{Reg, Ups} || #{reg := Reg, upstreams := Ups} <- maps:values(Routers)]
        ++ [{Reg, Ups} || #{reg := Reg, upstreams := Ups} <- maps:values(Gates0)],
    {Subs, Gates} =
        lists:foldl(
          fun({Reg, Ups}, Acc) ->
                  %% A remote upstream learns of its consumers by their subscription.
                  maps:fold(fun(_Src, {_, {_, _}}, Acc1) -> Acc1;
                               ({E, Out}, {emitter, _}, {SAcc, GAcc}) ->
                                    {add_sub([E, Out], Reg, SAcc), GAcc};
                               (Src, {gate, _}, {SAcc, GAcc}) ->
                                    Key = maps:get(Src, GateOf),
                                    {SAcc, add_sub([Key, subs, Src], Reg, GAcc)}
                            end, Acc, Ups)
          end, {#{}, Gates0}, lists:sort(Consumers)),
    #{routers => Routers, gates => Gates, subs => Subs}.

add_sub([K], Reg, Map) ->
    maps:update_with(K, fun(L) -> lists:usort([Reg | L]) end, [Reg], Map);
add_sub([K | Path], Reg, Map) ->
    maps:put(K, add_sub(Path, Reg, maps:get(K, Map, #{})), Map).

%% @doc The gate of every inhibited output: output -> gate key (its group's
%% smallest member).
-spec gates(wiring()) -> #{source() => source()}.
gates(#{inhibitors := Inhs}) ->
    maps:from_list([{M, Key} || {Key, Ms} <- maps:to_list(groups(Inhs)), M <- Ms]).

%% Groups of gated outputs: connected by mutual inhibition, keyed by the
%% smallest member.
groups(Inhs) ->
    Gated = lists:sort(maps:keys(Inhs)),
    Mutual = fun(A, B) ->
                     lists:keymember(A, 1, maps:get(B, Inhs, [])) andalso
                         lists:keymember(B, 1, maps:get(A, Inhs, []))
             end,
    {Groups, _} = lists:foldl(
                    fun(O, {Acc, Seen}) ->
                            case lists:member(O, Seen) of
                                true -> {Acc, Seen};
                                false ->
                                    Comp = component([O], [], Gated, Mutual),
                                    {Acc#{hd(Comp) => Comp}, Comp ++ Seen}
                            end
                    end, {#{}, []}, Gated),
    Groups.

component([], Done, _All, _Mutual) -> lists:sort(Done);
component([X | Todo], Done, All, Mutual) ->
    Next = [Y || Y <- All, Y =/= X, Mutual(X, Y), not lists:member(Y, Done),
                 not lists:member(Y, Todo)],
    component(Todo ++ Next, [X | Done], All, Mutual).
