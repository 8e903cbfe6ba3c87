%% @doc Fault schedules of the robustness lab (SPEC §17): what they may
%% say, how a seed turns a schedule into concrete faults, and what the
%% faults that live in the world (the sensors, the camera, the wheels) do
%% to a tick's readings and commands. Pure: `torobot_sim' applies the
%% result, `torobot_chaos' runs and shrinks it.
%%
%% A schedule is a list of `{at, Ms, Fault}' (explicit) and `{rate,
%% PerSimulatedSecond, FaultSpec}' (drawn from the run's seed: a Poisson
%% process over the world's duration). {@link concrete/4} gives the
%% concrete faults, `{at, Ms, Fault}' sorted by time. Faults:
%% <table>
%% <tr><th>fault</th><th>what it does</th><th>where</th></tr>
%% <tr><td>`{kill, Name}'</td><td>behavior or device `Name' killed</td><td>robot</td></tr>
%% <tr><td>`{kill, router, {Receiver, Input}}'</td><td>that input's router killed</td><td>robot</td></tr>
%% <tr><td>`{kill, port, pru_port | lua_port}'</td><td>the C program's OS
%%   process killed (every `pru_port' program of the robot's devices, or the
%%   node's `lua_port'); its owner starts the next one and tells the devices
%%   or Lua behaviors, all at that instant</td><td>robot</td></tr>
%% <tr><td>`{suspend, Name, Ms}'</td><td>behavior suspended for Ms</td><td>robot</td></tr>
%% <tr><td>`{dropout, Sensor, Ms}'</td><td>no readings</td><td>world</td></tr>
%% <tr><td>`{stuck, Sensor, Ms}'</td><td>the reading at its start, repeated</td><td>world</td></tr>
%% <tr><td>`{noise, Sensor, Sigma, Ms}'</td><td>seeded Gaussian noise on numbers</td><td>world</td></tr>
%% <tr><td>`{camera, loss, P, Ms}'</td><td>each datagram lost with probability P</td><td>world</td></tr>
%% <tr><td>`{camera, delay, D, Ms}'</td><td>datagrams D ms late</td><td>world</td></tr>
%% <tr><td>`{slip, left | right | both, Factor, Ms}'</td><td>the wheels move Factor of what they are told</td><td>world</td></tr>
%% </table>
%% Sensors: `{ir, left}', `{ir, right}', `ir' (both), `camera', and the
%% simulated sensors `range', `bumper', `light', `odometry', `beacon'. A
%% `FaultSpec' may say `any' for a name (`any' behavior of the wiring,
%% `any' sensor: `{ir, left}', `{ir, right}', `camera', `range'), `{one_of,
%% [Name]}' for a behavior drawn from those, and
%% `{Min, Max}' for a duration, a sigma, a probability or a factor.
%% `lua_port' is known only to a wiring with Lua behaviors (`names()'
%% `ports'). A robot over several nodes (SPEC §13) also takes `{disconnect, Node,
%% Ms}' (the node cut from the rest of the robot for Ms, then healed) and
%% `{kill_node, Node}' (cut for good), where `Node' is one of the wiring's
%% nodes other than the world's (`nodes' of the names).
-module(torobot_faults).

-export([check/2, read/2, concrete/4, describe/1, ends/1, world_faults/2, robot_faults/1,
         robot_events/1]).
-export([readings/5, sensor_readings/4, datagrams/5, wheels/3, sensors/0]).
-export_type([fault/0, schedule/0, concrete/0, names/0]).

-type fault() :: tuple().
-type schedule() :: [{at, number(), fault()} | {rate, number(), fault()}].
-type concrete() :: [{at, non_neg_integer(), fault()}].
%% what a schedule may name: the wiring's behaviors and devices, and its
%% routers' inputs
%% `ports': the port programs the robot runs (default `[pru_port]'; a
%% wiring with Lua behaviors adds `lua_port'); `nodes': the wiring's nodes
%% other than the world's.
-type names() :: #{behaviors := [atom()], devices := [atom()], inputs := [{atom(), atom()}],
                   ports => [pru_port | lua_port], nodes => [node()]}.

-define(SENSORS, [{ir, left}, {ir, right}, ir, camera, range, bumper, light, odometry, beacon]).
-define(ANY_SENSORS, [{ir, left}, {ir, right}, camera, range]).

%%====================================================================
%% Checking
%%====================================================================

%% @doc The sensors a fault may name.
-spec sensors() -> [term()].
sensors() -> ?SENSORS.

