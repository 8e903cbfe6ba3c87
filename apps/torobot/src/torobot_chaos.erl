%% @doc The robustness lab (SPEC §17): fault schedules run in lockstep,
%% properties judged on simulated time, failing schedules shrunk to a
%% minimum and replayed byte for byte.
%%
%% {@link run/1} runs one schedule on one world (in this node, as
%% `torobot_sim:run/2' does) and answers the trace's SHA-256, the first
%% violation of the property and the summary. {@link explore/1} runs N
%% seeded schedules over worker peers and nodes (`torobot_batch:calls/3'),
%% re-runs every failing one to check that its trace is the same (one that
%% is not is `nondeterministic', which must never be), and shrinks the
%% first K failures ({@link shrink/2}: drop faults, then halve durations,
%% noise, losses and delays, then move faults earlier, each candidate run
%% again, until no single reduction still fails). A shrunk failure is
%% written as a replay file that {@link replay/1} runs again.
%% {@link main/1} is `make chaos' and {@link replay_main/1} `make run
%% REPLAY=file'.
%%
%% Everything is checked before anything runs: a bad fault, a name the
%% wiring lacks, a bad time, an unknown condition, a malformed file give
%% `{error, {Reason, Detail}}' (with `File:Line' for files).
-module(torobot_chaos).

-export([run/1, explore/1, replay/1, shrink/2, names/1, at_rate/2]).
-export([run_job/1, main/1, replay_main/1]).
-export_type([run_opts/0, explore_opts/0, report/0]).

-type run_opts() :: #{world := file:name_all() | [tuple()], wiring => file:name_all(),
                      faults => torobot_faults:schedule() | file:name_all(),
                      property => torobot_props:property() | file:name_all(),
                      seed => integer(), trace => file:name_all(),
                      marks => [#{t_ms := non_neg_integer(), kind := atom(), text := iodata()}]}.
-type explore_opts() :: #{worlds := [file:name_all()] | {generated, pos_integer(), integer()},
                          wiring => file:name_all(),
                          faults := torobot_faults:schedule() | file:name_all(),
                          property := torobot_props:property() | file:name_all(),
                          runs => pos_integer(), seed => integer(), nodes => [node()],
                          parallel => pos_integer() | auto | {auto, pos_integer()}, shrink => non_neg_integer(),
                          dir => file:name_all(), progress => boolean()}.
-type report() :: #{runs := non_neg_integer(), passed := non_neg_integer(),
                    failed := [map()], nondeterministic := [integer()], _ => _}.

-define(WIRING, "config/torobot.wiring").
-define(LOG, #{domain => [torobot, chaos]}).
%% at most this many candidate runs for one shrink
-define(SHRINK_TRIES, 400).
%% the simulated devices every run has, besides the wiring's
-define(SIM_DEVICES, [ir, motors, camera, push, wheels, range, bumper, odometry, light, beacon]).

%%====================================================================
%% One run
%%====================================================================

%% @doc Runs one schedule in lockstep: the explicit faults as they are,
%% the generated ones drawn from `seed' (default 0). Answers the SHA-256
%% of the run's trace (hex), the first violation of `property' (default:
%% none to judge) and the summary, with the concrete faults it ran.
-spec run(run_opts()) -> {ok, #{sha256 := binary(), violation := torobot_props:violation(),
                                summary := map(), faults := torobot_faults:concrete()}}
                         | {error, term()}.
run(Opts) when is_map(Opts) ->
    case prepare(Opts) of
        {ok, Job} -> run_job(Job);
        {error, _} = Error -> Error
    end.

