%% @doc The directory between nodes (SPEC §13): what the wiring servers of
%% connected nodes tell each other of what they run, written down once.
%% It runs inside the wiring server (`toroco_wiring'), which keeps a
%% {@link dir()} in its state and hands it the messages below; it is never
%% on the event path.
%%
%% The wiring servers find each other in the `pg' scope `toroco' (group
%% `wiring') and through `net_kernel:monitor_nodes/1', and tell each other
%% their directory (names, ports, layers, gated outputs) whenever it
%% changes, when one starts and when a node (re)connects. Each server
%% changes only the wiring of its own node; a remote name takes part through
%% what its node told. A name that two nodes claim is a clash: reported with
%% a logger error and listed (`toroco:inspect()', `name_clashes'), never
%% merged.
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>`DIR(Node, Dir, Hello, Ack)'</td><td>wiring server → wiring server</td>
%%     <td>the server starts, meets a node before a first request to it, a
%%         node comes up, or a change alters what `Node' runs (`Dir' holds
%%         its names and the names it just removed)</td>
%%     <td>the same back if `Hello'; `DIR_ACK' once applied if `Ack' is
%%         `{Pid, Ref}'</td></tr>
%% <tr><td>`DIR_ACK(Ref, Node)'</td><td>wiring server → wiring server</td>
%%     <td>a directory told with `Ack' was applied on `Node'</td>
%%     <td>none: the change waiting for it is answered once every node
%%         acknowledged, or after a second (`TOLD(Ref)', to itself)</td></tr>
%% <tr><td>`{nodeup, Node}' / `{nodedown, Node}'</td><td>`net_kernel' → wiring server</td>
%%     <td>a node connects / goes away</td>
%%     <td>`DIR' to it / its acknowledgements are no longer waited for (its
%%         names stay in the wiring until it removes them)</td></tr>
%% </table>
-module(toroco_wiring_dir).

-include("toroco_wire.hrl").

-export([new/1, clashes/1, join/1, peers/0, meet/4, changed/5, handle/3, applied/3]).
-export_type([dir/0]).

-define(SCOPE, toroco).
-define(SERVER, toroco_wiring).
-define(DIR(Node, Dir, Hello, Ack), {'$toroco_dir', Node, Dir, Hello, Ack}).
-define(DIR_ACK(Ref, Node), {'$toroco_dir_ack', Ref, Node}).
-define(TOLD(Ref), {'$toroco_dir_told', Ref}).
%% How long a change waits for the other nodes to take it in.
-define(TELL_MS, 1000).

-record(d, {clashes = [] :: [{atom(), node()}],
            %% changes whose answer waits for the other nodes to know them
            telling = #{} :: #{reference() => {gen_server:from(), [node()]}},
            %% the nodes whose wiring servers told this one what they run
            known = [] :: [node()]}).
-opaque dir() :: #d{}.

%% @doc A directory with the clashes a previous incarnation of the server
%% saw.
-spec new([{atom(), node()}]) -> dir().
new(Clashes) -> #d{clashes = Clashes}.

%% @doc The names that this node and another one both claim, with the
%% other node.
-spec clashes(dir()) -> [{atom(), node()}].
clashes(#d{clashes = Cl}) -> Cl.

%% @doc Called by the wiring server as it starts: it joins the others and
%% tells every connected node what it runs.
-spec join(toroco_wiring_core:wiring()) -> ok.
join(W) ->
    ok = pg:join(?SCOPE, wiring, self()),
    ok = net_kernel:monitor_nodes(true),
    _ = [tell(N, W, [], true, none) || N <- nodes()],
    ok.

%% @doc The nodes whose wiring servers this one knows, itself included.
-spec peers() -> [node()].
peers() ->
    lists:usort([node() | [node(P) || P <- pg:get_members(?SCOPE, wiring)]]).

%% @doc Before a first request to `Node': it learns this node's names (and
%% answers with its own); `From' is answered once it has, or after a second.
-spec meet(node(), gen_server:from(), toroco_wiring_core:wiring(), dir()) -> dir().
meet(Node, From, W, D) ->
    wait_for([Node], From, fun(Ack) -> tell(Node, W, [], true, Ack) end, D).

%% @doc A local change from `W0' to `W1' (`Removed' the names it removed):
%% `reply' at once if the other nodes need not know, else `noreply' and
%% `From' is answered once each connected node has taken it in, or after a
%% second. A clash ends when this node's name goes.
-spec changed(toroco_wiring_core:wiring(), toroco_wiring_core:wiring(), [atom()],
              gen_server:from(), dir()) -> {reply | noreply, dir()}.
changed(W0, W1, Removed, From, D0 = #d{clashes = Cl}) ->
    Local = toroco_wiring_core:nodes(W1),
    D = D0#d{clashes = [C || C = {N, _} <- Cl, maps:is_key(N, Local)]},
    Others = lists:usort(D#d.known ++ peers()) -- [node()],
    Changed = Others =/= [] andalso (Removed =/= [] orelse
        toroco_wiring_core:directory(W0) =/= toroco_wiring_core:directory(W1)),
    case Changed of
        false -> {reply, D};
        true -> {noreply, wait_for(Others, From,
                                   fun(Ack) -> [tell(N, W1, Removed, false, Ack) || N <- Others] end,
                                   D)}
    end.

%% @doc A message of the directory's protocol, with the server's wiring:
%% `{ok, Dir}' when the wiring stays as it is; `{told, Node, Wiring, Ack,
%% Dir}' when `Node' told what it runs and `Wiring' takes it in (the server
%% applies it, then calls {@link applied/3}); `unknown' for a message that
%% is not the directory's.
-spec handle(term(), toroco_wiring_core:wiring(), dir()) ->
          {ok, dir()} | {told, node(), toroco_wiring_core:wiring(), term(), dir()} | unknown.
handle(?DIR(Node, Dir, Hello, Ack), W, D = #d{clashes = Cl, known = Known}) ->
    _ = Hello andalso tell(Node, W, [], false, none),
    {W1, Clashes} = toroco_wiring_core:set_remote(W, Node, Dir),
    _ = [logger:error("toroco: ~p is on both ~p and ~p: the names of a robot must be unique "
                      "across its nodes; rename or remove one", [N, node(), Node],
                      #{domain => [toroco, wiring]}) || N <- Clashes],
    %% A node's clashes are those of its latest directory: one resolved
    %% (renamed or removed on either side) is no longer listed.
    Cl1 = lists:usort([{N, Node} || N <- Clashes] ++ [C || C = {_, At} <- Cl, At =/= Node]),
    {told, Node, W1, Ack, D#d{clashes = Cl1, known = lists:usort([Node | Known])}};
handle(?DIR_ACK(Ref, Node), _W, D) ->
    {ok, told(Ref, [Node], D)};
handle(?TOLD(Ref), _W, D = #d{telling = T}) ->
    %% A node that did not answer in time learns it when it does.
    case T of
        #{Ref := {_, Waiting}} -> {ok, told(Ref, Waiting, D)};
        #{} -> {ok, D}
    end;
handle({nodeup, Node}, W, D) ->
    tell(Node, W, [], true, none),
    {ok, D};
handle({nodedown, Node}, _W, D = #d{telling = T, known = Known}) ->
    %% Its names stay in the wiring: the routers let its sources go after
    %% their max age, and the wiring is as it was when the node comes back.
    {ok, maps:fold(fun(Ref, _, Acc) -> told(Ref, [Node], Acc) end,
                   D#d{known = lists:delete(Node, Known)}, T)};
handle(_Msg, _W, _D) ->
    unknown.

%% @doc What `Node' told is applied (the wiring is now `W'): the consumers
%% fed from it subscribe again to what they do not hear, and it gets its
%% acknowledgement if it asked for one.
-spec applied(node(), term(), toroco_wiring_core:wiring()) -> ok.
applied(Node, Ack, W) ->
    #{routers := Rs, gates := Gs} = toroco_wiring_core:plan(W),
    _ = [toroco_wire:send(toroco_wire:address(Reg), ?WIRE_RESUBSCRIBE)
         || #{reg := Reg, upstreams := Ups} <- maps:values(Rs) ++ maps:values(Gs),
            lists:any(fun({_, {_, N}}) -> N =:= Node; (_) -> false end, maps:values(Ups))],
    case Ack of
        {Pid, Ref} -> toroco_wire:send(Pid, ?DIR_ACK(Ref, node()));
        none -> ok
    end.

%%====================================================================
%% Internal
%%====================================================================

%% Tells the wiring server of `Node' what this node runs; `Removed' names
%% were just removed here.
tell(Node, W, Removed, Hello, Ack) ->
    Dir = #{nodes => toroco_wiring_core:directory(W), removed => Removed},
    toroco_wire:send({?SERVER, Node}, ?DIR(node(), Dir, Hello, Ack)).

%% `From' waits for `Nodes' to acknowledge what `Tell' sends them.
wait_for(Nodes, From, Tell, D = #d{telling = T}) ->
    Ref = make_ref(),
    _ = Tell({self(), Ref}),
    erlang:send_after(?TELL_MS, self(), ?TOLD(Ref)),
    D#d{telling = T#{Ref => {From, Nodes}}}.

told(Ref, Nodes, D = #d{telling = T}) ->
    case T of
        #{Ref := {From, Waiting}} ->
            case Waiting -- Nodes of
                [] -> gen_server:reply(From, ok), D#d{telling = maps:remove(Ref, T)};
                Left -> D#d{telling = T#{Ref := {From, Left}}}
            end;
        #{} -> D
    end.
