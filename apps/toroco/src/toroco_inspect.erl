%% @doc Looking inside a running network: the maps of `toroco:inspect/0,1',
%% the `toroco:top/0' table and the `toroco:wiring_dot/0' graph.
%%
%% Everything here runs in the caller's process: it asks the wiring server for
%% the wiring (data only) and asks routers, gates and emitters for their state
%% directly, so inspecting never holds up the wiring server.
-module(toroco_inspect).

-export([overview/0, node/1, top/0, top_iodata/0, dot/0]).
-compile({no_auto_import, [node/1]}).

%%====================================================================
%% inspect/0,1
%%====================================================================

-spec overview() -> #{behaviors := [atom()], devices := [atom()],
                      layers := #{non_neg_integer() => [atom()]},
                      removed_layers := [non_neg_integer()]}.
overview() ->
    {W, Removed} = toroco_wiring:call(wiring),
    Nodes = lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
    Behaviors = [{N, L} || {N, #{kind := behavior, layer := L}} <- Nodes],
    #{behaviors => [N || {N, _} <- Behaviors],
      devices => [N || {N, #{kind := device}} <- Nodes],
      layers => lists:foldl(fun({N, L}, Acc) ->
                                    maps:update_with(L, fun(Ns) -> Ns ++ [N] end, [N], Acc)
                            end, #{}, Behaviors),
      removed_layers => Removed}.

-spec node(atom()) -> map() | {error, term()}.
node(Name) ->
    case toroco_wiring:call({node, Name}) of
        {ok, Info} -> describe(Name, Info);
        Err -> Err
    end.

describe(Name, #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs,
                 inputs_wired := Wired, inhibitors := Inhs, gates := Gates}) ->
    Engine = case toroco_behavior:info(Name) of
                 #{} = I -> I;
                 {error, _} -> #{status => down, latches => #{}}
             end,
    Latches = maps:get(latches, Engine),
    Base = #{name => Name, kind => Kind, module => M, layer => L,
             status => maps:get(status, Engine),
             inputs => maps:from_list([{I, input(Name, I, Wired)} || I <- Ins]),
             outputs => maps:from_list(
                          [{O, output(Name, O, maps:get(O, Inhs, []), Gates, Latches)}
                           || O <- Outs])},
    B1 = case Wired of
             #{'$reset' := #{sources := Srcs}} -> Base#{reset => [S || {S, _} <- Srcs]};
             #{} -> Base
         end,
    case Engine of
        #{device := Counters} -> B1#{device => Counters};
        #{} -> B1
    end.

input(Name, I, Wired) ->
    case Wired of
        #{I := #{sources := Srcs, buffer := B}} ->
            case toroco_router:info({Name, I}) of
                #{} = Info -> maps:with([sources, winner, holds, latches, last, buffer], Info);
                none -> #{sources => [S || {S, _} <- Srcs], winner => none, holds => [],
                          latches => [], last => none, buffer => B}
            end;
        #{} ->
            #{sources => [], winner => none, holds => [], latches => [], last => none}
    end.

output(Name, O, Inhibitors, Gates, Latches) ->
    Inhibited = case Gates of
                    #{{Name, O} := Key} ->
                        case toroco_gate:info(Key) of
                            #{{Name, O} := #{inhibited := I}} -> I;
                            _ -> false
                        end;
                    #{} -> false
                end,
    #{inhibited => Inhibited, inhibitors => [S || {S, _} <- Inhibitors],
      latch => case Latches of
                   #{O := V} -> {value, V};
                   #{} -> none
               end}.

%%====================================================================
%% top/0
%%====================================================================

-spec top() -> ok.
top() ->
    io:put_chars(unicode:characters_to_binary(top_iodata())).