%% Everything checked, files read: a job any node of this code can run.
prepare(Opts) ->
    Wiring = maps:get(wiring, Opts, application:get_env(torobot, wiring, ?WIRING)),
    Seed = maps:get(seed, Opts, 0),
    case names(Wiring) of
        {ok, Names} ->
            case {world_terms(maps:get(world, Opts, undefined)),
                  schedule(maps:get(faults, Opts, []), Names),
                  property(maps:get(property, Opts, fun(_) -> true end))} of
                {{error, _} = E, _, _} -> E;
                {_, {error, _} = E, _} -> E;
                {_, _, {error, _} = E} -> E;
                _ when not is_integer(Seed) -> {error, {bad_seed, Seed}};
                {{ok, World}, {ok, Schedule}, {ok, Prop}} ->
                    {ok, #{world => World, wiring => Wiring, schedule => Schedule,
                           property => Prop, seed => Seed, names => Names,
                           trace => maps:get(trace, Opts, undefined),
                           marks => maps:get(marks, Opts, [])}}
            end;
        Error ->
            Error
    end.

%% @private One job (what {@link run/1} prepared): the run, judged.
-spec run_job(map()) -> {ok, map()} | {error, term()}.
run_job(Job = #{world := World, wiring := Wiring, schedule := Schedule, property := Prop,
                seed := Seed, names := Names}) ->
    {ok, [W | _]} = torobot_world:from_terms_all(World),
    Faults = torobot_faults:concrete(Schedule, Seed, torobot_world:duration_ms(W), Names),
    Trace = case maps:get(trace, Job, undefined) of
                undefined -> tmp_trace();
                T -> T
            end,
    Stop = case maps:get(early, Job, false) of
               true -> #{stop => fun(Obs) -> torobot_props:settled(Prop, Obs) end};
               false -> #{}
           end,
    try torobot_sim:observe(World, Stop#{time => lockstep, wiring => Wiring, trace => Trace,
                                         faults => Faults, seed => Seed,
                                         marks => maps:get(marks, Job, [])}) of
        {ok, Final, Obs} ->
            {ok, Bin} = file:read_file(Trace),
            Context = #{faults => Faults, reference => reference(Prop, Job)},
            {ok, #{sha256 => string:lowercase(binary:encode_hex(crypto:hash(sha256, Bin))),
                   violation => torobot_props:violation(Prop, Obs, Context),
                   summary => torobot_world:summary(Final), faults => Faults}};
        {error, _} = Error ->
            Error
    after
        case maps:get(trace, Job, undefined) of
            undefined -> file:delete(Trace);
            _ -> ok
        end
    end.

tmp_trace() ->
    filename:join(filename:basedir(user_cache, "torobot"),
                  ["chaos_", os:getpid(), "_", integer_to_list(erlang:unique_integer([positive])),
                   ".trace"]).

