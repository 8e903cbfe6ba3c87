%% The split Torobot (config/torobot_split.wiring) in one lockstep world
%% over two nodes (SPEC §13, §17): "the laptop" is a peer on loopback.
-module(torobot_split_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, init_per_suite/1, end_per_suite/1]).
-export([split_run_is_exact/0, disconnect_takeover_at_deadline/0, bad_nodes_refused/0,
         partition_found_shrunk_replayed/0, long_cut_fires_monitors/0, killed_node_lets_go_at_once/0]).
-export([split_run_is_exact/1, disconnect_takeover_at_deadline/1, bad_nodes_refused/1,
         partition_found_shrunk_replayed/1, long_cut_fires_monitors/1, killed_node_lets_go_at_once/1]).

all() ->
    [bad_nodes_refused, split_run_is_exact, disconnect_takeover_at_deadline,
     long_cut_fires_monitors, killed_node_lets_go_at_once, partition_found_shrunk_replayed].

init_per_suite(Config) ->
    logger:set_primary_config(level, error),
    Stop = toroco_test_lib:distributed("split_ct"),
    Root = toroco_test_lib:root(),
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    PeerName = list_to_atom("laptop" ++ integer_to_list(erlang:unique_integer([positive]))),
    %% not linked: the case processes come and go; stopped by its handle
    {ok, Peer, Laptop} = peer:start(#{name => PeerName, host => "127.0.0.1", longnames => true,
                                           args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                                    "-pa" | Paths]}),
    {ok, _} = erpc:call(Laptop, application, ensure_all_started, [toroco]),
    %% the split wiring with the peer as its laptop
    {ok, Text} = file:read_file(filename:join([Root, "config", "torobot_split.wiring"])),
    Wiring = filename:join(?config(priv_dir, Config), "split.wiring"),
    ok = file:write_file(Wiring, binary:replace(Text, <<"'laptop@127.0.0.1'">>,
                                                iolist_to_binary(io_lib:format("~0p", [Laptop])),
                                                [global])),
    [{peer, Peer}, {laptop, Laptop}, {split, Wiring}, {stop_dist, Stop},
     {world, filename:join([Root, "config", "worlds", "default.world"])},
     {one_node, filename:join([Root, "config", "torobot.wiring"])} | Config].

end_per_suite(Config) ->
    ok = peer:stop(?config(peer, Config)),
    _ = ?config(stop_dist, Config) andalso net_kernel:stop(),
    logger:set_primary_config(level, notice).

%%====================================================================

bad_nodes_refused() ->
    [{doc, "A wiring naming a node that is not connected, and a disconnect of the world's "
      "own node or of a node the wiring lacks, are refused before anything runs."}].
bad_nodes_refused(Config) ->
    Bad = filename:join(?config(priv_dir, Config), "bad.wiring"),
    ok = file:write_file(Bad, "{behavior, forward, torobot_forward, #{node => 'nowhere@127.0.0.1', "
                              "layer => 0, params => #{speed => 80}}}.\n"),
    ?assertEqual({error, {node_not_connected, 'nowhere@127.0.0.1'}},
                 torobot_sim:run(?config(world, Config), #{time => lockstep, wiring => Bad})),
    Own = {at, 1000, {disconnect, node(), 500}},
    ?assertMatch({error, {own_node, {_, Own}}},
                 torobot_chaos:run(#{world => ?config(world, Config), wiring => ?config(split, Config),
                                     faults => [Own]})),
    Other = {at, 1000, {disconnect, 'nowhere@127.0.0.1', 500}},
    ?assertMatch({error, {unknown_node, {_, Other}}},
                 torobot_chaos:run(#{world => ?config(world, Config), wiring => ?config(split, Config),
                                     faults => [Other]})).

split_run_is_exact() ->
    [{doc, "The split Torobot in lockstep gives a byte-identical trace twice, each line "
      "naming its node, and the one-node run's summary."}].
