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

-export([overview/0, describe/1]).

%% @doc The network: behaviors and devices by name, the layers and the
%% layers taken out (`toroco:inspect/0').
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

%% @doc One behavior or device (`toroco:inspect/1', SPEC §6): its status,
%% each input with sources, winner, holds, latches and last value, each
%% output with its inhibition and latch; a device's own counters.
-spec describe(atom()) -> map() | {error, term()}.
describe(Name) ->
    case toroco_wiring:call({node, Name}) of
        {ok, Info} -> node_map(Name, Info);
        Err -> Err
    end.

%% The map of one node, from its wiring and from what its engine, routers
%% and gates tell.
node_map(Name, #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs,
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
