%% Lockstep (a section of `make bench', TOROCO_BENCH_ONLY=lockstep): the
%% default world with the Torobot's wiring run in lockstep, several times,
%% each with a trace; one table row per run: the VM's flags (`scripts/bench'
%% starts a VM per setting: schedulers, `+T', a CPU burner), the trace's
%% SHA-256, the summary and the wall time. Every row must show the same
%% SHA-256: that is what lockstep promises.
%%
%% `main/1' takes the results directory, the root of the checkout, the
%% label of the VM's setting and the number of runs.
-module(torobot_lockstep_bench).
-export([main/1]).

main([Dir, Root, Label, Runs]) ->
    Wiring = filename:join([Root, "config", "torobot.wiring"]),
    World = filename:join([Root, "config", "worlds", "default.world"]),
    runs(Dir, World, Wiring, Label, Runs),
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
                   [Label, I, Sha, torobot_sim:summary_json(Summary), round(Wall)])
     end || I <- lists:seq(1, list_to_integer(Runs))].
