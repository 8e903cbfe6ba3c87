%% @doc The wiring table: its rows, written down once. The table belongs to
%% `toroco_store', which lends it to each incarnation of the wiring server
%% (`toroco_wiring', the only writer, through {@link claim/0}) and takes it
%% back when that dies, so what is written here outlives a crash of its
%% writer. Every process may read it; nothing reads it per event.
%%
%% <table>
%% <tr><th>row</th><th>read by</th><th>when</th></tr>
%% <tr><td>`{{router, {Receiver, Input}}, Cfg}'</td><td>the router</td>
%%     <td>it (re)starts (a re-wired one gets its `Cfg' with the call)</td></tr>
%% <tr><td>`{{gate, Source}, Cfg}'</td><td>the gate</td><td>the same</td></tr>
%% <tr><td>`{{subs, Emitter}, #{Output => [Reg]}}'</td><td>the emitter</td>
%%     <td>it (re)starts</td></tr>
%% <tr><td>`{{nodes, Name}, {Kind, Module, Layer, Inputs, Outputs}}' (and
%%     `open' a sixth element for a node with open ports)</td>
%%     <td>`toroco:inject/3' (a name known, not running); the wiring server</td>
%%     <td>it restarts</td></tr>
%% <tr><td>``{'$meta', Meta}''</td><td>the wiring server</td><td>it restarts</td></tr>
%% </table>
-module(toroco_wiring_table).

-export([claim/0, lookup/1, known/1, subs_of/1, ports_of/1, row/2, plan_changed/2, forget/2,
         nodes_changed/2, write_meta/1, restore/1]).

-define(TABLE, toroco_wiring).

%% @doc Makes the caller (the wiring server) the table's writer until it dies.
-spec claim() -> ok.
claim() ->
    ok = toroco_store:claim(?TABLE).

%% @doc A router's or gate's configuration.
-spec lookup({router | gate, term()}) -> {ok, map()} | error.
lookup(Key) ->
    try ets:lookup(?TABLE, Key) of
        [{_, Cfg}] -> {ok, Cfg};
        [] -> error
    catch error:badarg -> error
    end.

%% @doc Whether `Name' is a behavior or device of this node's wiring.
-spec known(atom()) -> boolean().
known(Name) ->
    try ets:member(?TABLE, {nodes, Name})
    catch error:badarg -> false
    end.

%% @doc The inputs and outputs of `Name' in the wiring (an open behavior's
%% grow as the wiring names them), `#{}' if it has no node of that name.
-spec ports_of(atom()) -> #{inputs => [atom()], outputs => [atom()]}.
ports_of(Name) ->
    try ets:lookup(?TABLE, {nodes, Name}) of
        [{_, Row}] -> maps:with([inputs, outputs], node_info(Row));
        [] -> #{}
    catch error:badarg -> #{}
    end.

%% @doc The consumers each output of emitter `Name' is planned to feed.
-spec subs_of(atom()) -> #{atom() => [atom()]}.
subs_of(Name) ->
    try ets:lookup(?TABLE, {subs, Name}) of
        [{_, Subs}] -> Subs;
        [] -> #{}
    catch error:badarg -> #{}
    end.

%% @doc What a consumer keeps of its configuration in the plan: the rest is
%% the plan's own (its key says the rest), and every byte counts ten
%% thousand times.
-spec row(router | gate, map()) -> map().
row(router, Cfg) -> maps:with([sources, upstreams, buffer, idle, max_age], Cfg);
row(gate, Cfg) -> maps:with([members, entries, upstreams, subs], Cfg).

%% @doc Writes the rows of a new plan that differ from the old one's (those
%% of consumers no longer planned go with {@link forget/2}).
-spec plan_changed(toroco_wiring_core:plan(), toroco_wiring_core:plan()) -> ok.
plan_changed(#{routers := OldR, gates := OldG, subs := OldSubs},
             #{routers := NewR, gates := NewG, subs := NewSubs}) ->
    Changed = fun(New, Old) -> [{K, V} || {K, V} <- maps:to_list(New), maps:get(K, Old, none) =/= V] end,
    _ = [ets:insert(?TABLE, {{subs, E}, Subs}) || {E, Subs} <- Changed(NewSubs, OldSubs)],
    _ = [ets:delete(?TABLE, {subs, E}) || E <- maps:keys(OldSubs), not maps:is_key(E, NewSubs)],
    _ = [ets:insert(?TABLE, {{gate, K}, row(gate, Cfg)}) || {K, Cfg} <- Changed(NewG, OldG)],
    _ = [ets:insert(?TABLE, {{router, K}, row(router, Cfg)}) || {K, Cfg} <- Changed(NewR, OldR)],
    ok.

%% @doc A consumer's configuration goes (before the consumer: a restart
%% racing with its stop ends at once).
-spec forget(router | gate, term()) -> ok.
forget(Kind, Key) ->
    true = ets:delete(?TABLE, {Kind, Key}),
    ok.

%% @doc Writes the nodes that changed. A node is kept as a tuple: a map of
%% five keys costs twice the words.
-spec nodes_changed(#{atom() => toroco_wiring_core:node_info()},
                    #{atom() => toroco_wiring_core:node_info()}) -> ok.
nodes_changed(Old, New) ->
    maps:foreach(fun(K, V = #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs}) ->
                         case Old of
                             #{K := V} -> ok;
                             #{} -> ets:insert(?TABLE, {{nodes, K},
                                                        node_row(V, {Kind, M, L, Ins, Outs})})
                         end
                 end, New),
    maps:foreach(fun(K, _) ->
                         case New of
                             #{K := _} -> ok;
                             #{} -> ets:delete(?TABLE, {nodes, K})
                         end
                 end, Old).

node_row(#{open := true}, Row) -> erlang:append_element(Row, open);
node_row(#{}, Row) -> Row.

node_info({Kind, M, L, Ins, Outs}) ->
    #{kind => Kind, module => M, layer => L, inputs => Ins, outputs => Outs};
node_info({Kind, M, L, Ins, Outs, open}) ->
    (node_info({Kind, M, L, Ins, Outs}))#{open => true}.

%% @doc Writes the wiring server's own state.
-spec write_meta(#{network := term(), atom() => term()}) -> ok.
write_meta(Meta) ->
    true = ets:insert(?TABLE, {'$meta', Meta}),
    ok.

%% @doc What a previous incarnation of the writer left, if it wrote it for
%% the same `Network' (the pids of the supervisors it started processes
%% in): its state, its nodes, and the routers' and gates' configurations.
%% Otherwise the network was restarted meanwhile and is empty: the table is
%% emptied, and `fresh'.
-spec restore(term()) ->
          {ok, map(), #{atom() => toroco_wiring_core:node_info()},
           [{term(), map()}], [map()]} | fresh.
restore(Network) ->
    case ets:lookup(?TABLE, '$meta') of
        [{_, Meta = #{network := Network}}] ->
            Part = fun(P) -> ets:select(?TABLE, [{{{P, '$1'}, '$2'}, [], [{{'$1', '$2'}}]}]) end,
            Nodes = maps:from_list([{N, node_info(Row)} || {N, Row} <- Part(nodes)]),
            {ok, Meta, Nodes, Part(router), [G || {_, G} <- Part(gate)]};
        _ ->
            true = ets:delete_all_objects(?TABLE),
            fresh
    end.