split_run_is_exact(Config) ->
    Dir = ?config(priv_dir, Config),
    [A, B] = [filename:join(Dir, N) || N <- ["a.trace", "b.trace"]],
    {ok, SumA} = torobot_sim:run(?config(world, Config), #{time => lockstep, trace => A,
                                                           wiring => ?config(split, Config)}),
    {ok, SumB} = torobot_sim:run(?config(world, Config), #{time => lockstep, trace => B,
                                                           wiring => ?config(split, Config)}),
    %% the one-node run on a node of its own: the laptop's directory of
    %% names would otherwise keep this node's one-node behaviors
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    {ok, OnePeer, OneNode} = peer:start(#{name => list_to_atom("one" ++ integer_to_list(
                                                                          erlang:unique_integer([positive]))),
                                          host => "127.0.0.1", longnames => true,
                                          args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                                   "-connect_all", "false", "-pa" | Paths]}),
    {ok, One} = erpc:call(OneNode, torobot_sim, run, [?config(world, Config),
                                                      #{time => lockstep,
                                                        wiring => ?config(one_node, Config)}]),
    ok = peer:stop(OnePeer),
    {ok, BinA} = file:read_file(A),
    {ok, BinB} = file:read_file(B),
    ?assertEqual(crypto:hash(sha256, BinA), crypto:hash(sha256, BinB)),
    ?assertEqual(SumA, SumB),
    ?assertEqual(One, SumA),
    Laptop = atom_to_binary(?config(laptop, Config)),
    ?assertMatch({_, _}, binary:match(BinA, <<" ", Laptop/binary, " toroco:red_follower deliver">>)),
    ?assertMatch({_, _}, binary:match(BinA, <<" ", (atom_to_binary(node()))/binary,
                                              " toroco:motors deliver">>)).

disconnect_takeover_at_deadline() ->
    [{doc, "Cutting the laptop while it follows red, the board's motors router lets "
      "red_follower go at the simulated instant its max age says (the last word heard "
      "from it + 300 ms), to the millisecond; the trace shows the cut and the heal, and "
      "red is followed again after it."}].
disconnect_takeover_at_deadline(Config) ->
    Laptop = ?config(laptop, Config),
    CutAt = 38000,
    Lines = cut_run(Config, "cut.trace", [{at, CutAt, {disconnect, Laptop, 3000}}]),
    Board = atom_to_list(node()),
    L = atom_to_list(Laptop),
    ?assert(lists:member([integer_to_list(CutAt), Board, "cut", L, "3000"], Lines)),
    ?assert(lists:member([integer_to_list(CutAt + 3000), Board, "heal", L], Lines)),
    %% the last word the motors' router heard from red_follower before the cut
    Heard = lists:max([list_to_integer(T)
                       || [T, N, "toroco:motors/setvel", Kind, "red_follower.motors" | _] <- Lines,
                          N =:= Board, Kind =:= "alive" orelse Kind =:= "emit",
                          list_to_integer(T) =< CutAt]),
    Deadline = Heard + 300,
    ?assert(lists:member([integer_to_list(Deadline), Board, "toroco:motors/setvel", "timer",
                          "{timeout,stale}", "check"], Lines)),
    %% red_follower wins until then, the board's layers from then on
    Winners = [{list_to_integer(T), W} || [T, "wheels", _, _, W] <- Lines],
    [{Away, Layer} | _] = [{T, W} || {T, W} <- Winners, T > CutAt, W =/= "red_follower"],
    ?assertEqual(Deadline, Away),
    ?assert(lists:member(Layer, ["forward", "avoid_left", "avoid_right"])),
    ?assert(lists:any(fun({T, W}) -> T > CutAt + 3000 andalso W =:= "red_follower" end, Winners)).

partition_found_shrunk_replayed() ->
    [{doc, "Exploring partitions of the laptop over 100 seeds finds a property made to fail "
      "on purpose (the board must win within 200 ms of a cut, the laptop's sources' max "
      "age is 300 ms), shrinks it to one cut, and its replay file gives the same trace "
      "and violation."}].
