%% The robustness lab's speed (a section of `make bench',
%% TOROCO_BENCH_ONLY=chaos): N runs of the default world with the Torobot's
%% wiring under `mixed.faults' at 0.5 faults per simulated second (in all,
%% the file's mix kept: `torobot_chaos:at_rate/2'), on this node's worker peers and then on
%% this node and a second one on loopback; then the shrinking of a failing
%% schedule of 20 faults to its minimum. One table row per measure.
%%
%% `main/1' takes the results directory, the root of the checkout and the
%% number of runs. The VM must be distributed (scripts/bench starts it so)
%% for the two-node row; without, that row says so.
-module(torobot_chaos_bench).
-export([main/1]).

main([_Dir, Root, Runs]) ->
    logger:set_primary_config(level, critical),
    N = list_to_integer(Runs),
    Wiring = filename:join([Root, "config", "torobot.wiring"]),
    World = filename:join([Root, "config", "worlds", "default.world"]),
    Props = filename:join([Root, "config", "props", "torobot.props"]),
    {ok, Names} = torobot_chaos:names(Wiring),
    {ok, Mixed} = torobot_faults:read(filename:join([Root, "config", "faults", "mixed.faults"]), Names),
    Schedule = torobot_chaos:at_rate(Mixed, 0.5),
    Opts = #{worlds => [World], wiring => Wiring, faults => Schedule, property => Props,
             runs => N, seed => 1, shrink => 0},
    io:format("~n## Chaos~n~n| measure | runs | wall (s) | runs/s | failed | nondeterministic |~n"
              "|---|---:|---:|---:|---:|---:|~n"),
    row("1 node", N, fun() -> torobot_chaos:explore(Opts) end),
    case node() of
        nonode@nohost ->
            io:format("| 2 nodes | - | - | - | - | (this VM is not distributed) |~n");
        _ ->
            {ok, Peer, Node} = peer:start(#{name => peer:random_name(chaos_bench),
                                            host => "127.0.0.1", longnames => true,
                                            %% the same code and configuration as this
                                            %% node: a run must not depend on where it goes
                                            args => ["-config", filename:join(Root, "config/sim")
                                                     | ["-pa" | code:get_path() -- lib_paths()]]}),
            try row("2 nodes", N, fun() -> torobot_chaos:explore(Opts#{nodes => [node(), Node]}) end)
            after peer:stop(Peer)
            end
    end,
    shrink20(World, Wiring, Props, Names),
    halt(0).

lib_paths() ->
    Root = code:root_dir(),
    [P || P <- code:get_path(), lists:prefix(Root, P)].

row(Label, N, Explore) ->
    T0 = erlang:monotonic_time(millisecond),
    {ok, R} = Explore(),
    S = (erlang:monotonic_time(millisecond) - T0) / 1000,
    io:format("| explore, ~s | ~b | ~.1f | ~.2f | ~b | ~b |~n",
              [Label, N, S, N / S, length(maps:get(failed, R)),
               length(maps:get(nondeterministic, R))]).

%% A failing schedule of 20 kills (the first 20 of a seed at one kill a
%% second), shrunk.
shrink20(World, Wiring, Props, Names) ->
    {ok, Terms} = file:consult(World),
    Faults = lists:sublist(torobot_faults:concrete([{rate, 1, {kill, any}}], 3, 60000, Names), 20),
    Job = #{world => Terms, wiring => Wiring, schedule => Faults, seed => 3, names => Names,
            property => element(2, torobot_props:read(Props))},
    case torobot_chaos:run_job(Job) of
        {ok, #{violation := none}} ->
            io:format("| shrink 20 faults | - | - | - | (the schedule does not fail) | - |~n");
        {ok, #{violation := V}} ->
            T0 = erlang:monotonic_time(millisecond),
            {ok, #{faults := Min, tried := Tried}} = torobot_chaos:shrink(Job, V),
            S = (erlang:monotonic_time(millisecond) - T0) / 1000,
            io:format("| shrink 20 faults to ~b (~s) | ~b candidate runs | ~.1f | ~.2f | - | - |~n",
                      [length(Min), lists:join("; ", [torobot_faults:describe(F) || {at, _, F} <- Min]),
                       Tried, S, Tried / S])
    end.