%% The observations of the same world without faults, which `recovers'
%% compares with; run once per world and wiring in a node.
reference(Prop, #{world := World, wiring := Wiring, seed := Seed}) ->
    case mentions_recovers(Prop) of
        false ->
            [];
        true ->
            Key = {?MODULE, reference, erlang:phash2({World, Wiring})},
            case persistent_term:get(Key, none) of
                none ->
                    {ok, _, Obs} = torobot_sim:observe(World, #{time => lockstep, wiring => Wiring,
                                                                seed => Seed}),
                    persistent_term:put(Key, Obs),
                    Obs;
                Obs ->
                    Obs
            end
    end.

mentions_recovers({recovers, _}) -> true;
mentions_recovers({'and', Ps}) -> lists:any(fun mentions_recovers/1, Ps);
mentions_recovers(_) -> false.

%%====================================================================
%% Exploring
%%====================================================================

%% @doc Runs `runs' (default 100) seeded schedules in lockstep, run I with
%% seed `seed' + I - 1 on world (I - 1) rem (number of worlds); judges
%% each, re-runs each failing one once, shrinks the first `shrink'
%% (default 3) failures, writing their replay files under `dir' (default
%% `_build/chaos') `shrunk/'. The same call twice gives the same report
%% but for `wall_ms'.
-spec explore(explore_opts()) -> {ok, report()} | {error, term()}.
explore(Opts) when is_map(Opts) ->
    Runs = maps:get(runs, Opts, 100),
    Seed = maps:get(seed, Opts, 1),
    case check_explore(Opts, Runs, Seed) of
        {ok, Worlds, Job0} ->
            T0 = erlang:monotonic_time(millisecond),
            Jobs = [{Name, Job0#{world => Terms, seed => Seed + I - 1}}
                    || I <- lists:seq(1, Runs),
                       {Name, Terms} <- [lists:nth((I - 1) rem length(Worlds) + 1, Worlds)]],
            Nodes = case Job0 of
                        %% a robot over several nodes runs from this node,
                        %% whose clock its nodes join: one run at a time
                        #{names := #{nodes := [_ | _]}} -> local;
                        #{} -> maps:get(nodes, Opts, [node()])
                    end,
            %% a lockstep run waits on its own steps' hops about half the
            %% time: two runs a scheduler keep the cores busy (measured:
            %% 100 runs in 52.9 s against 62.4 s with one a scheduler, 66.6
            %% s with three, 2 cores)
            Parallel = maps:get(parallel, Opts, {auto, 2}),
            Results = in_batches(Jobs, Nodes, Parallel, maps:get(progress, Opts, false)),
            Rows = [row(Name, Job, Result) || {{Name, Job}, Result} <- lists:zip(Jobs, Results)],
            Failed = [R || R = #{violation := V} <- Rows, V =/= none],
            Again = calls([{?MODULE, run_job, [Job]} || #{job := Job} <- Failed], Nodes, Parallel),
            Nondet = [S || {#{seed := S, sha256 := Sha}, {ok, #{sha256 := Sha2}}}
                               <- lists:zip(Failed, Again), Sha2 =/= Sha],
            Dir = maps:get(dir, Opts, "_build/chaos"),
            K = maps:get(shrink, Opts, 3),
            {ToShrink, Rest} = lists:split(min(K, length(Failed)), Failed),
            Shrunk = [shrunk(F, Dir) || F <- ToShrink],
            Report = #{runs => Runs, passed => Runs - length(Failed) - length(errors(Rows)),
                       failed => [clean(F) || F <- Shrunk ++ Rest],
                       errors => errors(Rows),
                       nondeterministic => Nondet,
                       rows => [maps:remove(job, R) || R <- Rows],
                       wall_ms => erlang:monotonic_time(millisecond) - T0},
            {ok, Report};
        {error, _} = Error ->
            Error
    end.

check_explore(Opts, Runs, Seed) ->
    Known = [worlds, wiring, faults, property, runs, seed, nodes, parallel, shrink, dir, progress],
    case lists:sort(maps:keys(Opts) -- Known) of
        [Bad | _] -> {error, {bad_option, Bad}};
        [] when not is_integer(Runs); Runs < 1 -> {error, {runs, Runs}};
        [] when not is_integer(Seed) -> {error, {seed, Seed}};
        [] ->
            case worlds(maps:get(worlds, Opts, undefined)) of
                {ok, Worlds} ->
                    case prepare(#{world => element(2, hd(Worlds)),
                                   wiring => maps:get(wiring, Opts,
                                                      application:get_env(torobot, wiring, ?WIRING)),
                                   faults => maps:get(faults, Opts, []),
                                   property => maps:get(property, Opts, undefined)}) of
                        {ok, Job} -> {ok, Worlds, maps:remove(trace, Job)};
                        Error -> Error
                    end;
                Error ->
                    Error
            end
    end.

worlds({generated, N, Seed}) when is_integer(N), N > 0, is_integer(Seed) ->
    {ok, [{iolist_to_binary(io_lib:format("generated_~b", [S])), torobot_worlds:generate(S, #{})}
          || S <- lists:seq(Seed, Seed + N - 1)]};
worlds(Files) when is_list(Files), Files =/= [] ->
    lists:foldr(fun(F, {ok, Acc}) ->
                        case world_terms(F) of
                            {ok, Terms} -> {ok, [{iolist_to_binary(filename:basename(F, ".world")),
                                                  Terms} | Acc]};
                            Error -> Error
                        end;
                   (_, Error) -> Error
                end, {ok, []}, Files);
worlds(Other) ->
    {error, {worlds, Other}}.

%% The runs, in batches of 50 with a progress line after each.
in_batches(Jobs, Nodes, Parallel, Progress) ->
    Chunks = chunks(Jobs, 50),
    {Results, _} = lists:mapfoldl(
                     fun(Chunk, Done) ->
                             R = calls([{?MODULE, run_job, [J]} || {_, J} <- Chunk], Nodes, Parallel),
                             Done1 = Done + length(Chunk),
                             Progress andalso io:format("chaos: ~b/~b runs~n", [Done1, length(Jobs)]),
                             {R, Done1}
                     end, 0, Chunks),
    lists:append(Results).

calls(Calls, local, _Parallel) ->
    [try apply(M, F, A) catch Class:Reason -> {error, {Class, Reason}} end || {M, F, A} <- Calls];
calls(Calls, Nodes, Parallel) ->
    torobot_batch:calls(Calls, Nodes, Parallel).

chunks([], _N) -> [];
chunks(L, N) when length(L) =< N -> [L];
chunks(L, N) -> {A, B} = lists:split(N, L), [A | chunks(B, N)].

row(Name, Job = #{seed := Seed}, {ok, #{sha256 := Sha, violation := V, summary := Sum,
                                        faults := Faults}}) ->
    #{world => Name, seed => Seed, sha256 => Sha, violation => V, summary => Sum,
      faults => Faults, job => Job};
row(Name, Job = #{seed := Seed}, Error) ->
    #{world => Name, seed => Seed, error => Error, violation => none, faults => [], job => Job,
      sha256 => <<>>, summary => #{}}.

errors(Rows) ->
    [#{world => W, seed => S, error => E} || #{world := W, seed := S, error := E} <- Rows].

clean(F) -> maps:without([job, summary], F).

shrunk(F = #{job := Job, faults := Faults, violation := V}, Dir) ->
    case shrink(Job#{schedule => Faults}, V) of
        {ok, Min = #{faults := MinFaults, violation := MinV, sha256 := Sha}} ->
            Path = filename:join([Dir, "shrunk", integer_to_list(maps:get(seed, Job)) ++ ".replay"]),
            ok = write_replay(Path, Job#{schedule => MinFaults}, MinV, Sha),
            F#{shrunk => Min#{replay => Path}};
        {error, Reason} ->
            F#{shrunk => #{error => Reason}}
    end.

%%====================================================================
%% Shrinking
%%====================================================================

%% @doc Shrinks a failing job's concrete faults (`schedule' of explicit
%% faults): one reduction at a time, kept when the run still violates the
%% same clause, until none is. Each candidate runs in lockstep here.
-spec shrink(map(), torobot_props:violation()) -> {ok, map()} | {error, term()}.
shrink(Job = #{schedule := Faults}, {Clause, _} = V) ->
    shrink_loop(Job, Faults, V, Clause, 0).

shrink_loop(Job, Faults, _V, Clause, Tried) ->
    case first_failing(Job, candidates(Faults), Clause, Tried) of
        {found, Smaller, V1, Tried1} -> shrink_loop(Job, Smaller, V1, Clause, Tried1);
        {none, Tried1} ->
            case run_job(Job#{schedule => Faults}) of
                {ok, #{sha256 := Sha, violation := V2}} ->
                    {ok, #{faults => Faults, violation => V2, sha256 => Sha, tried => Tried1,
                           lines => [line(F) || F <- Faults]}};
                Error -> {error, Error}
            end
    end.

first_failing(_Job, [], _Clause, Tried) ->
    {none, Tried};
first_failing(_Job, _Candidates, _Clause, Tried) when Tried >= ?SHRINK_TRIES ->
    {none, Tried};
first_failing(Job, [C | Cs], Clause, Tried) ->
    %% a candidate ends as soon as its property is violated for sure
    case run_job(Job#{schedule => C, early => true}) of
        {ok, #{violation := {Clause, _} = V}} -> {found, C, V, Tried + 1};
        _ -> first_failing(Job, Cs, Clause, Tried + 1)
    end.

%% The reductions of a fault list, the biggest first: drop a half, a
%% quarter, ... then one fault (so a single culprit among many is found
%% in a few runs); halve a duration or a magnitude; move one back to the
%% 100 ms before it.
candidates(Faults) ->
    Drops = lists:append([drops(Faults, Size) || Size <- sizes(length(Faults))]),
    Indexed = lists:enumerate(Faults),
    Halves = [replace(Faults, I, H) || {I, F} <- Indexed, H <- halves(F)],
    Moves = [lists:keysort(2, replace(Faults, I, {at, (Ms - 1) div 100 * 100, Fault}))
             || {I, {at, Ms, Fault}} <- Indexed, Ms > 0, Ms rem 100 =/= 0],
    Drops ++ Halves ++ Moves.

sizes(0) -> [];
sizes(N) -> lists:usort(fun(A, B) -> A >= B end, [max(1, N div D) || D <- [2, 4, 8, 16, N]]).

drops(Faults, Size) ->
    N = length(Faults),
    [lists:sublist(Faults, Start - 1) ++ lists:nthtail(min(N, Start - 1 + Size), Faults)
     || Start <- lists:seq(1, N, Size)].

replace(L, I, New) ->
    {A, [_ | B]} = lists:split(I - 1, L),
    A ++ [New | B].

halves({at, _, F}) when element(1, F) =:= kill ->
    [];
halves({at, Ms, F}) ->
    Last = tuple_size(F),
    D = round(element(Last, F)),
    Duration = [{at, Ms, setelement(Last, F, D div 2)} || D > 1],
    Magnitude = case F of
                    {noise, S, Sigma, Dur} when Sigma > 0.01 -> [{at, Ms, {noise, S, Sigma / 2, Dur}}];
                    {camera, loss, P, Dur} when P > 0.01 -> [{at, Ms, {camera, loss, P / 2, Dur}}];
                    {camera, delay, De, Dur} when De > 1 -> [{at, Ms, {camera, delay, De div 2, Dur}}];
                    {slip, W, Fa, Dur} when Fa < 0.99 -> [{at, Ms, {slip, W, (1 + Fa) / 2, Dur}}];
                    _ -> []
                end,
    Duration ++ Magnitude.

line({at, Ms, F}) ->
    iolist_to_binary(io_lib:format("t=~.3f s ~ts", [Ms / 1000, torobot_faults:describe(F)])).

%%====================================================================
%% Replay files
%%====================================================================

write_replay(Path, #{world := World, wiring := Wiring, schedule := Faults, property := Prop,
                     seed := Seed}, Violation, Sha) ->
    ok = filelib:ensure_dir(Path),
    Terms = [{world, World}, {wiring, Wiring}, {faults, Faults}, {seed, Seed},
             {property, printable(Prop)}, {violation, Violation}, {sha256, Sha}],
    file:write_file(Path, ["%% A shrunk failing schedule of the robustness lab: "
                           "make run REPLAY=", Path, "\n"
                           | [io_lib:format("~tp.~n", [T]) || T <- Terms]]).

printable(F) when is_function(F) -> fun_property;
printable(P) -> P.

%% @doc Runs a replay file again in lockstep: the same SHA-256 and
%% violation as when it was written (`expected' has them).
-spec replay(file:name_all()) -> {ok, map()} | {error, term()}.
replay(File) ->
    case torobot_terms:read(File) of
        {ok, Located} ->
            T = maps:from_list([{K, V} || {_, {K, V}} <- Located]),
            case [K || K <- [world, wiring, faults, seed, property], not is_map_key(K, T)] of
                [] ->
                    Prop = case maps:get(property, T) of
                               fun_property -> fun(_) -> true end;
                               P -> P
                           end,
                    %% the violation it had, marked on the dashboard's timeline
                    Marks = case maps:get(violation, T, none) of
                                {Clause, At} -> [#{t_ms => At, kind => violation,
                                                   text => io_lib:format("~0tp", [Clause])}];
                                _ -> []
                            end,
                    case run(#{world => maps:get(world, T), wiring => maps:get(wiring, T),
                               faults => maps:get(faults, T), seed => maps:get(seed, T),
                               property => Prop, marks => Marks}) of
                        {ok, R} -> {ok, R#{expected => maps:with([sha256, violation], T)}};
                        Error -> Error
                    end;
                [Missing | _] ->
                    {error, {bad_replay, {File, {missing, Missing}}}}
            end;
        Error ->
            Error
    end.

%%====================================================================
%% Reading
%%====================================================================

%% @doc What a schedule may name in a wiring file: its behaviors, its
%% devices (and the simulated world's) and its wired inputs.
-spec names(file:name_all()) -> {ok, torobot_faults:names()} | {error, term()}.
names(Wiring) ->
    case toroco:read_wiring(Wiring) of
        {ok, #{behaviors := Bs, devices := Ds, inputs := Inputs, modules := Modules,
               nodes := Nodes}} ->
            Lua = lists:member(toroco_lua, maps:values(Modules)),
            {ok, #{behaviors => lists:sort(Bs),
                   devices => lists:usort(Ds ++ ?SIM_DEVICES),
                   inputs => Inputs,
                   ports => [pru_port | [lua_port || Lua]],
                   nodes => Nodes}};
        {error, {wiring_file, {_, Reason}}} ->
            {error, {wiring, {Wiring, Reason}}}
    end.

world_terms(Terms) when is_list(Terms), Terms =/= [], is_tuple(hd(Terms)) ->
    case torobot_world:from_terms_all(Terms) of
        {ok, [_]} -> {ok, Terms};
        %% the properties judge one robot's run
        {ok, _} -> {error, {world, several_robots}};
        {error, Reason} -> {error, {world, Reason}}
    end;
world_terms(File) when is_list(File); is_binary(File) ->
    case file:consult(File) of
        {ok, Terms} -> world_terms(Terms);
        {error, Reason} -> {error, {world, {File, Reason}}}
    end;
world_terms(Other) ->
    {error, {world, Other}}.

schedule(File, Names) when is_list(File), File =/= [], is_integer(hd(File)) ->
    torobot_faults:read(File, Names);
schedule(File, Names) when is_binary(File) ->
    schedule(binary_to_list(File), Names);
schedule(Schedule, Names) ->
    case torobot_faults:check(Schedule, Names) of
        ok -> {ok, Schedule};
        Error -> Error
    end.

property(undefined) ->
    {error, {bad_property, undefined}};
property(File) when is_list(File), File =/= [], is_integer(hd(File)) ->
    torobot_props:read(File);
property(Prop) ->
    case torobot_props:check(Prop) of
        ok -> {ok, Prop};
        Error -> Error
    end.

%%====================================================================
%% make chaos, make run REPLAY=
%%====================================================================

%% @doc `make chaos': `[Wiring, World, Faults, Props, N, Rates, Nodes,
%% Seed, Dir, Shrink]' (Rates `none' or `0,0.1,...', Nodes `none' or
%% `a@h,b@h', Shrink how many failures to shrink per rate).
%% Prints the table, writes `Dir'; halts 0, or 2 on bad input.
-spec main([string()]) -> no_return().
main([Wiring, World, Faults, Props, N, Rates, Nodes, Seed, Dir]) ->
    main([Wiring, World, Faults, Props, N, Rates, Nodes, Seed, Dir, "3"]);
main([Wiring, World, Faults, Props, N, Rates, Nodes, Seed, Dir, Shrink]) ->
    %% the crashes are the point: their supervisors' reports would drown the table
    ok = logger:set_primary_config(level, critical),
    NodeList = case Nodes of
                   "none" -> [node()];
                   _ -> [list_to_atom(X) || X <- string:lexemes(Nodes, ",")]
               end,
    RateList = case Rates of
                   "none" -> [none];
                   _ -> [to_number(R) || R <- string:lexemes(Rates, ",")]
               end,
    Names = names(Wiring),
    Sched = case Names of
                {ok, Ns} -> schedule(Faults, Ns);
                E -> E
            end,
    case Sched of
        {error, Reason} ->
            io:format(standard_error, "make chaos: ~0tp~n", [{error, Reason}]),
            halt(2);
        {ok, Schedule} ->
            Reports = [{Rate, explore(#{worlds => [World], wiring => Wiring,
                                        faults => at_rate(Schedule, Rate), property => Props,
                                        runs => list_to_integer(N),
                                        seed => list_to_integer(Seed), nodes => NodeList,
                                        dir => Dir, progress => true,
                                        shrink => list_to_integer(Shrink)})}
                       || Rate <- RateList],
            case [E || {_, {error, _} = E} <- Reports] of
                [Error | _] ->
                    io:format(standard_error, "make chaos: ~0tp~n", [Error]),
                    halt(2);
                [] ->
                    Ok = [{Rate, R} || {Rate, {ok, R}} <- Reports],
                    ok = torobot_chaos_report:write(Ok, #{dir => Dir, wiring => Wiring,
                                                          world => World, faults => Faults,
                                                          property => Props}),
                    io:put_chars(torobot_chaos_report:table(Ok)),
                    io:format("report: ~ts~n", [filename:join(Dir, "report.md")]),
                    halt(0)
            end
    end.

%% @doc `Schedule' with its generated faults drawn at `Rate' per simulated
%% second in all, the file's mix kept in proportion (a schedule whose
%% rates are all 0 gets `Rate' shared equally); explicit faults as they
%% are. `none' leaves it as it is.
-spec at_rate(torobot_faults:schedule(), number() | none) -> torobot_faults:schedule().
at_rate(Schedule, none) ->
    Schedule;
at_rate(Schedule, Rate) ->
    Rates = [R || {rate, R, _} <- Schedule],
    Total = lists:sum(Rates),
    Scale = fun(R) when Total > 0 -> Rate * R / Total;
               (_) -> Rate / length(Rates)
            end,
    [case E of {rate, R, Spec} -> {rate, Scale(R), Spec}; _ -> E end || E <- Schedule].

to_number(S) ->
    try list_to_float(S) catch error:badarg -> list_to_integer(S) end.

%% @doc `make run REPLAY=file': runs it, prints the SHA-256 and the
%% violation; halts 0 when both are as the file says, 1 when not, 2 on a
%% bad file. With `[File, "1"]' the node stays up afterwards, so the
%% dashboard shows the run with its faults and violation on the timeline.
-spec replay_main([string()]) -> no_return().
replay_main([File]) ->
    replay_main([File, "0"]);
replay_main([File, Serve]) ->
    ok = logger:set_primary_config(level, critical),
    case replay(File) of
        {ok, #{sha256 := Sha, violation := V, summary := Sum, expected := Exp, faults := Fs}} ->
            [io:format("~ts~n", [line(F)]) || F <- Fs],
            io:format("sha256: ~ts~nviolation: ~0tp~n~ts~n",
                      [Sha, V, torobot_sim:summary_json(Sum)]),
            Code = case Exp of
                       #{sha256 := Sha, violation := V} -> 0;
                       _ -> io:format("replay: differs from the file (~0tp)~n", [Exp]), 1
                   end,
            %% the dashboard keeps showing the run, its faults and its
            %% violation on the timeline, until the user ends it
            case Serve of
                "1" -> io:format("dashboard: serving the replay; Ctrl-C to end~n"),
                       receive after infinity -> ok end;
                _ -> halt(Code)
            end;
        {error, Reason} ->
            io:format(standard_error, "replay: ~0tp~n", [{error, Reason}]),
            halt(2)
    end.