partition_found_shrunk_replayed(Config) ->
    Laptop = ?config(laptop, Config),
    World = filename:join(?config(data_dir, Config), "red_ahead.world"),
    Away = {'not', {any, [{winner, setvel, L} || L <- [red_follower, hold_left, hold_right,
                                                        trq_ignore]]}},
    {ok, R} = torobot_chaos:explore(#{worlds => [World], wiring => ?config(split, Config),
                                      faults => [{rate, 0.1, {disconnect, Laptop, {500, 1500}}}],
                                      property => {always_after, {cut, Laptop}, 200, Away},
                                      runs => runs(), seed => 1, shrink => 1,
                                      dir => filename:join(?config(priv_dir, Config), "chaos")}),
    #{runs := Runs, failed := [#{shrunk := Shrunk} | _], nondeterministic := []} = R,
    ?assertEqual(runs(), Runs),
    #{faults := Faults, violation := {_, At}, sha256 := Sha, replay := File} = Shrunk,
    ?assertMatch([{at, _, {disconnect, Laptop, _}}], Faults),
    ?assertMatch({ok, #{sha256 := Sha, violation := {_, At}}}, torobot_chaos:replay(File)).

runs() ->
    list_to_integer(os:getenv("SPLIT_RUNS", "100")).

long_cut_fires_monitors() ->
    [{doc, "A cut that outlasts the net tick time fires the monitors across it as "
      "`noconnection' at the cut + the net tick time, and at the heal the consumers "
      "subscribe again and red is followed again."}].
long_cut_fires_monitors(Config) ->
    Laptop = ?config(laptop, Config),
    Old = net_kernel:get_net_ticktime(),
    _ = net_kernel:set_net_ticktime(4, 0),
    Lines = try cut_run(Config, "long.trace", [{at, 36000, {disconnect, Laptop, 6000}}])
            after net_kernel:set_net_ticktime(Old, 0)
            end,
    Board = atom_to_list(node()),
    L = atom_to_list(Laptop),
    ?assert(lists:member(["40000", Board, "noconnection", L], Lines)),
    Downs = [{T, N} || [T, N, _, "down", "noconnection"] <- Lines],
    ?assert(lists:member({"40000", Board}, Downs)),
    ?assert(lists:member({"40000", L}, Downs)),
    ?assertEqual([], [T || {T, _} <- Downs, T =/= "40000"]),
    ?assert(lists:member(["42000", Board, "heal", L], Lines)),
    Resub = [T || [T, _, _, "'$toroco_resubscribe'"] <- Lines],
    ?assert(lists:member("42000", Resub)),
    ?assert(lists:any(fun([T, "wheels", _, _, "red_follower"]) -> list_to_integer(T) > 42000;
                         (_) -> false
                      end, Lines)).

killed_node_lets_go_at_once() ->
    [{doc, "A node killed lets its sources go at once (its monitors fire as `noconnection' "
      "at the kill), and its layers never win again."}].
killed_node_lets_go_at_once(Config) ->
    Laptop = ?config(laptop, Config),
    Lines = cut_run(Config, "kill.trace", [{at, 38000, {kill_node, Laptop}}]),
    ?assert(lists:member(["38000", atom_to_list(node()), "kill", atom_to_list(Laptop)], Lines)),
    After = [{list_to_integer(T), W} || [T, "wheels", _, _, W] <- Lines, list_to_integer(T) >= 38000],
    ?assertMatch([{38000, _} | _], After),
    ?assertEqual([], [W || {_, W} <- After, lists:member(W, ["red_follower", "hold_left",
                                                            "hold_right", "trq_ignore"])]).

cut_run(Config, Name, Faults) ->
    Trace = filename:join(?config(priv_dir, Config), Name),
    {ok, _} = torobot_chaos:run(#{world => ?config(world, Config), wiring => ?config(split, Config),
                                  faults => Faults, trace => Trace}),
    {ok, Bin} = file:read_file(Trace),
    [string:split(L, " ", all) || L <- string:split(binary_to_list(Bin), "\n", all), L =/= ""].
