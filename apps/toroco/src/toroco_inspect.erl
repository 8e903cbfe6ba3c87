%% @doc The maps of `toroco:inspect/0,1': what the network holds and what
%% one behavior or device is doing. `toroco_top' reads them for its table.
%%
%% Everything here runs in the caller's process: it asks the wiring server for
%% the wiring (data only) and asks routers, gates and emitters for their state
%% directly, so inspecting never holds up the wiring server.
%%
%% <ul>
%% <li>{@link overview/0}: the names of behaviors and devices, by layer.</li>
%% <li>{@link describe/1}: one behavior or device, its inputs and outputs.</li>
%% </ul>
-module(toroco_inspect).

-export([overview/0, describe/1, local_overview/0]).

%% @doc The network: behaviors and devices by name, the layers and the
%% layers taken out (`toroco:inspect/0').
-spec overview() -> #{behaviors := [atom()], devices := [atom()],
                      layers := #{non_neg_integer() => [atom()]},
                      removed_layers := [non_neg_integer()]}.
overview() ->
    Local = local_overview(),
    case [N || N <- toroco_wiring:peers(), N =/= node()] of
        [] ->
            Local;
        Others ->
            %% The whole robot: every connected node's own part, merged;
            %% `nodes' says where each name is.
            Answers = lists:zip(Others, erpc:multicall(Others, ?MODULE, local_overview, [], 5000)),
            Parts = [Local#{node => node()} | [P#{node => N} || {N, {ok, P}} <- Answers]],
            Merge = fun(K) -> lists:usort(lists:append([maps:get(K, P) || P <- Parts])) end,
            #{behaviors => Merge(behaviors), devices => Merge(devices),
              layers => lists:foldl(
                          fun(#{layers := Ls}, Acc) ->
                                  maps:fold(fun(L, Ns, A) ->
                                                    maps:update_with(L, fun(Old) -> lists:usort(Old ++ Ns) end,
                                                                     Ns, A)
                                            end, Acc, Ls)
                          end, #{}, Parts),
              removed_layers => Merge(removed_layers),
              nodes => maps:from_list([{Name, N} || #{node := N, behaviors := Bs, devices := Ds} <- Parts,
                                                     Name <- Bs ++ Ds]),
              name_clashes => lists:usort(lists:append([maps:get(name_clashes, P, []) || P <- Parts]))}
    end.

%% @doc This node's part of the robot.
-spec local_overview() -> #{behaviors := [atom()], devices := [atom()],
                            layers := #{non_neg_integer() => [atom()]},
                            removed_layers := [non_neg_integer()]}.
local_overview() ->
    {W, Removed} = toroco_wiring:call(wiring),
    Nodes = lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
    Behaviors = [{N, L} || {N, #{kind := behavior, layer := L}} <- Nodes],
    Base = #{behaviors => [N || {N, _} <- Behaviors],
             devices => [N || {N, #{kind := device}} <- Nodes],
             layers => lists:foldl(fun({N, L}, Acc) ->
                                           maps:update_with(L, fun(Ns) -> Ns ++ [N] end, [N], Acc)
                                   end, #{}, Behaviors),
             removed_layers => Removed},
    %% A robot of one node keeps the map of SPEC §6 as it is.
    Clashes = toroco_wiring:call(clashes),
    case map_size(toroco_wiring_core:remote(W)) =:= 0 andalso Clashes =:= []
        andalso toroco_wiring:peers() =:= [node()] of
        true -> Base;
        false -> Base#{nodes => maps:from_list([{N, node()} || {N, _} <- Nodes]),
                       name_clashes => Clashes}
    end.

-spec describe(atom()) -> map() | {error, term()}.
describe(Name) ->
    case toroco_wiring:call({node, Name}) of
        {ok, Info} -> node_map(Name, Info);
        Err -> Err
    end.

%% The map of one node, from its wiring and from what its engine, routers
%% and gates tell.
node_map(Name, #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs0,
                 inputs_wired := Wired, inhibitors := Inhs, gates := Gates}) ->
    Engine = case toroco_behavior:info(Name) of
                 #{} = I -> I;
                 {error, _} -> #{status => down, latches => #{}}
             end,
    Latches = maps:get(latches, Engine),
    %% a behavior with open ports has the outputs it emitted on too
    Outs = lists:usort(Outs0 ++ maps:get(outputs, Engine, [])),
    Base = #{name => Name, kind => Kind, module => M, layer => L, node => node(),
             status => maps:get(status, Engine),
             restarts => toroco_restarts:count(Name),
             process => maps:with([state, mailbox], Engine),
             inputs => maps:from_list([{I, input(Name, I, Wired)} || I <- Ins]),
             outputs => maps:from_list(
                          [{O, output(Name, O, maps:get(O, Inhs, []), Gates, Latches)}
                           || O <- Outs])},
    B1 = case Wired of
             #{'$reset' := #{sources := Srcs}} -> Base#{reset => [S || {S, _} <- Srcs]};
             #{} -> Base
         end,
    %% a device's counters, a behavior's own workings (the optional info/2)
    maps:merge(B1, maps:with([device, behavior], Engine)).

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
    {Inhibited, Holds} = case Gates of
                             #{{Name, O} := Key} ->
                                 case toroco_gate:info(Key) of
                                     #{{Name, O} := #{inhibited := I, holds := H}} -> {I, H};
                                     _ -> {false, []}
                                 end;
                             #{} -> {false, []}
                         end,
    #{inhibited => Inhibited, inhibitors => [S || {S, _} <- Inhibitors],
      inhibitor_holds => Holds,
      latch => case Latches of
                   #{O := V} -> {value, V};
                   #{} -> none
               end}.
