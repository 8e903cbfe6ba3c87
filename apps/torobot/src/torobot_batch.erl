%% @doc Batch evaluation in the simulated lab (SPEC §14): many worlds, each
%% run several times, several runs at once, on one node or spread over
%% several connected Erlang nodes, scored.
%%
%% {@link run/1} (also `torobot_sim:batch/1') checks everything first, then
%% runs:
%% <ol>
%% <li>the options: one it does not know is refused as `{error,
%%     {bad_option, Key}}', a bad value as `{error, {Option, Value}}'
%%     (`runs', `speed', `parallel', `time', `nodes');</li>
%% <li>every world is loaded (files) or generated (`{generated, N, Seed}':
%%     seeds Seed .. Seed + N - 1 of `torobot_worlds:generate/2'); a bad one
%%     is refused as `{error, {world, Name, Reason}}';</li>
%% <li>the wiring is tried once on a scratch robot node (its devices, its
%%     behaviors, its wiring, exactly as a run starts them); a bad one is
%%     refused as `{error, {wiring, File, Reason}}';</li>
%% <li>only then the runs start (below).</li>
%% </ol>
%%
%% Time: `time => lockstep' (the default) runs every world in lockstep
%% (`torobot_sim', SPEC §14 "Lockstep"): a run depends only on its world,
%% the wiring and the seed, and goes as fast as the CPU allows; `time =>
%% realtime' runs it `speed' (default 10) times faster than real time, and
%% its outcome then depends on the machine's load. `speed' means nothing in
%% lockstep.
%%
%% Where the runs go: `nodes' (default `[node()]') lists connected Erlang
%% nodes that have this code (the same release or checkout: nothing is
%% loaded onto them). The runs are dealt to them in turn (run I of the
%% batch, counting every world's runs in order, goes to node I rem K of the
%% K nodes), and each node runs its share `parallel' at a time (default:
%% that node's schedulers online) on worker nodes of its own: an OTP `peer'
%% per slot, over its standard I/O, started by {@link worker/2} on that
%% node, which runs one world after another with `torobot_sim:simulate/2'
%% (its robot in the worker, `nodes => local'; a world of named robots on
%% peers of the worker's). The world's terms and the wiring's text travel
%% with the runs, so the other nodes need neither file. A node that is not
%% connected (and cannot be) or dies mid-batch wedges nothing: the runs of
%% its share that did not come back are failures `{node, Node, Reason}',
%% the other nodes' runs go on, and nothing is retried elsewhere.
%%
%% The report: per world and overall, the runs, the success rate (red
%% touched), time to red p50 and p90 (over the runs that touched it, in
%% world ms; `none' when none did), wall and blue contacts per minute of
%% world time, and the mean distance; every run with its final world; the
%% failures; the `time', `speed' and `wiring' it ran with. Each robot of a
%% world of several counts as a run. In lockstep the report is the same
%% whatever the nodes, their number, `parallel' or the machine's load, and
%% the same for two batches of the same options: only `wall_ms' (the wall
%% time of the batch) naturally differs. `torobot_eval' prints it and
%% draws it.
%%
%% Options: `worlds' (required), `runs' (1), `time' (`lockstep'), `speed'
%% (10), `nodes' (`[node()]'), `parallel' (per node), `wiring' (app env
%% `wiring' of `torobot', else `config/torobot.wiring'), `generate'
%% (options of `torobot_worlds:generate/2' for generated worlds).
-module(torobot_batch).

-export([run/1, percentile/2, calls/3]).
%% the node side of a batch: what another node runs for it
-export([worker/2]).

-export_type([opts/0, report/0, row/0, run/0]).

-type opts() :: #{worlds := [file:name_all()] | {generated, pos_integer(), integer()},
                  runs => pos_integer(), time => lockstep | realtime, speed => number(),
                  nodes => [node(), ...], wiring => file:name_all(),
                  parallel => pos_integer(), generate => torobot_worlds:opts()}.
-type row() :: #{world := binary(), runs := non_neg_integer(), success_rate := float(),
                 red_p50_ms := non_neg_integer() | none, red_p90_ms := non_neg_integer() | none,
                 wall_contacts_per_min := float(), blue_contacts_per_min := float(),
                 distance_m := float(), failed := non_neg_integer()}.
-type run() :: #{world := binary(), run := pos_integer(), robot := atom() | undefined,
                 summary := torobot_world:summary(), time_ms := non_neg_integer(),
                 final := torobot_world:world()}.
-type report() :: #{worlds := [row()], overall := row(), runs := [run()],
                    failures := [{binary(), pos_integer(), term()}],
                    time := lockstep | realtime, speed := number(),
                    wiring := file:name_all(), wall_ms := non_neg_integer()}.

-define(OPTIONS, [worlds, runs, time, speed, nodes, wiring, parallel, generate]).
%% How long a node has to say how many cores it has, and a worker to start.
-define(ASK_MS, 10000).
-define(PEER_BOOT_MS, 30000).
%% How long past a run's own limit (torobot_sim's) a worker waits for it.
-define(RUN_GRACE_MS, 60000).
%% A call of calls/3 (one lockstep run of the robustness lab, or a few).
-define(CALL_LIMIT_MS, 600000).

%% @doc Runs the batch and reports; nothing runs unless every option, every
%% world and the wiring are good.
-spec run(opts()) -> {ok, report()} | {error, term()}.
run(Opts) when is_map(Opts) ->
    case lists:sort(maps:keys(Opts) -- ?OPTIONS) of
        [Key | _] -> {error, {bad_option, Key}};
        [] -> check(Opts)
    end;
run(Opts) ->
    {error, {opts, Opts}}.

check(#{worlds := Worlds} = Opts) ->
    Runs = maps:get(runs, Opts, 1),
    Time = maps:get(time, Opts, lockstep),
    Speed = maps:get(speed, Opts, 10),
    Nodes = maps:get(nodes, Opts, [node()]),
    Parallel = maps:get(parallel, Opts, auto),
    Wiring = maps:get(wiring, Opts,
                      application:get_env(torobot, wiring, "config/torobot.wiring")),
    if
        not is_integer(Runs); Runs < 1 -> {error, {runs, Runs}};
        Time =/= lockstep, Time =/= realtime -> {error, {time, Time}};
        not is_number(Speed); Speed =< 0 -> {error, {speed, Speed}};
        Parallel =/= auto, not is_integer(Parallel); Parallel =/= auto, Parallel < 1 ->
            {error, {parallel, Parallel}};
        true ->
            case {good_nodes(Nodes), worlds(Worlds, maps:get(generate, Opts, #{}))} of
                {false, _} ->
                    {error, {nodes, Nodes}};
                {true, {ok, Named}} ->
                    case try_wiring(Wiring, Named) of
                        {ok, Text} ->
                            Setup = #{time => Time, speed => Speed, wiring => Wiring,
                                      text => Text, parallel => Parallel},
                            {ok, batch(Named, Runs, Nodes, Setup)};
                        {error, _} = Error ->
                            Error
                    end;
                {true, {error, _} = Error} ->
                    Error
            end
    end;
check(Opts) ->
    {error, {missing, worlds, Opts}}.

good_nodes(Nodes) ->
    is_list(Nodes) andalso Nodes =/= [] andalso lists:all(fun is_atom/1, Nodes)
        andalso length(lists:usort(Nodes)) =:= length(Nodes).

%% @doc The P-th percentile (0-100, nearest rank) of a list of numbers;
%% `none' for an empty list.
-spec percentile([number()], number()) -> number() | none.
percentile([], _P) ->
    none;
percentile(Values, P) ->
    Sorted = lists:sort(Values),
    Rank = max(1, ceil(P / 100 * length(Sorted))),
    lists:nth(Rank, Sorted).

%%====================================================================
%% Checking first
%%====================================================================

worlds({generated, N, Seed}, GenOpts) when is_integer(N), N > 0, is_integer(Seed) ->
    {ok, [{iolist_to_binary(["seed ", integer_to_list(S)]), torobot_worlds:generate(S, GenOpts)}
          || S <- lists:seq(Seed, Seed + N - 1)]};
worlds(Files, _GenOpts) when is_list(Files), Files =/= [] ->
    %% a world travels as its terms: the nodes that run it need not have
    %% the file
    Loaded = [{File, file:consult(File)} || File <- Files],
    Checked = [{File, case Read of
                          {ok, Terms} -> torobot_world:from_terms_all(Terms);
                          {error, Why} -> {error, {file, Why}}
                      end} || {File, Read} <- Loaded],
    case [{File, Reason} || {File, {error, Reason}} <- Checked] of
        [{File, Reason} | _] ->
            {error, {world, File, Reason}};
        [] ->
            {ok, [{unicode:characters_to_binary(filename:basename(F)), Terms}
                  || {F, {ok, Terms}} <- Loaded]}
    end;
worlds(Other, _GenOpts) ->
    {error, {worlds, Other}}.

%% The wiring, tried on a robot node as a run would start it; its text, to
%% send to the other nodes.
try_wiring(Wiring, [{_, Spec} | _]) ->
    case {toroco:read_wiring(Wiring), file:read_file(Wiring)} of
        {{error, {wiring_file, {_, Reason}}}, _} ->
            {error, {wiring, Wiring, Reason}};
        {_, {error, Reason}} ->
            {error, {wiring, Wiring, Reason}};
        {{ok, _}, {ok, Text}} ->
            {ok, [World | _]} = torobot_world:from_terms_all(Spec),
            Opts = #{wiring => Wiring, speed => 1,
                     thresholds => torobot_world:ir_thresholds(World),
                     %% the library's sensors, as a run adds them
                     sensors => [{Name, Os} || {Name, Outputs} <- torobot_sensors:devices(),
                                               Os <- [Outputs(World)], Os =/= []]},
            case torobot_sim_robot:start_peer(Opts) of
                {ok, Handle, _Port} -> ok = torobot_sim_robot:stop_peer(Handle), {ok, Text};
                {error, Reason} -> {error, {wiring, Wiring, Reason}}
            end
    end.

%%====================================================================
%% Running
%%====================================================================

batch(Named, Runs, Nodes, Setup) ->
    T0 = erlang:monotonic_time(millisecond),
    Jobs = [{Name, Spec, I} || {Name, Spec} <- Named, I <- lists:seq(1, Runs)],
    Results = spread(lists:enumerate(Jobs), Nodes, Setup),
    RunRows = [#{world => Name, run => I, robot => torobot_world:name(W),
                 summary => torobot_world:summary(W), time_ms => torobot_world:time_ms(W),
                 final => W}
               || {{Name, _, I}, {ok, Finals}} <- lists:zip(Jobs, Results),
                  W <- as_list(Finals)],
    Failures = [{Name, I, Reason} || {{Name, _, I}, {error, Reason}} <- lists:zip(Jobs, Results)],
    #{worlds => [row(Name, [R || R = #{world := N} <- RunRows, N =:= Name],
                     length([F || {N, _, _} = F <- Failures, N =:= Name]))
                 || {Name, _} <- Named],
      overall => row(<<"overall">>, RunRows, length(Failures)),
      runs => RunRows,
      failures => Failures,
      time => maps:get(time, Setup),
      speed => maps:get(speed, Setup),
      wiring => maps:get(wiring, Setup),
      wall_ms => erlang:monotonic_time(millisecond) - T0}.