%% @doc The `top/0' table as text.
-spec top_iodata() -> iodata().
top_iodata() ->
    #{behaviors := Bs, devices := Ds, layers := Layers, removed_layers := Removed} = overview(),
    Rows = [row(N) || N <- Bs ++ Ds],
    [io_lib:format("Torocó  ~ts  layers ~w  taken out ~w~n",
                   [calendar:system_time_to_rfc3339(erlang:system_time(second)),
                    maps:keys(Layers), Removed]),
     io_lib:format("~-20s ~-8s ~5s ~-10s ~6s ~8s~n",
                   [name, kind, layer, status, queue, reds]),
     [io_lib:format("~-20s ~-8s ~5w ~-10s ~6w ~8w~n", [N, K, L, S, Q, R])
      || {N, K, L, S, Q, R, _} <- Rows],
     "\ninputs (winner, holds ms, latches)\n",
     [[io_lib:format("  ~w.~w <- ~w  holds ~w  latches ~w~n",
                     [N, I, W, Hs, Ls])
       || {I, #{winner := W, holds := Hs, latches := Ls, sources := [_ | _]}}
              <- maps:to_list(maps:get(inputs, Info, #{}))]
      || {N, _, _, _, _, _, Info} <- Rows],
     "\ninhibited outputs\n",
     [[io_lib:format("  ~w.~w by ~w~n", [N, O, Inh])
       || {O, #{inhibited := true, inhibitors := Inh}} <- maps:to_list(maps:get(outputs, Info, #{}))]
      || {N, _, _, _, _, _, Info} <- Rows],
     "\ndevice counters\n",
     [io_lib:format("  ~w ~w~n", [N, C]) || {N, _, _, _, _, _, #{device := C}} <- Rows]].

row(N) ->
    Info = case node(N) of
               #{} = I -> I;
               _ -> #{}
           end,
    {Q, R} = case whereis(toroco_names:node(N)) of
                 undefined -> {'-', '-'};
                 Pid -> case erlang:process_info(Pid, [message_queue_len, reductions]) of
                            [{_, Q0}, {_, R0}] -> {Q0, R0};
                            undefined -> {'-', '-'}
                        end
             end,
    {N, maps:get(kind, Info, '?'), maps:get(layer, Info, '?'), maps:get(status, Info, down),
     Q, R, Info}.

%%====================================================================
%% wiring_dot/0
%%====================================================================

%% @doc Behaviors and devices are records with inputs on the left and outputs
%% on the right; suppression edges are solid (labelled with their priority,
%% 1 = highest), inhibition edges dashed red, reset edges dotted.
-spec dot() -> iodata().
dot() ->
    {W, _} = toroco_wiring:call(wiring),
    Nodes = lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
    Edges = lists:append(
              [[edge(S, {N, I}, P, I) || {I, #{sources := Srcs}} <- lists:sort(maps:to_list(
                                                                     toroco_wiring_core:inputs_of(W, N))),
                                         {P, {S, _}} <- lists:zip(lists:seq(1, length(Srcs)), Srcs)]
               || {N, _} <- Nodes]),
    Inh = [io_lib:format("  ~s -> ~s [style=dashed, color=red, label=\"inhibits\"];~n",
                         [port(I, out), port({E, O}, out)])
           || {E, #{outputs := Outs}} <- Nodes, O <- Outs,
              {I, _} <- toroco_wiring_core:inhibitors_of(W, {E, O})],
    ["digraph toroco {\n  rankdir=LR;\n  node [shape=record, fontname=\"Helvetica\"];\n",
     [io_lib:format("  ~s [label=\"{~s|{~s}|~s}\"~s];~n",
                    [quote(N), ports(Ins, in), io_lib:format("~w\\nlayer ~w", [N, L]),
                     ports(Outs, out), case K of device -> ", style=rounded"; _ -> "" end])
      || {N, #{inputs := Ins, outputs := Outs, layer := L, kind := K}} <- Nodes],
     Edges, Inh, "}\n"].

edge(S, {R, '$reset'}, _P, _I) ->
    io_lib:format("  ~s -> ~s [style=dotted, label=\"reset\"];~n", [port(S, out), quote(R)]);
edge(S, To, P, _I) ->
    io_lib:format("  ~s -> ~s [label=\"~w\"];~n", [port(S, out), port(To, in), P]).

ports(Ports, Dir) ->
    lists:join("|", [io_lib:format("<~s_~s> ~w", [Dir, P, P]) || P <- Ports]).

port({N, P}, Dir) -> io_lib:format("~s:~s_~s", [quote(N), Dir, P]).

quote(N) -> io_lib:format("\"~w\"", [N]).