%% @doc Checks a schedule against the names of a wiring: `ok' or the
%% first bad entry, `{error, {Reason, Entry}}'.
-spec check(schedule(), names()) -> ok | {error, {atom(), term()}}.
check(Schedule, Names) when is_list(Schedule) ->
    check_all([{none, E} || E <- Schedule], Names);
check(Other, _Names) ->
    {error, {bad_schedule, Other}}.

check_all([], _Names) ->
    ok;
check_all([{Line, Entry} | Rest], Names) ->
    case entry(Entry, Names) of
        ok -> check_all(Rest, Names);
        {error, {Reason, Detail}} when Line =:= none -> {error, {Reason, Detail}};
        {error, {Reason, Detail}} -> {error, {Reason, {Line, Detail}}}
    end.

%% @doc A file of schedule terms (`config/faults/*.faults'), checked:
%% errors name `File:Line'.
-spec read(file:name_all(), names()) -> {ok, schedule()} | {error, {atom(), term()}}.
read(File, Names) ->
    case torobot_terms:read(File) of
        {ok, Located} ->
            case check_all([{Loc, T} || {Loc, T} <- Located], Names) of
                ok -> {ok, [T || {_, T} <- Located]};
                Error -> Error
            end;
        Error ->
            Error
    end.

entry({at, Ms, Fault} = E, Names) ->
    case is_number(Ms) andalso Ms >= 0 of
        true -> fault(Fault, Names, false, E);
        false -> {error, {bad_time, E}}
    end;
entry({rate, R, Spec} = E, Names) ->
    case is_number(R) andalso R >= 0 of
        true -> fault(Spec, Names, true, E);
        false -> {error, {bad_rate, E}}
    end;
entry(E, _Names) ->
    {error, {bad_entry, E}}.

fault({kill, router, {R, I}}, Names, _Spec, E) ->
    case lists:member({R, I}, maps:get(inputs, Names)) of
        true -> ok;
        false -> {error, {unknown_input, {{R, I}, E}}}
    end;
fault({kill, port, P}, Names, _Spec, E) when P =:= pru_port; P =:= lua_port ->
    case lists:member(P, maps:get(ports, Names, [pru_port])) of
        true -> ok;
        false -> {error, {unknown_port, {P, E}}}
    end;
fault({kill, port, _}, _Names, _Spec, E) ->
    {error, {unknown_port, E}};
fault({kill, Name}, Names, Spec, E) ->
    name(Name, Names, Spec, E, [behaviors, devices]);
fault({suspend, Name, Ms}, Names, Spec, E) ->
    all([name(Name, Names, Spec, E, [behaviors]), duration(Ms, Spec, E)]);
fault({dropout, Sensor, Ms}, _Names, Spec, E) ->
    all([sensor(Sensor, Spec, E), duration(Ms, Spec, E)]);
fault({stuck, Sensor, Ms}, _Names, Spec, E) ->
    all([sensor(Sensor, Spec, E), duration(Ms, Spec, E)]);
fault({noise, Sensor, Sigma, Ms}, _Names, Spec, E) ->
    all([sensor(Sensor, Spec, E), number(Sigma, Spec, E, 0, infinity), duration(Ms, Spec, E)]);
fault({camera, loss, P, Ms}, _Names, Spec, E) ->
    all([number(P, Spec, E, 0, 1), duration(Ms, Spec, E)]);
fault({camera, delay, D, Ms}, _Names, Spec, E) ->
    all([number(D, Spec, E, 0, infinity), duration(Ms, Spec, E)]);
fault({slip, Wheel, F, Ms}, _Names, Spec, E) when Wheel =:= left; Wheel =:= right;
                                                   Wheel =:= both ->
    all([number(F, Spec, E, 0, infinity), duration(Ms, Spec, E)]);
fault({disconnect, Node, Ms}, Names, Spec, E) ->
    all([robot_node(Node, Names, E), duration(Ms, Spec, E)]);
fault({kill_node, Node}, Names, _Spec, E) ->
    robot_node(Node, Names, E);
fault(_Other, _Names, _Spec, E) ->
    {error, {unknown_fault, E}}.

all(Results) ->
    case [R || R <- Results, R =/= ok] of
        [] -> ok;
        [First | _] -> First
    end.

name(any, _Names, true, _E, _Kinds) ->
    ok;
name({one_of, [_ | _] = L}, Names, true, E, Kinds) ->
    case [N || N <- L, name(N, Names, false, E, Kinds) =/= ok] of
        [] -> ok;
        [Bad | _] -> {error, {unknown_name, {Bad, E}}}
    end;
name(Name, Names, _Spec, E, Kinds) when is_atom(Name) ->
    case lists:any(fun(K) -> lists:member(Name, maps:get(K, Names)) end, Kinds) of
        true -> ok;
        false -> {error, {unknown_name, {Name, E}}}
    end;
name(Name, _Names, _Spec, E, _Kinds) ->
    {error, {unknown_name, {Name, E}}}.

%% A node of the robot's other than the world's own.
robot_node(Node, _Names, E) when Node =:= node() ->
    {error, {own_node, {Node, E}}};
robot_node(Node, Names, E) ->
    case lists:member(Node, maps:get(nodes, Names, [])) of
        true -> ok;
        false -> {error, {unknown_node, {Node, E}}}
    end.

sensor(any, true, _E) -> ok;
sensor(S, _Spec, E) ->
    case lists:member(S, ?SENSORS) of
        true -> ok;
        false -> {error, {unknown_sensor, {S, E}}}
    end.

duration(Ms, Spec, E) ->
    case number(Ms, Spec, E, 0, infinity) of
        ok -> ok;
        {error, {_, _}} -> {error, {bad_duration, E}}
    end.

number({Min, Max}, true, E, Lo, Hi) ->
    case number(Min, false, E, Lo, Hi) =:= ok andalso number(Max, false, E, Lo, Hi) =:= ok
        andalso Min =< Max of
        true -> ok;
        false -> {error, {bad_number, E}}
    end;
number(N, _Spec, E, Lo, Hi) ->
    case is_number(N) andalso N >= Lo andalso (Hi =:= infinity orelse N =< Hi) of
        true -> ok;
        false -> {error, {bad_number, E}}
    end.

%%====================================================================
%% Concrete faults
%%====================================================================

%% @doc The schedule's concrete faults for a run of `DurationMs' with
%% `Seed', sorted by time (then in the schedule's order): the explicit
%% ones as they are, the generated ones drawn with the seed.
-spec concrete(schedule(), integer(), pos_integer(), names()) -> concrete().
concrete(Schedule, Seed, DurationMs, Names) ->
    {Faults, _} = lists:foldl(
                    fun({at, Ms, F}, {Acc, R}) ->
                            {[{round(Ms), F} | Acc], R};
                       ({rate, Rate, Spec}, {Acc, R}) ->
                            {Drawn, R1} = poisson(Rate, Spec, DurationMs, Names, R),
                            {lists:reverse(Drawn, Acc), R1}
                    end, {[], rand:seed_s(exsss, {Seed, 17, 4711})}, Schedule),
    Indexed = lists:zip(lists:seq(1, length(Faults)), lists:reverse(Faults)),
    [{at, Ms, F} || {_, {Ms, F}} <- lists:sort(fun({I, {A, _}}, {J, {B, _}}) -> {A, I} =< {B, J} end,
                                               Indexed)].

poisson(Rate, _Spec, _Duration, _Names, R) when Rate == 0 ->
    {[], R};
poisson(Rate, Spec, Duration, Names, R) ->
    poisson(Rate, Spec, Duration, Names, R, 0.0, []).

poisson(Rate, Spec, Duration, Names, R, T, Acc) ->
    {U, R1} = rand:uniform_s(R),
    T1 = T - math:log(U) * 1000 / Rate,
    case T1 >= Duration of
        true ->
            {lists:reverse(Acc), R1};
        false ->
            {F, R2} = draw(Spec, Names, R1),
            poisson(Rate, Spec, Duration, Names, R2, T1, [{round(T1), F} | Acc])
    end.

%% A spec's `any' names and ranges, drawn.
draw(Spec, Names, R) ->
    {Elements, R1} = lists:mapfoldl(fun(E, Acc) -> pick(E, Spec, Names, Acc) end, R,
                                    tuple_to_list(Spec)),
    {list_to_tuple(Elements), R1}.

pick(any, Spec, Names, R) ->
    Pool = case element(1, Spec) of
               kill -> maps:get(behaviors, Names);
               suspend -> maps:get(behaviors, Names);
               _ -> ?ANY_SENSORS
           end,
    {I, R1} = rand:uniform_s(length(Pool), R),
    {lists:nth(I, Pool), R1};
pick({one_of, L}, _Spec, _Names, R) ->
    {I, R1} = rand:uniform_s(length(L), R),
    {lists:nth(I, L), R1};
pick({Min, Max}, _Spec, _Names, R) when is_integer(Min), is_integer(Max) ->
    {I, R1} = rand:uniform_s(Max - Min + 1, R),
    {Min + I - 1, R1};
pick({Min, Max}, _Spec, _Names, R) when is_number(Min), is_number(Max) ->
    {U, R1} = rand:uniform_s(R),
    {Min + U * (Max - Min), R1};
pick(E, _Spec, _Names, R) ->
    {E, R}.

%% @doc A fault as one line of text (`kill avoid_left', `dropout {ir,left} 500 ms').
-spec describe(fault()) -> iolist().
describe({kill, router, {R, I}}) -> io_lib:format("kill router ~s.~s", [R, I]);
describe({kill, port, P}) -> io_lib:format("kill port ~s", [P]);
describe({kill, Name}) -> io_lib:format("kill ~s", [Name]);
describe({kill_node, Node}) -> io_lib:format("kill_node ~s", [Node]);
describe(F) ->
    [Kind | Args] = tuple_to_list(F),
    lists:join(" ", [atom_to_list(Kind) | [arg(A) || A <- Args]]) ++ [" ms"].

arg(A) when is_float(A) -> float_to_list(A, [{decimals, 3}, compact]);
arg(A) -> io_lib:format("~0tp", [A]).

%% @doc When a fault ends (a kill ends at once).
-spec ends({at, non_neg_integer(), fault()}) -> non_neg_integer().
ends({at, Ms, F}) ->
    case F of
        {kill, _} -> Ms;
        {kill, _, _} -> Ms;
        {kill_node, _} -> Ms;
        _ -> Ms + round(element(tuple_size(F), F))
    end.

%% @doc The faults the robot's runtime takes (kills, suspends), in order.
-spec robot_faults(concrete()) -> concrete().
robot_faults(Faults) ->
    [F || {at, _, Fault} = F <- Faults, robot_fault(Fault)].

robot_fault(Fault) ->
    lists:member(element(1, Fault), [kill, suspend, disconnect, kill_node]).

%% @doc The robot's faults as events at their instants (a suspend is two); the
%% world's act on the readings alone (readings/5), so one that changes
%% nothing (noise of sigma 0) leaves the trace as it is.
-spec robot_events(concrete()) -> [{non_neg_integer(), tuple()}].
robot_events(Faults) ->
    lists:keysort(1, lists:append(
                       [case F of
                            {suspend, Name, D} -> [{Ms, {suspend, Name}},
                                                   {Ms + round(D), {resume, Name}}];
                            _ -> [{Ms, F}]
                        end || {at, Ms, F} <- robot_faults(Faults)])).

%% @doc The faults of the world (sensors, camera, wheels) active at `T'.
-spec world_faults(concrete(), non_neg_integer()) -> concrete().
world_faults(Faults, T) ->
    [F || {at, Ms, Fault} = F <- Faults, not robot_fault(Fault), Ms =< T, T < ends(F)].

%%====================================================================
%% The world's faults
%%====================================================================

%% @doc The readings of every simulated sensor (`Device => Readings') as
%% the active faults leave them ({@link readings/5} for each): a sensor
%% whose readings the faults empty has no entry.
-spec sensor_readings(#{atom() => map()}, concrete(), #{term() => term()},
                      {integer(), integer()}) -> {#{atom() => map()}, #{term() => term()}}.
sensor_readings(Readings, Active, Stuck, Seed) ->
    maps:fold(fun(Dev, R, {Acc, St}) ->
                      case readings(Dev, R, Active, St, Seed) of
                          {R1, St1} when map_size(R1) =:= 0, map_size(R) > 0 -> {Acc, St1};
                          {R1, St1} -> {Acc#{Dev => R1}, St1}
                      end
              end, {#{}, Stuck}, Readings).

%% @doc A tick's IR readings (`ir') or a simulated sensor's (`Device'),
%% as the active faults leave them: `{ok, Readings}', where a sensor in
%% dropout has none and a stuck one the value it had when it stuck
%% (`Stuck': the readings at each stuck fault's start, kept by the caller).
-spec readings(atom(), map(), concrete(), #{term() => term()}, {integer(), integer()}) ->
          {map(), #{term() => term()}}.
readings(Device, Now, Active, Stuck, Seed) ->
    lists:foldl(fun(F, {R, St}) -> reading(Device, F, R, St, Seed) end, {Now, Stuck}, Active).

reading(Device, {at, _, {dropout, S, _}}, R, St, _Seed) ->
    {maps:without(keys(Device, S, R), R), St};
reading(Device, {at, Ms, {stuck, S, _}} = F, R, St, _Seed) ->
    Ks = keys(Device, S, R),
    Frozen = case St of
                 #{F := #{Device := Was}} -> Was;
                 #{} -> maps:with(Ks, R)
             end,
    {maps:merge(R, maps:with(Ks, Frozen)),
     St#{F => (maps:get(F, St, #{}))#{Device => Frozen}, {started, F} => Ms}};
reading(Device, {at, Ms, {noise, S, Sigma, _}}, R, St, {Seed, T}) ->
    Ks = keys(Device, S, R),
    Rand0 = rand:seed_s(exsss, {Seed, T, erlang:phash2({Device, S, Ms})}),
    {R1, _} = lists:foldl(fun(K, {Acc, Rand}) ->
                                  {V, Rand1} = noisy(maps:get(K, Acc), Sigma, Device, Rand),
                                  {Acc#{K := V}, Rand1}
                          end, {R, Rand0}, lists:sort(Ks)),
    {R1, St};
reading(_Device, _F, R, St, _Seed) ->
    {R, St}.

%% The keys of a device's readings that sensor `S' names.
keys(ir, ir, R) -> maps:keys(R);
keys(ir, {ir, Side}, R) -> [Side || is_map_key(Side, R)];
keys(Device, Device, R) -> maps:keys(R);
keys(_Device, _S, _R) -> [].

noisy(V, Sigma, Device, R) when is_number(V) ->
    {G, R1} = rand:normal_s(R),
    W = V + G * Sigma,
    {case Device of
         ir -> max(0, min(1023, round(W)));
         _ when is_integer(V), Sigma == 0 -> V;
         _ -> W
     end, R1};
noisy(V, _Sigma, _Device, R) when is_map(V) ->
    {V, R};
noisy(V, _Sigma, _Device, R) ->
    {V, R}.

%% @doc A tick's camera datagrams as the active faults leave them:
%% `{Now, Delayed}', the datagrams sent now and those held back with the
%% time they are due.
-spec datagrams([binary()], concrete(), [{integer(), binary()}], #{term() => term()},
                {integer(), integer()}) ->
          {[binary()], [{integer(), binary()}], #{term() => term()}}.
datagrams(Datagrams, Active, Delayed, Stuck, {Seed, T}) ->
    {D1, St1} = lists:foldl(
                  fun({at, _, {dropout, camera, _}}, {_, St}) ->
                          {[], St};
                     ({at, _, {stuck, camera, _}} = F, {Ds, St}) ->
                          case St of
                              #{{camera, F} := Was} -> {Was, St};
                              #{} -> {Ds, St#{{camera, F} => Ds}}
                          end;
                     ({at, Ms, {camera, loss, P, _}}, {Ds, St}) ->
                          R0 = rand:seed_s(exsss, {Seed, T, erlang:phash2({loss, Ms})}),
                          {Kept, _} = lists:foldl(fun(D, {Acc, R}) ->
                                                          {U, R1} = rand:uniform_s(R),
                                                          case U < P of
                                                              true -> {Acc, R1};
                                                              false -> {[D | Acc], R1}
                                                          end
                                                  end, {[], R0}, Ds),
                          {lists:reverse(Kept), St};
                     (_, Acc) ->
                          Acc
                  end, {Datagrams, Stuck}, Active),
    Delay = lists:max([0 | [round(D) || {at, _, {camera, delay, D, _}} <- Active]]),
    Held = Delayed ++ [{T + Delay, D} || D <- D1],
    {Due, Later} = lists:partition(fun({At, _}) -> At =< T end, Held),
    {[D || {_, D} <- Due], Later, St1}.

%% @doc The wheels' velocities as slip leaves them.
-spec wheels({number(), number()}, concrete(), any()) -> {number(), number()}.
wheels(Wheels, Active, _) ->
    lists:foldl(fun({at, _, {slip, left, F, _}}, {L, R}) -> {L * F, R};
                   ({at, _, {slip, right, F, _}}, {L, R}) -> {L, R * F};
                   ({at, _, {slip, both, F, _}}, {L, R}) -> {L * F, R * F};
                   (_, W) -> W
                end, Wheels, Active).