as_list(Worlds) when is_list(Worlds) -> Worlds;
as_list(World) -> [World].

%% Deals the jobs to the nodes in turn and runs each node's share on it;
%% the results in job order.
spread(Indexed, Nodes, Setup) ->
    K = length(Nodes),
    Shares = [{Node, [Job || {I, _} = Job <- Indexed, (I - 1) rem K =:= J - 1]}
              || {J, Node} <- lists:enumerate(Nodes)],
    Self = self(),
    Pids = [spawn_link(fun() -> Self ! {self(), share(Node, Share, Setup)} end)
            || {Node, Share} <- Shares, Share =/= []],
    Done = lists:append([receive {Pid, Results} -> Results end || Pid <- Pids]),
    [Result || {_, Result} <- lists:sort(Done)].

%% One node's share: a worker per slot on that node, each given the next
%% run when it is free; [{I, Result}].
share(Node, Jobs, Setup) ->
    case connect(Node) andalso slots(Node, maps:get(parallel, Setup)) of
        false ->
            [{I, {error, {node, Node, not_connected}}} || {I, _} <- Jobs];
        {error, Reason} ->
            [{I, {error, {node, Node, Reason}}} || {I, _} <- Jobs];
        Slots ->
            Work = maps:with([time, speed, wiring, text], Setup),
            Workers = [spawn_monitor(Node, ?MODULE, worker, [self(), Work])
                       || _ <- lists:seq(1, min(Slots, length(Jobs)))],
            deal(Node, Jobs, maps:from_list([{Pid, idle} || {Pid, _} <- Workers]), #{},
                 not_connected)
    end.

