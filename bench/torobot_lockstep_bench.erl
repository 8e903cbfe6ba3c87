%% Lockstep (a section of `make bench', TOROCO_BENCH_ONLY=lockstep): the
%% default world with the Torobot's wiring run in lockstep, several times,
%% each with a trace; one table row per run: the VM's flags (`scripts/bench'
%% starts a VM per setting: schedulers, `+T', a CPU burner), the trace's
%% SHA-256, the summary and the wall time. Every row must show the same
%% SHA-256: that is what lockstep promises.
%%
%% Then the split Torobot (config/torobot_split.wiring) in one lockstep
%% world over this node and a peer on loopback (SPEC §13): its rows must
%% show one SHA-256 too (its lines name the nodes, whose names are fixed
%% here for that), the one-node run's summary, and a last line gives its
%% median wall time over the one-node run's (at most 3).
%%
%% `main/1' takes the results directory, the root of the checkout, the
%% label of the VM's setting and the number of runs.
-module(torobot_lockstep_bench).
-export([main/1]).

main([Dir, Root, Label, Runs]) ->
    Wiring = filename:join([Root, "config", "torobot.wiring"]),
    World = filename:join([Root, "config", "worlds", "default.world"]),
    One = runs(Dir, World, Wiring, Label, Runs),
    Split = split(Dir, Root, World, Label, Runs),
    io:format("| ~s | split / one node | | median wall time ratio | ~.2f |~n",
              [Label, median(Split) / median(One)]),
    %% the red follower crashing every 2 s (its exits and restarts are steps)
    {ok, Terms} = file:consult(Wiring),
    Crashing = filename:join(Dir, "crashing.wiring"),
    ok = file:write_file(Crashing, [io_lib:format("~tp.~n", [case T of
                                                              {behavior, red_follower, _, O} ->
                                                                  {behavior, red_follower,
                                                                   torobot_crashing_follower, O};
                                                              _ -> T
                                                          end]) || T <- Terms]),
    logger:set_primary_config(level, critical),
    runs(Dir, filename:join([Root, "test", "worlds", "red_crashing.world"]), Crashing,
         Label ++ ", red follower crashing", Runs),
    halt(0).

runs(Dir, World, Wiring, Label, Runs) ->
    Trace = filename:join(Dir, "lockstep.trace"),
    [begin
         T0 = erlang:monotonic_time(microsecond),
         {ok, Summary} = torobot_sim:run(World, #{time => lockstep, trace => Trace,
                                                  wiring => Wiring}),
         Wall = (erlang:monotonic_time(microsecond) - T0) / 1000,
         {ok, Bin} = file:read_file(Trace),
         Sha = binary:encode_hex(crypto:hash(sha256, Bin)),
         io:format("| ~s | ~b | ~s | ~s | ~b |~n",
                   [Label, I, Sha, torobot_sim:summary_json(Summary), round(Wall)]),
         Wall
     end || I <- lists:seq(1, list_to_integer(Runs))].

%% The split Torobot, this node its board and a peer its laptop.
split(Dir, Root, World, Label, Runs) ->
    {ok, _} = net_kernel:start(['lockstep_board@127.0.0.1', longnames]),
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    {ok, Peer, Laptop} = peer:start(#{name => lockstep_laptop, host => "127.0.0.1",
                                      longnames => true,
                                      args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                               "-config", filename:join([Root, "config", "sim"]),
                                               "-pa" | Paths]}),
    {ok, _} = erpc:call(Laptop, application, ensure_all_started, [toroco]),
    {ok, Text} = file:read_file(filename:join([Root, "config", "torobot_split.wiring"])),
    Wiring = filename:join(Dir, "split.wiring"),
    ok = file:write_file(Wiring, binary:replace(Text, <<"'laptop@127.0.0.1'">>,
                                                iolist_to_binary(io_lib:format("~0p", [Laptop])),
                                                [global])),
    try
        runs(Dir, World, Wiring, Label ++ ", split over 2 nodes", Runs)
    after
        peer:stop(Peer),
        net_kernel:stop()
    end.

median(Walls) ->
    lists:nth((length(Walls) + 1) div 2, lists:sort(Walls)).
