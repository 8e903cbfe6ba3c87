%% @doc The wiring server: the one place where the wiring changes.
%%
%% It holds the current `toroco_wiring_core:wiring()', validates each request
%% against it (a wiring file's terms through `toroco_wiring_file'), and
%% applies the resulting plan: it starts, re-wires and stops routers and
%% gates, starts and stops behaviors (in their layer's supervisor) and
%% devices, and writes the wiring table, an ETS table that the processes
%% read when they (re)start to find their place; a consumer being re-wired
%% gets its new configuration with the call. It is never on the event path:
%% events go emitter → (gate) → router → receiver.
%%
%% It also watches the layer supervisors: a layer that exceeds its restart
%% intensity is taken out as a whole, reported with a logger error and listed
%% in `toroco:inspect()' under `removed_layers'.
%%
%% Several nodes (SPEC §13): the wiring servers of connected nodes tell each
%% other what they run (`toroco_wiring_dir', the directory's protocol). Each
%% server changes only the wiring of its own node: the inputs of its
%% receivers, the inhibitors of its emitters; a remote name takes part
%% through what its node told. A name removed on its node leaves the wiring
%% of every node. A name that two nodes claim (added on both sides of a
%% partition) is listed in `toroco:inspect()' under `name_clashes', never
%% merged.
%%
%% The wiring table's rows are written down in `toroco_wiring_table': this
%% server is the table's only writer, lent it by `toroco_store' in each
%% incarnation.
-module(toroco_wiring).
-behaviour(gen_server).

-export([start_link/0, call/1, call/2, lookup/1, subs_of/1, ports_of/1, known/1, stopping/0,
         peers/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).

-record(s, {wiring = toroco_wiring_core:new() :: toroco_wiring_core:wiring(),
            layers = #{} :: #{non_neg_integer() => {pid(), reference()}},
            removed = [] :: [non_neg_integer()],
            stopping = false :: boolean(),
            dir = toroco_wiring_dir:new([]) :: toroco_wiring_dir:dir()}).

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], [{hibernate_after, 1000}]).

%% @doc Sends a request to the wiring server and waits for its answer.
%%
%% The caller may be a behavior or device (a callback that adds, removes or
%% re-wires at run time): the consumers that subscribe to it do not wait
%% for its answer (it is busy in this call); they take it as soon as its
%% callback returns. Every wait behind this call is bounded (a consumer
%% waits `sync_timeout_ms' at most for an upstream), so the call itself
%% waits for the change to be applied, however large.
-spec call(term()) -> term().
call(Request) ->
    gen_server:call(?MODULE, Request, infinity).

%% @doc The same, to the wiring server of `Node'; `{error, {nodedown,
%% Node}}' if it cannot be reached.
-spec call(node(), term()) -> term().
call(Node, Request) when Node =:= node() ->
    call(Request);
call(Node, Request) ->
    Met = lists:member(Node, peers()) orelse
        (net_kernel:connect_node(Node) =:= true andalso call({meet, Node}) =:= ok),
    try Met andalso gen_server:call({?MODULE, Node}, Request, infinity) of
        false -> {error, {nodedown, Node}};
        Reply -> Reply
    catch exit:{{nodedown, _}, _} -> {error, {nodedown, Node}};
          exit:{noproc, _} -> {error, {nodedown, Node}}
    end.

%% @doc The nodes whose wiring servers this one knows, itself included.
-spec peers() -> [node()].
peers() ->
    toroco_wiring_dir:peers().

%% @doc A router's or gate's configuration from the wiring table.
-spec lookup({router | gate, term()}) -> {ok, map()} | error.
lookup(Key) ->
    toroco_wiring_table:lookup(Key).

%% @doc Whether `Name' is a behavior or device of the wiring (read from the
%% table, without asking the server).
-spec known(atom()) -> boolean().
known(Name) ->
    toroco_wiring_table:known(Name).

%% @doc The consumers each output of emitter `Name' is planned to feed.
-spec subs_of(atom()) -> #{atom() => [atom()]}.
subs_of(Name) ->
    toroco_wiring_table:subs_of(Name).

%% @doc The ports of `Name' in the wiring (read from the table): an open
%% behavior's are those its wiring named so far. `#{}' for an unknown name.
-spec ports_of(atom()) -> #{inputs => [atom()], outputs => [atom()]}.
ports_of(Name) ->
    toroco_wiring_table:ports_of(Name).

