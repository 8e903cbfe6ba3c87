%% @doc Batch evaluation in the simulated lab (SPEC §14): many worlds, each
%% run several times, several runs at once, scored.
%%
%% {@link run/1} (also `torobot_sim:batch/1') checks everything first, then
%% runs:
%% <ol>
%% <li>every world is loaded (files) or generated (`{generated, N, Seed}':
%%     seeds Seed .. Seed + N - 1 of `torobot_worlds:generate/2'); a bad one
%%     is refused as `{error, {world, Name, Reason}}';</li>
%% <li>the wiring is tried once on a scratch robot node (its devices, its
%%     behaviors, its wiring, exactly as a run starts them); a bad one is
%%     refused as `{error, {wiring, File, Reason}}';</li>
%% <li>only then the runs start: each on robot nodes of its own
%%     (`torobot_sim' with `nodes => peer'), `parallel' at a time (default:
%%     the schedulers online, one per core).</li>
%% </ol>
%% The report: per world and overall, the runs, the success rate (red
%% touched), time to red p50 and p90 (over the runs that touched it, in
%% world ms; `none' when none did), wall and blue contacts per minute of
%% world time, and the mean distance. Each robot of a world of several
%% counts as a run. `torobot_eval' prints it and draws it.
%%
%% Options: `worlds' (required), `runs' (1), `speed' (10), `wiring'
%% (app env `wiring' of `torobot', else `config/torobot.wiring'),
%% `parallel', `generate' (options of `torobot_worlds:generate/2' for
%% generated worlds).
-module(torobot_batch).

-export([run/1, percentile/2]).

-export_type([opts/0, report/0, row/0, run/0]).

-type opts() :: #{worlds := [file:name_all()] | {generated, pos_integer(), integer()},
                  runs => pos_integer(), speed => number(), wiring => file:name_all(),
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
                    speed := number(), wiring := file:name_all(), wall_ms := non_neg_integer()}.

%% @doc Runs the batch and reports; nothing runs unless every world and the
%% wiring are good.
-spec run(opts()) -> {ok, report()} | {error, term()}.
run(#{worlds := Worlds} = Opts) ->
    Runs = maps:get(runs, Opts, 1),
    Speed = maps:get(speed, Opts, 10),
    Parallel = maps:get(parallel, Opts, erlang:system_info(schedulers_online)),
    Wiring = maps:get(wiring, Opts,
                      application:get_env(torobot, wiring, "config/torobot.wiring")),
    if
        not is_integer(Runs); Runs < 1 -> {error, {runs, Runs}};
        not is_number(Speed); Speed =< 0 -> {error, {speed, Speed}};
        not is_integer(Parallel); Parallel < 1 -> {error, {parallel, Parallel}};
        true ->
            case worlds(Worlds, maps:get(generate, Opts, #{})) of
                {ok, Named} ->
                    case try_wiring(Wiring, Named) of
                        ok -> {ok, batch(Named, Runs, Speed, Wiring, Parallel)};
                        {error, _} = Error -> Error
                    end;
                {error, _} = Error ->
                    Error
            end
    end;
run(Opts) ->
    {error, {missing, worlds, Opts}}.

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
    Loaded = [{File, torobot_world:load_all(File)} || File <- Files],
    case [{File, Reason} || {File, {error, Reason}} <- Loaded] of
        [{File, Reason} | _] ->
            {error, {world, File, Reason}};
        [] ->
            {ok, [{unicode:characters_to_binary(filename:basename(F)), F} || F <- Files]}
    end;
worlds(Other, _GenOpts) ->
    {error, {worlds, Other}}.

%% The wiring, tried on a robot node as a run would start it.
try_wiring(Wiring, [{_, Spec} | _]) ->
    case file:consult(Wiring) of
        {error, Reason} ->
            {error, {wiring, Wiring, Reason}};
        {ok, _} ->
            {ok, [World | _]} = load(Spec),
            Opts = #{wiring => Wiring, speed => 1,
                     thresholds => torobot_world:ir_thresholds(World),
                     %% the library's sensors, as a run adds them
                     sensors => [{Name, Outputs(World)}
                                 || {Name, Outputs} <- torobot_sensors:devices()]},
            case torobot_sim_robot:start_peer(Opts) of
                {ok, Handle, _Port} -> torobot_sim_robot:stop_peer(Handle);
                {error, Reason} -> {error, {wiring, Wiring, Reason}}
            end
    end.

load(Terms) when is_list(Terms), is_tuple(hd(Terms)) -> torobot_world:from_terms_all(Terms);
load(File) -> torobot_world:load_all(File).

%%====================================================================
%% Running
%%====================================================================

batch(Named, Runs, Speed, Wiring, Parallel) ->
    T0 = erlang:monotonic_time(millisecond),
    Jobs = [{Name, Spec, I} || {Name, Spec} <- Named, I <- lists:seq(1, Runs)],
    Results = pool(Jobs, Parallel, fun({_, Spec, _}) ->
                                           torobot_sim:simulate(Spec, #{speed => Speed,
                                                                        wiring => Wiring,
                                                                        nodes => peer})
                                   end),
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
      speed => Speed,
      wiring => Wiring,
      wall_ms => erlang:monotonic_time(millisecond) - T0}.

as_list(Worlds) when is_list(Worlds) -> Worlds;
as_list(World) -> [World].

%% Runs Fun on every job, at most Parallel at a time; results in job order.
pool(Jobs, Parallel, Fun) ->
    Indexed = lists:enumerate(Jobs),
    pool(Indexed, Parallel, Fun, #{}, #{}).

pool([], _Parallel, _Fun, Running, Done) when map_size(Running) =:= 0 ->
    [V || {_, V} <- lists:sort(maps:to_list(Done))];
pool([{I, Job} | Rest], Parallel, Fun, Running, Done) when map_size(Running) < Parallel ->
    Self = self(),
    {Pid, Ref} = spawn_monitor(fun() -> Self ! {self(), I, Fun(Job)} end),
    pool(Rest, Parallel, Fun, Running#{Pid => {I, Ref}}, Done);
pool(Queue, Parallel, Fun, Running, Done) ->
    receive
        {Pid, I, Result} when is_map_key(Pid, Running) ->
            {{I, Ref}, Running1} = maps:take(Pid, Running),
            demonitor(Ref, [flush]),
            pool(Queue, Parallel, Fun, Running1, Done#{I => Result});
        {'DOWN', _Ref, process, Pid, Why} when is_map_key(Pid, Running) ->
            {{I, _}, Running1} = maps:take(Pid, Running),
            pool(Queue, Parallel, Fun, Running1, Done#{I => {error, {crashed, Why}}})
    end.

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