connect(Node) when Node =:= node() -> true;
connect(Node) -> net_kernel:connect_node(Node).

slots(_Node, Parallel) when is_integer(Parallel) ->
    Parallel;
slots(Node, auto) ->
    slots(Node, {auto, 1});
slots(Node, {auto, K}) ->
    try K * erpc:call(Node, erlang, system_info, [schedulers_online], ?ASK_MS)
    catch Class:Reason -> {error, {Class, Reason}}
    end.

%% The share's process and its workers (worker/2), plain messages under
%% monitors (the worker's of its share, the share's of each worker):
%%
%%   from     to       message            when
%%   worker   share    {Worker, ready}    its peer is up
%%   share    worker   {run, I, Spec}     it is free and a run is left
%%   worker   share    {Worker, I, Res}   run I ended: {ok, Final(s)} | {error, R}
%%   share    worker   stop               it is free and no run is left
%%
%% Workers: idle (not yet started or free) or busy with run I. A worker
%% gone while busy fails its run naming the node; when no worker is left
%% the runs not done fail with the last one's reason.
deal(Node, Jobs, Workers, Done, Why) when map_size(Workers) =:= 0 ->
    maps:to_list(Done) ++ [{I, {error, {node, Node, Why}}} || {I, _} <- Jobs];
deal(Node, Jobs, Workers, Done, Why) ->
    receive
        {Pid, ready} when is_map_key(Pid, Workers) ->
            next(Node, Pid, Jobs, Workers, Done, Why);
        {Pid, I, Result} when is_map_key(Pid, Workers) ->
            next(Node, Pid, Jobs, Workers, Done#{I => Result}, Why);
        {'DOWN', _, process, Pid, Reason} when is_map_key(Pid, Workers) ->
            Done1 = case maps:get(Pid, Workers) of
                        idle -> Done;
                        I -> Done#{I => {error, {node, Node, Reason}}}
                    end,
            deal(Node, Jobs, maps:remove(Pid, Workers), Done1, Reason)
    end.

next(Node, Pid, [{I, {_Name, Spec, _Run}} | Jobs], Workers, Done, Why) ->
    Pid ! {run, I, Spec},
    deal(Node, Jobs, Workers#{Pid := I}, Done, Why);
next(Node, Pid, [], Workers, Done, Why) ->
    Pid ! stop,
    deal(Node, [], Workers#{Pid := idle}, Done, Why).

%% @doc A worker of a batch, spawned on each node by the node running the
%% batch (one per slot): starts a node of its own (an OTP `peer' with this
%% node's code path and application environment), says `ready' and runs
%% the worlds it is sent there one after another with
%% `torobot_sim:simulate/2', answering each with its result; stops (its
%% peer with it) when told to or when the batch goes away. A run that fails
%% leaves the peer to be replaced before the next one.
-spec worker(pid(), #{time := lockstep | realtime, speed := number(),
                      wiring := file:name_all(), text := binary()}) -> ok.
worker(Batch, #{time := Time, speed := Speed} = Work) ->
    monitor(process, Batch),
    Wiring = case Work of
                 #{text := <<>>} -> maps:get(wiring, Work);
                 _ -> wiring_here(Batch, Work)
             end,
    SimOpts = case Time of
                  lockstep -> #{time => lockstep, wiring => Wiring, nodes => local};
                  realtime -> #{time => realtime, speed => Speed, wiring => Wiring,
                                nodes => local}
              end,
    case start_worker_peer() of
        {ok, Peer} ->
            Batch ! {self(), ready},
            work(Batch, Peer, SimOpts);
        {error, Reason} ->
            exit({peer, Reason})
    end.

work(Batch, Peer, SimOpts) ->
    receive
        {run, I, {M, F, A}} ->
            Result = try peer:call(Peer, M, F, A, ?CALL_LIMIT_MS)
                     catch Class:Reason -> {error, {run, Class, Reason}}
                     end,
            Batch ! {self(), I, Result},
            work(Batch, Peer, SimOpts);
        {run, I, Spec} ->
            Result = try peer:call(Peer, torobot_sim, simulate, [Spec, SimOpts],
                                   run_limit(Spec, SimOpts))
                     catch Class:Reason -> {error, {run, Class, Reason}}
                     end,
            Batch ! {self(), I, Result},
            case Result of
                {ok, _} ->
                    work(Batch, Peer, SimOpts);
                _ ->
                    stop_worker_peer(Peer),
                    case start_worker_peer() of
                        {ok, Peer1} -> work(Batch, Peer1, SimOpts);
                        {error, Reason1} -> exit({peer, Reason1})
                    end
            end;
        stop ->
            stop_worker_peer(Peer);
        {'DOWN', _, process, Batch, _} ->
            stop_worker_peer(Peer)
    end.

%% The wiring file: the batch's own on its node, else its text written
%% once here under a name of its content.
wiring_here(Batch, #{wiring := Wiring}) when node(Batch) =:= node() ->
    Wiring;
wiring_here(_Batch, #{wiring := Wiring, text := Text}) ->
    Hash = binary:encode_hex(erlang:md5(Text)),
    Dir = filename:join(filename:basedir(user_cache, "torobot"), "batch"),
    File = filename:join(Dir, [binary_to_list(Hash), "_", filename:basename(Wiring)]),
    case file:read_file(File) of
        {ok, Text} ->
            File;
        _ ->
            Tmp = [File, ".", os:getpid(), ".", integer_to_list(erlang:unique_integer([positive]))],
            ok = filelib:ensure_dir(File),
            ok = file:write_file(Tmp, Text),
            ok = file:rename(Tmp, File),
            File
    end.

%% What torobot_sim itself allows a run, and a margin.
run_limit(Spec, SimOpts) ->
    {ok, [World | _]} = torobot_world:from_terms_all(Spec),
    Ms = torobot_world:duration_ms(World),
    case SimOpts of
        #{time := lockstep} -> Ms;
        #{speed := Speed} -> round(Ms / Speed)
    end + 2 * ?RUN_GRACE_MS.

start_worker_peer() ->
    Root = code:root_dir(),
    Paths = [P || P <- code:get_path(), not lists:prefix(Root, P)],
    Env = [{App, K, V} || App <- [toroco, toroco_hw, torobot],
                          {K, V} <- application:get_all_env(App)],
    #{level := Level} = logger:get_primary_config(),
    case peer:start_link(#{connection => standard_io, args => ["-pa" | Paths],
                           wait_boot => ?PEER_BOOT_MS}) of
        {ok, Peer, _Node} ->
            try
                ok = peer:call(Peer, logger, set_primary_config, [level, Level], ?ASK_MS),
                %% loaded first: an application's .app file would override
                %% what is set before it is loaded
                _ = [peer:call(Peer, application, load, [App], ?ASK_MS)
                     || App <- [toroco, toroco_hw, torobot]],
                _ = [peer:call(Peer, application, set_env, [App, K, V], ?ASK_MS)
                     || {App, K, V} <- Env],
                {ok, Peer}
            catch
                Class:Reason ->
                    stop_worker_peer(Peer),
                    {error, {Class, Reason}}
            end;
        {error, Reason} ->
            {error, Reason}
    end.

stop_worker_peer(Peer) ->
    unlink(Peer),
    try peer:stop(Peer)
    catch exit:_ -> ok
    end.

%% @doc Runs calls `{M, F, A}' of this code on worker nodes as a batch's
%% runs are (one worker peer per slot, `parallel' slots on each of
%% `nodes', dealt in turn) and answers their results in order; a call
%% whose node or worker fails is `{error, {node, Node, Reason}}'. The
%% robustness lab (`torobot_chaos') runs its schedules so.
-spec calls([{module(), atom(), [term()]}], [node(), ...],
            pos_integer() | auto | {auto, pos_integer()}) -> [term()].
calls(Calls, Nodes, Parallel) ->
    Setup = #{parallel => Parallel, time => lockstep, speed => 1,
              wiring => "config/torobot.wiring", text => <<>>},
    spread(lists:enumerate([{call, MFA, 1} || MFA <- Calls]), Nodes, Setup).

%%====================================================================
%% Scoring
%%====================================================================

row(Name, Runs, Failed) ->
    Reds = [Ms || #{summary := #{red_touched_ms := Ms}} <- Runs, Ms =/= none],
    Minutes = lists:sum([T || #{time_ms := T} <- Runs]) / 60000,
    Sum = fun(Key) -> lists:sum([maps:get(Key, S) || #{summary := S} <- Runs]) end,
    PerMin = fun(Key) when Minutes > 0 -> Sum(Key) / Minutes;
                (_) -> 0.0
             end,
    N = length(Runs),
    #{world => Name,
      runs => N,
      failed => Failed,
      success_rate => case N of
                          0 -> 0.0;
                          _ -> length(Reds) / N
                      end,
      red_p50_ms => percentile(Reds, 50),
      red_p90_ms => percentile(Reds, 90),
      wall_contacts_per_min => float(PerMin(wall_contacts)),
      blue_contacts_per_min => float(PerMin(blue_contacts)),
      distance_m => case N of
                        0 -> 0.0;
                        _ -> Sum(distance_m) / N
                    end}.