%% @doc Called when the application is about to stop: layers going down from
%% now on are being shut down, not taken out.
-spec stopping() -> ok.
stopping() ->
    gen_server:call(?MODULE, stopping).

%%====================================================================
%% gen_server
%%====================================================================

-spec init([]) -> {ok, #s{}}.
init([]) ->
    ok = toroco_wiring_table:claim(),
    S = restore(),
    ok = toroco_wiring_dir:join(S#s.wiring),
    {ok, S}.

-spec handle_call(term(), gen_server:from(), #s{}) ->
          {reply, term(), #s{}} | {noreply, #s{}}.
handle_call({add, Kind, Name, Module, Opts}, From, S) ->
    reply(add_node(Kind, Name, Module, Opts, S), From, S);
handle_call({remove, _Kind, Name} = Req, From = {Caller, _}, S) ->
    reply(remove_node(Req, Caller, S), From, S, [Name]);
handle_call({set_inputs, R, Map}, From = {Caller, _}, S = #s{wiring = W}) ->
    reply(rewire(toroco_wiring_core:set_inputs(W, R, Map), Caller, S), From, S);
handle_call({set_inhibitors, E, Map}, From = {Caller, _}, S = #s{wiring = W}) ->
    reply(rewire(toroco_wiring_core:set_inhibitors(W, E, Map), Caller, S), From, S);
handle_call({set_reset, B, Srcs}, From = {Caller, _}, S = #s{wiring = W}) ->
    reply(rewire(toroco_wiring_core:set_reset(W, B, Srcs), Caller, S), From, S);
handle_call({load, Terms}, From = {Caller, _}, S) ->
    reply(load(Terms, Caller, S), From, S);
handle_call({node, Name}, _From, S = #s{wiring = W}) ->
    case toroco_wiring_core:node(W, Name) of
        {ok, Info} ->
            {reply, {ok, Info#{inputs_wired => toroco_wiring_core:inputs_of(W, Name),
                               inhibitors => maps:from_list(
                                               [{O, toroco_wiring_core:inhibitors_of(W, {Name, O})}
                                                || O <- maps:get(outputs, Info)]),
                               gates => gates_of(Name, S)}}, S};
        Err -> {reply, Err, S}
    end;
handle_call(wiring, _From, S = #s{wiring = W, removed = Removed}) ->
    {reply, {W, Removed}, S};
handle_call({where, Name}, _From, S = #s{wiring = W}) ->
    {reply, case {toroco_wiring_core:nodes(W), toroco_wiring_core:remote(W)} of
                {#{Name := _}, _} -> {ok, node()};
                {_, #{Name := #{node := N}}} -> {ok, N};
                _ -> {error, {unknown_name, Name}}
            end, S};
handle_call({meet, Node}, From, S = #s{wiring = W, dir = D}) ->
    %% Before a first request to another node: it learns this one's names
    %% (and answers with its own) before the request reaches it.
    {noreply, S#s{dir = toroco_wiring_dir:meet(Node, From, W, D)}};
handle_call(clashes, _From, S = #s{dir = D}) ->
    {reply, toroco_wiring_dir:clashes(D), S};
handle_call(stopping, _From, S) ->
    {reply, ok, persist(S, S#s{stopping = true})};
handle_call(Request, _From, S) ->
    {reply, {error, {unknown_request, Request}}, S}.

-spec handle_cast(term(), #s{}) -> {noreply, #s{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

-spec handle_info(term(), #s{}) -> {noreply, #s{}}.
handle_info({'DOWN', Ref, process, _Pid, Reason}, S = #s{layers = Layers, removed = Removed}) ->
    case [L || {L, {_, R}} <- maps:to_list(Layers), R =:= Ref] of
        [L] when S#s.stopping ->
            {noreply, persist(S, S#s{layers = maps:remove(L, Layers)})};
        [L] ->
            logger:error("toroco: layer ~p exceeded its restart intensity and was taken "
                         "out (~p); the layers below keep running", [L, Reason],
                         #{domain => [toroco, wiring]}),
            _ = [toroco_tap:lifecycle(N, {layer_removed, L})
                 || {N, #{kind := behavior, layer := NL}} <- maps:to_list(toroco_wiring_core:nodes(S#s.wiring)),
                    NL =:= L],
            {noreply, persist(S, S#s{layers = maps:remove(L, Layers),
                                     removed = lists:usort([L | Removed])})};
        [] ->
            {noreply, S}
    end;
handle_info(Msg, S = #s{wiring = W, dir = D}) ->
    case toroco_wiring_dir:handle(Msg, W, D) of
        {ok, D1} ->
            {noreply, S#s{dir = D1}};
        {told, Node, W1, Ack, D1} ->
            {ok, S1} = rewire({ok, W1}, none, S#s{dir = D1}),
            ok = toroco_wiring_dir:applied(Node, Ack, W1),
            {noreply, persist(S, S1)};
        unknown ->
            {noreply, S}
    end.

%% A change that the other nodes must know (a name added or removed, an
%% output gated) is answered once each connected node has taken it in, or
%% after a second; the others hear of it at once.
reply(Result, From, S) ->
    reply(Result, From, S, []).

reply({ok, S1 = #s{wiring = W1, dir = D}}, From, S, Removed) ->
    case toroco_wiring_dir:changed(S#s.wiring, W1, Removed, From, D) of
        {reply, D1} -> {reply, ok, persist(S, S1#s{dir = D1})};
        {noreply, D1} -> {noreply, persist(S, S1#s{dir = D1})}
    end;
reply({error, Reason, S1}, _From, S, _Removed) -> {reply, {error, Reason}, persist(S, S1)};
reply({error, _} = Err, _From, S, _Removed) -> {reply, Err, S}.

%%====================================================================
%% Surviving a crash
%%====================================================================

%% The wiring and the server's state are written through to the wiring
%% table (`toroco_wiring_table') after each change, so a restarted server
%% reads back what it had: the nodes (only those that changed), and the
%% server's own state; the inputs and the inhibitors are read back from the
%% routers' and gates' configurations, which the table holds anyway. If the
%% network's supervisors were restarted meanwhile (everything after the
%% store restarts with them), the network is empty, and so is the wiring.
persist(#s{wiring = W0} = S0, S1 = #s{wiring = W1}) ->
    ok = toroco_wiring_table:nodes_changed(toroco_wiring_core:nodes(W0), toroco_wiring_core:nodes(W1)),
    _ = meta(S0) =/= meta(S1) andalso toroco_wiring_table:write_meta(meta(S1)),
    S1.

meta(#s{layers = Layers, removed = Removed, stopping = Stopping, wiring = W, dir = D}) ->
    #{network => network(), layers => maps:map(fun(_, {Pid, _}) -> Pid end, Layers),
      removed => Removed, stopping => Stopping, remote => toroco_wiring_core:remote(W),
      clashes => toroco_wiring_dir:clashes(D)}.

network() ->
    [whereis(Sup) || Sup <- [toroco_routers_sup, toroco_devices_sup, toroco_layers_sup]].

restore() ->
    case toroco_wiring_table:restore(network()) of
        {ok, #{layers := Layers, removed := Removed, stopping := Stopping,
               remote := Remote, clashes := Clashes}, Nodes, Routers, Gates} ->
            W = toroco_wiring_core:restore(Nodes, Routers, Gates, Remote),
            %% A layer taken out while the server was down is seen here.
            {Alive, Gone} = lists:partition(fun({_, Pid}) -> is_process_alive(Pid) end,
                                            maps:to_list(Layers)),
            S = #s{wiring = W, removed = lists:usort([L || {L, _} <- Gone] ++ Removed),
                   stopping = Stopping, dir = toroco_wiring_dir:new(Clashes),
                   layers = maps:from_list([{L, {Pid, erlang:monitor(process, Pid)}}
                                            || {L, Pid} <- Alive])},
            logger:notice("toroco: the wiring server restarted with the wiring it had "
                          "(~b behaviors and devices)", [map_size(Nodes)],
                          #{domain => [toroco, wiring]}),
            persist(S, S);
        fresh ->
            S = #s{},
            ok = toroco_wiring_table:write_meta(meta(S)),
            S
    end.

%%====================================================================
%% Nodes
%%====================================================================

add_node(Kind, Name, Module, Opts, S = #s{wiring = W}) ->
    case toroco_wiring_file:node(Kind, Name, Module, Opts) of
        {ok, Spec, Info} ->
            case toroco_wiring_core:add_node(W, Name, Info) of
                {ok, W1} ->
                    case start_node(Spec, S#s{wiring = W1}) of
                        {ok, _} = Ok -> Ok;
                        %% the node is not in the wiring; a layer
                        %% supervisor started for it stays known
                        {error, Reason, S1} -> {error, Reason, S1#s{wiring = W}}
                    end;
                Err -> Err
            end;
        Err -> Err
    end.

start_node(Spec = #{kind := Kind, name := Name, layer := L, module := M}, S) ->
    {Sup, S1} = case Kind of
                    device -> {toroco_devices_sup, S};
                    behavior -> layer_sup(L, S)
                end,
    %% A later failed hot reload of the module can only be undone with the
    %% object code kept from now.
    ok = toroco_reload:remember(M),
    ok = toroco_restarts:added(Name),
    case supervisor:start_child(Sup, toroco_behavior:child_spec(Spec)) of
        {ok, _} -> {ok, S1};
        {ok, _, _} -> {ok, S1};
        {error, Reason} -> {error, {start_failed, {Name, start_reason(Reason)}}, S1}
    end.

%% The supervisor wraps an init failure with its own child record.
start_reason({Reason, Child}) when element(1, Child) =:= child -> Reason;
start_reason(Reason) -> Reason.

layer_sup(L, S = #s{layers = Layers, removed = Removed}) ->
    case Layers of
        #{L := {Pid, Mon}} ->
            %% an empty layer started under the other clock counts its
            %% restarts in the wrong time: started again under this one
            case toroco_layer_sup:mode(Pid) =/= toroco_clock:mode()
                andalso supervisor:which_children(Pid) =:= [] of
                true ->
                    erlang:demonitor(Mon, [flush]),
                    _ = toroco_layers_sup:take_out(L),
                    layer_sup(L, S#s{layers = maps:remove(L, Layers)});
                false ->
                    {Pid, S}
            end;
        #{} ->
            Pid = case toroco_layers_sup:start_layer(L) of
                      {ok, P} -> P;
                      {error, {already_started, P}} -> P
                  end,
            {Pid, S#s{layers = Layers#{L => {Pid, erlang:monitor(process, Pid)}},
                      removed = lists:delete(L, Removed)}}
    end.

remove_node({remove, Kind, Name}, Caller, S = #s{wiring = W, layers = Layers}) ->
    case toroco_wiring_core:node(W, Name) of
        {ok, #{kind := Kind, layer := L}} ->
            Sup = case Kind of
                      device -> toroco_devices_sup;
                      behavior -> case Layers of
                                      #{L := {Pid, _}} -> Pid;
                                      #{} -> none
                                  end
                  end,
            %% The process goes first: its death ends its holds and clears its
            %% latches at once, so lower layers take over before re-wiring.
            _ = Sup =/= none andalso supervisor:terminate_child(Sup, Name),
            _ = Sup =/= none andalso supervisor:delete_child(Sup, Name),
            rewire(toroco_wiring_core:remove_node(W, Name), Caller, S);
        {ok, #{kind := Other}} ->
            {error, {case Other of device -> not_a_behavior; behavior -> not_a_device end, Name}};
        Err -> Err
    end.

%%====================================================================
%% Applying plans
%%====================================================================

%% The plan of the current wiring is recomputed rather than kept: it would
%% double the server's memory per behavior for a little CPU per change.
rewire({ok, W1}, Caller, S = #s{wiring = W0}) ->
    apply_plan(toroco_wiring_core:plan(W0), toroco_wiring_core:plan(W1), Caller),
    {ok, S#s{wiring = W1}};
rewire({error, _} = Err, _Caller, _S) ->
    Err.

%% Table first (restarting processes read it), then gates upstream-first, then
%% routers, then whatever is no longer needed.
apply_plan(Old = #{routers := OldR, gates := OldG}, New = #{routers := NewR, gates := NewG}, Caller) ->
    ok = toroco_wiring_table:plan_changed(Old, New),
    %% Only consumers that are new or whose configuration changed are touched,
    %% so a change costs in proportion to what it changes.
    _ = [ensure(gate, K, Cfg, maps:is_key(K, OldG), Caller)
         || {K, Cfg} <- gate_order(NewG), maps:get(K, OldG, none) =/= Cfg],
    _ = [ensure(router, K, Cfg, maps:is_key(K, OldR), Caller)
         || {K, Cfg} <- lists:sort(maps:to_list(NewR)), maps:get(K, OldR, none) =/= Cfg],
    _ = [stop(router, K) || K <- maps:keys(OldR), not maps:is_key(K, NewR)],
    _ = [stop(gate, K) || K <- maps:keys(OldG), not maps:is_key(K, NewG)],
    ok.

%% Starts a consumer that is not running (it reads its row), or re-wires one
%% whose configuration changed (it gets it with the call: its row may be
%% gone or newer by the time it takes the call in).
ensure(Kind, Key, Cfg, Changed, Caller) ->
    Mod = consumer_module(Kind),
    case toroco_routers_sup:start_consumer(Mod, Key, Caller) of
        {ok, _} -> answered(toroco_consumer:ready(Mod, Key));
        {error, {already_started, _}} when Changed ->
            answered(toroco_consumer:rewire(Mod, Key, toroco_wiring_table:row(Kind, Cfg), Caller));
        {error, {already_started, _}} -> ok;
        {error, Reason} ->
            logger:error("toroco: could not start ~p ~p: ~p", [Kind, Key, Reason],
                         #{domain => [toroco, wiring]})
    end.

%% A consumer that did not take its change in is logged; the change goes on
%% (the consumer's supervisor or its own late answers bring it right).
answered(ok) -> ok;
answered({error, Reason}) ->
    logger:error("toroco: a router or gate did not take a wiring change in: ~p", [Reason],
                 #{domain => [toroco, wiring]}).

stop(Kind, Key) ->
    _ = Kind =:= router andalso toroco_router:unwire(Key),
    %% The configuration goes first: a restart racing with the stop ends.
    ok = toroco_wiring_table:forget(Kind, Key),
    toroco_routers_sup:stop_consumer(consumer_module(Kind), Key).

consumer_module(router) -> toroco_router;
consumer_module(gate) -> toroco_gate.

%% Gates whose inhibitors come through other gates start after those.
gate_order(Gates) ->
    order(lists:sort(maps:to_list(Gates)), [], []).

order([], [], Done) -> lists:reverse(Done);
order([], Blocked, Done) -> order(lists:reverse(Blocked), [], Done);
order([{K, Cfg = #{upstreams := Ups}} | Rest], Blocked, Done) ->
    Needs = [G || {gate, G} <- maps:values(Ups)],
    DoneRegs = [toroco_names:gate(D) || {D, _} <- Done],
    Waiting = [G || G <- Needs, not lists:member(G, DoneRegs)],
    PendingRegs = [toroco_names:gate(P) || {P, _} <- Rest ++ Blocked],
    case [G || G <- Waiting, lists:member(G, PendingRegs)] of
        [] -> order(Rest, Blocked, [{K, Cfg} | Done]);
        _ -> order(Rest, [{K, Cfg} | Blocked], Done)
    end.

gates_of(Name, #s{wiring = W}) ->
    maps:filter(fun({E, _}, _) -> E =:= Name end, toroco_wiring_core:gates(W)).

%%====================================================================
%% Wiring files
%%====================================================================

%% The whole file is checked against a copy of the wiring first; only then are
%% its nodes started and its wiring applied. A node that fails to start undoes
%% the nodes started before it.
load(Terms, Caller, S = #s{wiring = W}) ->
    case toroco_wiring_file:validate(Terms, W) of
        {ok, W1, Specs} ->
            case start_nodes(Specs, S, []) of
                {ok, S1} -> rewire({ok, W1}, Caller, S1);
                Err -> Err
            end;
        Err -> Err
    end.

start_nodes([], S, _Started) ->
    {ok, S};
start_nodes([Spec = #{kind := Kind, name := Name} | Rest], S, Started) ->
    case start_node(Spec, S) of
        {ok, S1} -> start_nodes(Rest, S1, [{Kind, Name} | Started]);
        {error, Reason, S1} ->
            _ = [undo_start(K, N, S1) || {K, N} <- Started],
            {error, Reason, S1}
    end.

undo_start(device, Name, _S) ->
    _ = supervisor:terminate_child(toroco_devices_sup, Name),
    supervisor:delete_child(toroco_devices_sup, Name);
undo_start(behavior, Name, #s{layers = Layers}) ->
    [begin
         _ = supervisor:terminate_child(Pid, Name),
         supervisor:delete_child(Pid, Name)
     end || {Pid, _} <- maps:values(Layers)].
