%% Lua behaviors (SPEC §16) in the running network: values crossing both
%% ways, wait_for_input with and without a timeout, triggers, latches reaching
%% a fake actuator, sched.sleep on the runtime's clock, errors and limits
%% naming file and line with the behavior restarting, the port program killed
%% and every Lua behavior back, bad frames, and reload.
-module(toroco_lua_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, groups/0, suite/0, init_per_testcase/2, end_per_testcase/2]).
-export([log/2]).
-export([open_ports/1, wired_inputs_the_file_never_reads/1,
         inline_behavior_replaces_its_creator/1, inline_behavior_crash_restarts_it_alone/1,
         converter_values_reach_the_behavior/1, random_per_state_and_seeded/1,
         empty_file_is_a_behavior_with_no_tasks/1, inspect_at_once_with_a_full_window/1,
         interface_from_the_file/1, values_cross_both_ways/1, a_burst_arrives_whole_and_in_order/1,
         wait_for_input_with_and_without_timeout/1, sleep_on_the_runtime_clock/1,
         latches_reach_the_actuator/1, print_goes_to_the_logger/1,
         lua_error_names_file_and_line/1, emissions_before_a_fault_in_a_burst_go_out/1,
         endless_loop_hits_the_budget/1,
         endless_allocation_hits_the_memory_cap/1, hung_port_is_killed/1,
         lua_faults_leave_erlang_layers_flowing/1, reset_starts_a_fresh_state/1,
         port_killed_every_lua_behavior_back/1, owner_killed_every_lua_behavior_back/1,
         bad_frames_are_answered/1,
         port_dying_again_and_again_is_left_to_supervision/1,
         reload_all_or_nothing/1, reload_under_1khz_input/1,
         load_main_errors_name_the_line/1, lockstep_step_pending_answers_at_once/1, configure_polling_sets_the_period/1, load_main_from_the_program_folder/1, lockstep_timers_at_simulated_deadlines/1]).

-define(WAIT, 3000).
%% the bound on a 1 kHz load of 1,000 events (a loaded machine paces it slower)
-define(LOADED, 120000).

suite() ->
    [{timetrap, {seconds, 180}}].

all() ->
    [{group, api}, {group, original}, {group, faults}, {group, reload}, {group, lockstep}].

groups() ->
    [{original, [], [open_ports, wired_inputs_the_file_never_reads,
                      inline_behavior_replaces_its_creator, inline_behavior_crash_restarts_it_alone,
                      converter_values_reach_the_behavior, random_per_state_and_seeded,
                      empty_file_is_a_behavior_with_no_tasks]},
     {api, [], [interface_from_the_file, values_cross_both_ways, a_burst_arrives_whole_and_in_order,
                wait_for_input_with_and_without_timeout, sleep_on_the_runtime_clock,
                latches_reach_the_actuator, print_goes_to_the_logger, reset_starts_a_fresh_state,
                load_main_errors_name_the_line, load_main_from_the_program_folder,
                inspect_at_once_with_a_full_window,
                configure_polling_sets_the_period]},
     {faults, [], [lua_error_names_file_and_line, emissions_before_a_fault_in_a_burst_go_out,
                   endless_loop_hits_the_budget,
                   endless_allocation_hits_the_memory_cap, hung_port_is_killed,
                   lua_faults_leave_erlang_layers_flowing,
                   port_killed_every_lua_behavior_back, owner_killed_every_lua_behavior_back,
                   port_dying_again_and_again_is_left_to_supervision, bad_frames_are_answered]},
     {reload, [], [reload_all_or_nothing, reload_under_1khz_input]},
     {lockstep, [], [lockstep_timers_at_simulated_deadlines,
                      lockstep_step_pending_answers_at_once]}].

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    {ok, _} = application:ensure_all_started(toroco_lua),
    ok = logger:add_handler(lua_suite, ?MODULE, #{config => #{pid => self()}, level => notice}),
    #{level := Level} = logger:get_primary_config(),
    ok = logger:set_primary_config(level, notice),     % print() is a notice
    [{primary_level, Level} | Config].

end_per_testcase(Case, Config) ->
    _ = lists:member(Case, [lockstep_timers_at_simulated_deadlines,
                            lockstep_step_pending_answers_at_once])
        andalso toroco_clock:realtime(),
    _ = logger:remove_handler(lua_suite),
    ok = logger:set_primary_config(level, ?config(primary_level, Config)),
    %% the behaviors first, so none sees its port go
    ok = toroco_test_lib:stop(),
    _ = application:stop(toroco_lua),
    ok.

%% logger handler: the Lua domain's events to the test process
log(#{meta := Meta = #{domain := [toroco, lua]}, msg := Msg}, #{config := #{pid := Pid}}) ->
    Pid ! {lua_log, maps:get(name, Meta, undefined), text(Msg)};
log(_, _) ->
    ok.

text({string, S}) -> unicode:characters_to_binary(S);
text({report, R}) -> iolist_to_binary(io_lib:format("~p", [R]));
text({F, A}) -> iolist_to_binary(io_lib:format(F, A)).

%%% ---------------------------------------------------------------------
%%% Programs written for the original
%%% ---------------------------------------------------------------------

open_ports(doc) ->
    ["Ports are open: set_inputs names any input of a Lua behavior, an output exists "
     "once the code emits on it or the wiring names it; a refused change changes nothing"];
open_ports(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [echo, other]),
    ok = toroco_lua:add_behavior(e, #{file => data(Config, "echo.lua")}),
    #{inputs := Ins0, outputs := Outs0} = toroco:inspect(e),
    ?assertEqual({[], []}, {maps:keys(Ins0), maps:keys(Outs0)}),
    ok = toroco:set_inputs(e, #{value => [{s, value}], never_read => [{s, value}]}),
    ok = toroco:set_inputs(a, #{echo => [{e, echo}], other => [{e, not_emitted_yet}]}),
    #{inputs := Ins, outputs := Outs} = toroco:inspect(e),
    ?assertEqual([never_read, value], lists:sort(maps:keys(Ins))),
    ?assertEqual([echo, not_emitted_yet], lists:sort(maps:keys(Outs))),
    ok = toroco:inject({s, value}, 7),
    await(a, echo, [7]),
    %% emitted on, wired by nobody: it exists now
    #{outputs := Outs1} = toroco:inspect(e),
    ?assertEqual([count, echo, made, not_emitted_yet], lists:sort(maps:keys(Outs1))),
    %% devices keep their declared ports, and a refused change changes nothing
    ?assertEqual({error, {unknown_output, {s, nope}}},
                 toroco:set_inputs(e, #{value => [{s, value}], another => [{s, nope}]})),
    #{inputs := Ins2} = toroco:inspect(e),
    ?assertEqual([never_read, value], lists:sort(maps:keys(Ins2))).

wired_inputs_the_file_never_reads(doc) ->
    ["A main file wiring inputs its behavior never reads loads and runs; comments and "
     "strings in the behavior's file make no port"];
wired_inputs_the_file_never_reads(Config) ->
    ok = toroco:add_device(mouse, toroco_fake_sensor, #{outputs => [left, right]}),
    actuator(actuator, [signal]),
    ?assertEqual({ok, #{behaviors => [counter]}},
                 toroco_lua:load_main(data(Config, "open_ports/main.lua"), #{})),
    #{inputs := Ins, outputs := Outs} = toroco:inspect(counter),
    ?assertEqual([reset, spare, tick], lists:sort(maps:keys(Ins))),
    ?assertEqual([count], maps:keys(Outs)),
    ok = toroco:inject({mouse, left}, pressed),
    ok = toroco:inject({mouse, right}, pressed),
    ok = toroco:inject({mouse, left}, released),
    await(actuator, signal, [1, 2]),
    #{outputs := Outs1} = toroco:inspect(counter),
    ?assertEqual([count, made_later], lists:sort(maps:keys(Outs1))).

inline_behavior_replaces_its_creator(doc) ->
    ["A behavior removes itself, adds level3 whose trigger is an inline Lua function "
     "(with params), and rewires reporter's input to it: level3 runs in the state its "
     "creator made, after the creator is gone"];
inline_behavior_replaces_its_creator(Config) ->
    ok = toroco:add_device(mouse, toroco_fake_sensor, #{outputs => [left]}),
    actuator(actuator, [signal]),
    ?assertEqual({ok, #{behaviors => [level2, reporter]}},
                 toroco_lua:load_main(data(Config, "levels/main.lua"), #{})),
    ok = toroco:inject({mouse, left}, pressed),
    await(actuator, signal, [2]),
    Gone = erlang:monitor(process, toroco:whereis(level2)),
    ok = toroco:inject({mouse, left}, released),
    receive {'DOWN', Gone, process, _, _} -> ok after ?WAIT -> ct:fail(level2_not_removed) end,
    toroco_test_lib:wait_until(fun() -> is_map(toroco:inspect(level3)) end, ?WAIT, level3),
    #{behaviors := Bs} = toroco:inspect(),
    ?assertEqual([level3, reporter], lists:sort(Bs)),
    #{inputs := #{level := #{sources := [{level3, level}]}}} = toroco:inspect(reporter),
    ok = toroco:inject({mouse, left}, pressed),
    await(actuator, signal, [2, {3, <<"pressed">>}]),
    %% a supervised behavior like any other: inspect shows its task
    {ok, [#{kind := trigger, input := left}]} = toroco_lua:waits(level3),
    ok = toroco:suspend_behavior(level3),
    ok = toroco:inject({mouse, left}, released),
    ok = toroco:resume_behavior(level3),
    ok = toroco:inject({mouse, left}, pressed),
    await(actuator, signal, [2, {3, <<"pressed">>}, {3, <<"pressed">>}]),
    %% a Brooks reset starts its trigger again in the same state
    ok = toroco:reset_behavior(level3),
    ok = toroco:inject({mouse, left}, pressed),
    await(actuator, signal, [2, {3, <<"pressed">>}, {3, <<"pressed">>}, {3, <<"pressed">>}]),
    {ok, [#{kind := trigger, input := left}]} = toroco_lua:waits(level3).

inline_behavior_crash_restarts_it_alone(doc) ->
    ["A Lua error in a behavior made with inline code restarts it alone, in the same "
     "Lua state (its creator's upvalues live on), and its creator goes on in the same process"];
inline_behavior_crash_restarts_it_alone(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value, make]}),
    actuator(a, [child, made]),
    ok = toroco_lua:add_behavior(maker, #{file => data(Config, "levels/maker.lua")}),
    ok = toroco:set_inputs(maker, #{make => [{s, make}]}),
    ok = toroco:set_inputs(a, #{made => [{maker, made}]}),
    ok = toroco:inject({s, make}, go),
    await(a, made, [1]),
    toroco_test_lib:wait_until(fun() -> is_pid(toroco:whereis(child)) end,
                               ?WAIT, child),
    ok = toroco:inject({s, value}, 1),
    await(a, child, [{1, 1}]),
    Maker = toroco:whereis(maker),
    Child = toroco:whereis(child),
    Ref = erlang:monitor(process, Child),
    ok = toroco:inject({s, value}, <<"boom">>),
    receive {'DOWN', Ref, process, _, Why} ->
            ?assertMatch({lua_error, _, 17, <<"boom in child">>}, Why)
    after ?WAIT -> ct:fail(child_not_stopped)
    end,
    back(child),
    ?assertNotEqual(Child, toroco:whereis(child)),
    ok = toroco:inject({s, value}, 2),
    await(a, child, [{1, 1}, {2, 2}]),
    ?assertEqual(Maker, toroco:whereis(maker)),
    ok = toroco:inject({s, make}, go),
    await(a, made, [1, 2]).

converter_values_reach_the_behavior(doc) ->
    ["configure_polling with a converter: the converter runs in Lua on each reading "
     "and its return values are the event's values; a pollable device is polled at "
     "the period; one that emits by itself gets only the converter"];
converter_values_reach_the_behavior(Config) ->
    ok = toroco:add_device(trc_grey_left, toroco_fake_sensor, #{outputs => [value]}),
    actuator(trc_motor, [setvel2mtr]),
    ?assertEqual({ok, #{behaviors => [follower]}},
                 toroco_lua:load_main(data(Config, "line/main.lua"), #{})),
    ok = toroco:inject({trc_grey_left, value}, 700),
    await(trc_motor, setvel2mtr, [{10, 20, 700}]),
    ok = toroco:inject({trc_grey_left, value}, 100),
    await(trc_motor, setvel2mtr, [{10, 20, 700}, {20, 10, 100}]),
    %% a device that can be polled: polled at the period, each reading converted
    ok = toroco_test_lib:clear(),
    Polls = counters:new(1, []),
    Reading = fun() -> ok = counters:add(Polls, 1, 1), 100 + 800 * (counters:get(Polls, 1) rem 2) end,
    ok = toroco:add_device(trc_grey_left, toroco_poll_sensor, #{fn => Reading, every_ms => 60000}),
    actuator(trc_motor, [setvel2mtr]),
    {ok, _} = toroco_lua:load_main(data(Config, "line/main.lua"), #{}),
    #{device := #{every_ms := 50}} = toroco:inspect(trc_grey_left),
    ok = toroco_fake_actuator:await(trc_motor, fun(H) -> length(H) >= 3 end, ?WAIT),
    Got = lists:usort([V || {setvel2mtr, V, _} <- toroco_fake_actuator:history(trc_motor)]),
    ?assertEqual([{10, 20, 900}, {20, 10, 100}], Got).

random_per_state_and_seeded(doc) ->
    ["math.random is each state's own: two behaviors seeded alike draw alike however "
     "their draws interleave; os.time() is the runtime clock's seconds"];
random_per_state_and_seeded(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [a, b]}),
    actuator(act, [a, b]),
    [ok = toroco_lua:add_behavior(N, #{file => data(Config, "random.lua"), params => #{seed => 42}})
     || N <- [ra, rb]],
    ok = toroco:set_inputs(ra, #{go => [{s, a}]}),
    ok = toroco:set_inputs(rb, #{go => [{s, b}]}),
    ok = toroco:set_inputs(act, #{a => [{ra, drawn}], b => [{rb, drawn}]}),
    [ok = toroco:inject({s, a}, 1) || _ <- lists:seq(1, 3)],
    ok = toroco_fake_actuator:await(act, fun(H) -> length(H) =:= 3 end, ?WAIT),
    [ok = toroco:inject({s, b}, 1) || _ <- lists:seq(1, 3)],
    ok = toroco_fake_actuator:await(act, fun(H) -> length(H) =:= 6 end, ?WAIT),
    A = [R || {R, _} <- values(act, a)],
    ?assertEqual(A, [R || {R, _} <- values(act, b)]),
    ?assertEqual(3, length(lists:usort(A))),
    [{_, T} | _] = values(act, a),
    ?assert(abs(T - toroco_clock:now_ms() div 1000) =< 5).

empty_file_is_a_behavior_with_no_tasks(doc) ->
    ["An empty behavior file loads as a behavior with no tasks, with a warning"];
empty_file_is_a_behavior_with_no_tasks(Config) ->
    ok = toroco_lua:add_behavior(nothing, #{file => data(Config, "empty.lua")}),
    receive {lua_log, nothing, Text} ->
            ?assertMatch({_, _}, binary:match(Text, <<"returns nothing">>))
    after ?WAIT -> ct:fail(no_warning)
    end,
    ?assertEqual({ok, []}, toroco_lua:waits(nothing)).

%%% ---------------------------------------------------------------------
%%% The API
%%% ---------------------------------------------------------------------

inspect_at_once_with_a_full_window(doc) ->
    ["While a Lua behavior's window is full (slow activations, window 1), inspect, "
     "suspend and the tap are answered at once (each within 10 ms), and every input "
     "is still handled, in order"];
inspect_at_once_with_a_full_window(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [done]),
    ok = toroco_lua:add_behavior(slow, #{file => data(Config, "slow.lua"), window => 1,
                                         budget => 2000000000}),
    ok = toroco:set_inputs(slow, #{value => [{s, value}]}),
    ok = toroco:set_inputs(a, #{done => [{slow, done}]}),
    N = 6,
    [ok = toroco:inject({s, value}, K) || K <- lists:seq(1, N)],
    %% each activation takes a tenth of a second or more; the rest wait their turn
    ok = toroco_test_lib:wait_until(fun() -> busy(slow) end, ?WAIT, {busy, slow}),
    Times = [begin
                 {T, #{behavior := #{waits := {busy, _}}}} = timer:tc(toroco, inspect, [slow]),
                 {T2, ok} = timer:tc(toroco, suspend_behavior, [slow]),
                 {T3, ok} = timer:tc(toroco, resume_behavior, [slow]),
                 max(T, max(T2, T3))
             end || _ <- lists:seq(1, 3)],
    ct:pal("inspect, suspend, resume while the window is full: ~w us", [Times]),
    ?assert(lists:max(Times) < 10000),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= N end, 20000),
    ?assertEqual(lists:seq(1, N), values(a, done)).

busy(Name) ->
    case toroco:inspect(Name) of
        #{behavior := #{waits := {busy, _}}} -> true;
        _ -> false
    end.

interface_from_the_file(doc) ->
    ["toroco:add_behavior(Name, toroco_lua, #{file => ...}) as SPEC §16 writes it; the "
     "ports are open (nothing read from the file): `inputs'/`outputs' declare some beforehand"];
interface_from_the_file(Config) ->
    ?assertEqual(#{inputs => [], outputs => [], open => true},
                 toroco_lua:interface(#{file => data(Config, "echo.lua")})),
    ?assertEqual(#{inputs => [extra], outputs => [], open => true},
                 toroco_lua:interface(#{file => data(Config, "latch.lua"), inputs => [extra]})),
    %% as SPEC §16 writes it, straight through the runtime's API
    ok = toroco:add_behavior(lb, toroco_lua, #{file => data(Config, "echo.lua"), layer => 2,
                                               params => #{}}),
    #{module := toroco_lua, layer := 2} = toroco:inspect(lb),
    ?assertMatch({error, _}, toroco:add_behavior(nf, toroco_lua, #{file => "nope.lua"})).

values_cross_both_ways(doc) ->
    ["Values cross as SPEC §16 says: one value is the value, several a tuple, none {}; "
     "integral numbers integers, strings binaries, tables lists or maps; the reverse in"];
values_cross_both_ways(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [echo, count, made]),
    ok = toroco_lua:add_behavior(lb, #{file => data(Config, "echo.lua")}),
    ok = toroco:set_inputs(lb, #{value => [{s, value}]}),
    ok = toroco:set_inputs(a, #{echo => [{lb, echo}], count => [{lb, count}], made => [{lb, made}]}),
    In = [{20, 20}, 42, 2.5, 3.0, <<"bin">>, [1, 2, 3], #{a => 1}, {}, true, other, {1, {2, 3}}],
    Out = [{20, 20}, 42, 2.5, 3, <<"bin">>, [1, 2, 3], #{<<"a">> => 1}, {}, true, <<"other">>,
           {1, [2, 3]}],
    [ok = toroco:inject({s, value}, V) || V <- In],
    await(a, echo, Out),
    await(a, count, [2, 1, 1, 1, 1, 1, 1, 0, 1, 1, 2]),
    %% made reaches its own input: it may come after the others' last
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:keymember(made, 1, H) end, 5000),
    [Made | _] = values(a, made),
    ?assertEqual({1, 2.5, <<"text">>, true, [1, 2], #{<<"k">> => <<"v">>}}, Made).

a_burst_arrives_whole_and_in_order(doc) ->
    ["2,000 events injected at once through two Lua relays in a row, their activations "
     "in flight together (window 32, and 1): all reach the actuator once, in order, and "
     "inspect answers in the middle of it"];
a_burst_arrives_whole_and_in_order(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [echo]),
    N = 2000,
    [begin
         ok = toroco_lua:add_behavior(B, #{file => data(Config, "echo.lua"), window => W}),
         ok = toroco:set_inputs(B, #{value => [Src]})
     end || {B, W, Src} <- [{r1, 32, {s, value}}, {r2, 1, {r1, echo}}]],
    ok = toroco:set_inputs(a, #{echo => [{r2, echo}]}),
    [begin
         ok = toroco:inject({s, value}, K),
         _ = K =:= N div 2 andalso ?assertMatch(#{behavior := #{waits := W}}
                                                  when is_list(W) orelse element(1, W) =:= busy,
                                                toroco:inspect(r1))
     end || K <- lists:seq(1, N)],
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= N end, 20000),
    ?assertEqual(lists:seq(1, N), values(a, echo)).

wait_for_input_with_and_without_timeout(doc) ->
    ["wait_for_input pauses the coroutine until its input; with a timeout it gives nil "
     "after it, and an input in time cancels the timer; toroco:inspect/1 shows the waits"];
wait_for_input_with_and_without_timeout(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [go, more]}),
    actuator(a, [got, more, timeout]),
    ok = toroco_lua:add_behavior(w, #{file => data(Config, "waiter.lua")}),
    ok = toroco:set_inputs(w, #{go => [{s, go}], more => [{s, more}]}),
    ok = toroco:set_inputs(a, #{got => [{w, got}], more => [{w, more}], timeout => [{w, timeout}]}),
    ?assertMatch({ok, [#{kind := coroutine, input := go, timer := false}]}, toroco_lua:waits(w)),
    ok = toroco:inject({s, go}, 1),
    await(a, timeout, [1]),
    H = toroco_fake_actuator:history(a),
    [TGot] = [T || {got, 1, T} <- H],
    [TOut] = [T || {timeout, 1, T} <- H],
    ?assert(TOut - TGot >= 190),              % 0.2 s, on a generous bound
    ?assert(TOut - TGot < 2000),
    ok = toroco:inject({s, go}, 2),
    await(a, got, [1, 2]),
    ?assertMatch({ok, [#{input := more, timer := true}]}, toroco_lua:waits(w)),
    %% toroco:inspect/1 shows them too, under `behavior'
    #{behavior := #{waits := [#{kind := coroutine, input := more, timer := true}],
                    memory := Mem}} = toroco:inspect(w),
    ?assert(is_integer(Mem) andalso Mem > 0),
    ok = toroco:inject({s, more}, 3),
    await(a, more, [3]),
    ?assertMatch({ok, [#{input := go, timer := false}]}, toroco_lua:waits(w)),
    ?assertEqual([1], values(a, timeout)).

sleep_on_the_runtime_clock(doc) ->
    ["lumen's sched.sleep is a gen_statem timeout of the behavior: ticks come about "
     "every 0.05 s"];
sleep_on_the_runtime_clock(Config) ->
    actuator(a, [tick]),
    ok = toroco_lua:add_behavior(t, #{file => data(Config, "sleeper.lua")}),
    ok = toroco:set_inputs(a, #{tick => [{t, tick}]}),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= 4 end, ?WAIT),
    H = [{V, T} || {tick, V, T} <- toroco_fake_actuator:history(a)],
    [{V0, T0} | _] = H,
    {V3, T3} = lists:nth(4, H),
    ?assertEqual(V0 + 3, V3),
    ?assert(T3 - T0 >= 140).

latches_reach_the_actuator(doc) ->
    ["The thesis' avoid in Lua: set_output latches the motors over a lower source, "
     "unset_output lets the lower source's latch through again"];
latches_reach_the_actuator(Config) ->
    ok = toroco:add_device(ir, toroco_fake_sensor, #{outputs => [update]}),
    ok = toroco:add_device(low, toroco_fake_sensor, #{outputs => [motors]}),
    actuator(motors, [setvel]),
    ok = toroco_lua:add_behavior(avoid, #{file => data(Config, "latch.lua"), layer => 1,
                                          params => #{motors_vel => [20, -20]}}),
    ok = toroco:set_inputs(avoid, #{update => [{ir, update}]}),
    ok = toroco:set_inputs(motors, #{setvel => [{avoid, motors_setvel}, {low, motors}]}),
    ok = toroco:inject({low, motors}, {10, 10}),
    await(motors, setvel, [{10, 10}]),
    ok = toroco:inject({ir, update}, 1),
    await(motors, setvel, [{10, 10}, {20, -20}]),
    #{outputs := #{motors_setvel := #{latch := {value, {20, -20}}}}} = toroco:inspect(avoid),
    ok = toroco:inject({low, motors}, {11, 11}, #{latch => true}),   % suppressed
    ok = toroco:inject({ir, update}, 0),
    await(motors, setvel, [{10, 10}, {20, -20}, {11, 11}]),
    #{outputs := #{motors_setvel := #{latch := none}}} = toroco:inspect(avoid).

reset_starts_a_fresh_state(doc) ->
    ["Brooks' reset runs a Lua behavior's file again in a fresh state, and the old "
     "state is closed: resets leave one state, not one each"];
reset_starts_a_fresh_state(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value, reset]}),
    actuator(a, [booted, echo]),
    ok = toroco_lua:add_behavior(lb, #{file => data(Config, "boot.lua")}),
    ok = toroco:set_inputs(lb, #{value => [{s, value}]}),
    ok = toroco:set_inputs(a, #{booted => [{lb, booted}], echo => [{lb, echo}]}),
    ok = toroco:set_reset(lb, [{s, reset}]),
    ?assertEqual(1, toroco_lua_port:states()),
    [begin
         ok = toroco:inject({s, reset}, K),
         await(a, booted, lists:duplicate(K, {}))
     end || K <- lists:seq(1, 5)],
    ok = toroco:inject({s, value}, 7),
    await(a, echo, [7]),
    ?assertEqual(1, toroco_lua_port:states()).

print_goes_to_the_logger(doc) ->
    ["print() reaches the logger with the behavior's name"];
print_goes_to_the_logger(Config) ->
    ok = toroco:add_device(ir, toroco_fake_sensor, #{outputs => [update]}),
    ok = toroco_lua:add_behavior(avoid, #{file => data(Config, "latch.lua"),
                                          params => #{motors_vel => [1, 1]}}),
    ok = toroco:set_inputs(avoid, #{update => [{ir, update}]}),
    ok = toroco:inject({ir, update}, 5),
    receive {lua_log, avoid, Text} -> ?assertMatch({_, _}, binary:match(Text, <<"Avoiding!">>))
    after ?WAIT -> ct:fail(no_print)
    end.

load_main_from_the_program_folder(doc) ->
    ["A program runs from its main file's folder, as the original did: a behavior "
     "under behaviors/ requires a module of the program's lib/"];
load_main_from_the_program_folder(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [twice]),
    ?assertEqual({ok, #{behaviors => [user]}},
                 toroco_lua:load_main(data(Config, "prog/main.lua"), #{})),
    ok = toroco:inject({s, value}, 21),
    await(a, twice, [42]).

configure_polling_sets_the_period(doc) ->
    ["configure_polling(device.D.E, s) has a device that can be polled poll every s "
     "and leaves one that emits by itself as it is; an output the device has not is "
     "refused with the main file's line"];
configure_polling_sets_the_period(Config) ->
    ok = toroco:add_device(p, toroco_poll_sensor, #{fn => fun() -> 1 end, every_ms => 60000}),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    #{device := #{every_ms := 60000}} = toroco:inspect(p),
    ?assertEqual({ok, #{behaviors => []}},
                 toroco_lua:load_main(data(Config, "polling/main.lua"), #{})),
    #{device := #{every_ms := 20}} = toroco:inspect(p),
    %% polled again and again: at 60 s a period, the first poll would be the only one
    ok = toroco_test_lib:wait_until(fun() -> polls(p) >= 5 end, ?WAIT, {polled, p, 5}),
    Unknown = data(Config, "polling/unknown.lua"),
    ?assertEqual({error, {Unknown, 3, {unknown_output, {p, nope}}}},
                 toroco_lua:load_main(Unknown, #{})).

polls(Name) ->
    #{device := #{polls := P}} = toroco:inspect(Name),
    P.

load_main_errors_name_the_line(doc) ->
    ["load_main/2 stops at the first refused call with the main file's line, and "
     "at a main file that does not compile"];
load_main_errors_name_the_line(Config) ->
    Main = data(Config, "bad_main/main.lua"),
    ?assertMatch({error, {Main, 6, {unknown_name, nowhere}}}, toroco_lua:load_main(Main, #{})),
    %% what came before the refused call stays: the behavior is there
    ?assertMatch(#{kind := behavior}, toroco:inspect(e)),
    Syntax = data(Config, "bad_main/syntax.lua"),
    ?assertMatch({error, {Syntax, 3, <<"unexpected symbol near '<eof>'">>}},
                 toroco_lua:load_main(Syntax, #{})).

%%% ---------------------------------------------------------------------
%%% Faults
%%% ---------------------------------------------------------------------

lua_error_names_file_and_line(doc) ->
    ["A Lua error ends the behavior with {lua_error, File, Line, Message} and its "
     "layer restarts it; a sensor's path to an actuator beside it goes on"];
lua_error_names_file_and_line(Config) ->
    File = data(Config, "faulty.lua"),
    faulty(File),
    Reason = fault(f, <<"error">>),
    ?assertMatch({lua_error, File, 7, <<"attempt to index local 't' (a nil value)">>}, Reason),
    back(f),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]),
    ok = toroco:inject({e, value}, 2),
    await(a, erl, [1, 2]).

emissions_before_a_fault_in_a_burst_go_out(doc) ->
    ["A burst of inputs whose last one makes the Lua code fail: their answers come back "
     "together, and the emissions of those before the failure reach the actuator, in "
     "order, before the behavior stops"];
emissions_before_a_fault_in_a_burst_go_out(Config) ->
    faulty(data(Config, "faulty.lua")),
    Ref = erlang:monitor(process, toroco:whereis(f)),
    Kinds = [<<"k", (integer_to_binary(K))/binary>> || K <- lists:seq(1, 20)],
    [ok = toroco:inject({s, kind}, K) || K <- Kinds ++ [<<"error">>]],
    receive {'DOWN', Ref, process, _, Why} -> ?assertMatch({lua_error, _, 7, _}, Why)
    after 2 * ?WAIT -> ct:fail({not_stopped, f})
    end,
    await(a, alive, [<<"ok">> | Kinds]),
    back(f).

endless_loop_hits_the_budget(doc) ->
    ["An endless loop (in a required module) ends the behavior with {lua_limit, "
     "File, budget} naming that module, and it restarts"];
endless_loop_hits_the_budget(Config) ->
    File = data(Config, "faulty.lua"),
    faulty(File),
    Lib = filename:join(filename:dirname(File), "lib/limits.lua"),
    ?assertEqual({lua_limit, Lib, budget}, fault(f, <<"loop">>)),
    back(f),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]).

endless_allocation_hits_the_memory_cap(doc) ->
    ["Allocating without end ends the behavior with {lua_limit, File, memory}, and "
     "it restarts"];
endless_allocation_hits_the_memory_cap(Config) ->
    File = data(Config, "faulty.lua"),
    faulty(File),
    Reason = fault(f, <<"memory">>),
    ?assertMatch({lua_limit, _, memory}, Reason),
    back(f),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]).

hung_port_is_killed(doc) ->
    ["A C call the budget cannot see into (a pattern that backtracks for ages) hangs "
     "the program: its owner kills it after stuck_ms and the Lua behavior starts again "
     "in the new program, in the same process"];
hung_port_is_killed(Config) ->
    faulty(data(Config, "faulty.lua")),
    OsPid = toroco_lua_port:os_pid(),
    Pid = toroco:whereis(f),
    ok = toroco:inject({s, kind}, <<"pattern">>),
    reattached([f], OsPid),
    ?assertEqual(Pid, toroco:whereis(f)),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]).

lua_faults_leave_erlang_layers_flowing(doc) ->
    ["Under 1 kHz input to an Erlang behavior, a Lua behavior beside it errs, loops, "
     "hoards memory (restarting each time) and loses its port (starting again in the "
     "new one): the Erlang path loses no event and keeps its order"];
lua_faults_leave_erlang_layers_flowing(Config) ->
    faulty(data(Config, "faulty.lua")),
    ok = toroco:add_device(m, toroco_fake_sensor, #{outputs => [left, right]}),
    actuator(b, [signal]),
    ok = toroco:add_behavior(signaller, torobot_ex_signaller, #{}),
    ok = toroco:set_inputs(signaller, #{left => [{m, left}], right => [{m, right}]}),
    ok = toroco:set_inputs(b, #{signal => [{signaller, signal}]}),
    N = 1000,
    Load = paced({m, left}, N),
    Reasons = [begin R = fault(f, Kind), back(f), R end
               || Kind <- [<<"error">>, <<"loop">>, <<"memory">>]],
    ?assertMatch([{lua_error, _, 7, _}, {lua_limit, _, budget}, {lua_limit, _, memory}], Reasons),
    OsPid = toroco_lua_port:os_pid(),
    _ = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    reattached([f], OsPid),
    ok = injected(Load),
    ok = toroco_fake_actuator:await(b, fun(H) -> length(H) >= N end, 20000),
    ?assertEqual([{left, K} || K <- lists:seq(1, N)], values(b, signal)),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]).

port_killed_every_lua_behavior_back(doc) ->
    ["kill -9 of the port program: every Lua behavior, 8 of them in one layer (more "
     "than its restart intensity), answers again within 1 s in the same process, and "
     "the layer is not taken out; the Erlang path goes on in the same processes"];
port_killed_every_lua_behavior_back(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    Names = [list_to_atom("l" ++ integer_to_list(K)) || K <- lists:seq(0, 7)],
    Echo = fun(N) -> list_to_atom("echo_" ++ atom_to_list(N)) end,
    actuator(a, [erl | [Echo(N) || N <- Names]]),
    [begin
         ok = toroco_lua:add_behavior(N, #{file => data(Config, "echo.lua"), layer => 1}),
         ok = toroco:set_inputs(N, #{value => [{s, value}]})
     end || N <- Names],
    ok = toroco:set_inputs(a, maps:from_list([{Echo(N), [{N, echo}]} || N <- Names]
                                             ++ [{erl, [{s, value}]}])),
    ok = toroco:inject({s, value}, 1),
    [await(a, Echo(N), [1]) || N <- Names],
    Sensor = toroco:whereis(s),
    Owner = whereis(toroco_lua_port),
    Pids = [toroco:whereis(N) || N <- Names],
    OsPid = toroco_lua_port:os_pid(),
    T0 = erlang:monotonic_time(millisecond),
    _ = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
    reattached(Names, OsPid),
    ok = toroco:inject({s, value}, 2),
    [await(a, Echo(N), [1, 2]) || N <- Names],
    Back = erlang:monotonic_time(millisecond) - T0,
    ct:pal("every Lua behavior back and answering ~b ms after kill -9", [Back]),
    ?assert(Back < 1000),
    ?assertEqual(Pids, [toroco:whereis(N) || N <- Names]),
    ?assertEqual(Owner, whereis(toroco_lua_port)),
    ?assertEqual(Sensor, toroco:whereis(s)),
    ?assertEqual([1], maps:keys(maps:get(layers, toroco:inspect())) -- [0]),
    await(a, erl, [1, 2]).

owner_killed_every_lua_behavior_back(doc) ->
    ["The program's owner killed (and the program with it): every Lua behavior, 8 in "
     "one layer, starts its code again in the new program in the same process, and "
     "the layer is not taken out"];
owner_killed_every_lua_behavior_back(Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    Names = [list_to_atom("o" ++ integer_to_list(K)) || K <- lists:seq(0, 7)],
    Echo = fun(N) -> list_to_atom("echo_" ++ atom_to_list(N)) end,
    actuator(a, [Echo(N) || N <- Names]),
    [begin
         ok = toroco_lua:add_behavior(N, #{file => data(Config, "echo.lua"), layer => 1}),
         ok = toroco:set_inputs(N, #{value => [{s, value}]})
     end || N <- Names],
    ok = toroco:set_inputs(a, maps:from_list([{Echo(N), [{N, echo}]} || N <- Names])),
    ok = toroco:inject({s, value}, 1),
    [await(a, Echo(N), [1]) || N <- Names],
    Pids = [toroco:whereis(N) || N <- Names],
    OsPid = toroco_lua_port:os_pid(),
    Owner = whereis(toroco_lua_port),
    exit(Owner, kill),
    toroco_test_lib:wait_until(fun() -> is_pid(whereis(toroco_lua_port))
                                            andalso whereis(toroco_lua_port) =/= Owner end,
                               ?WAIT, new_owner),
    reattached(Names, OsPid),
    ok = toroco:inject({s, value}, 2),
    [await(a, Echo(N), [1, 2]) || N <- Names],
    ?assertEqual(Pids, [toroco:whereis(N) || N <- Names]),
    ?assertEqual([1], maps:keys(maps:get(layers, toroco:inspect())) -- [0]).

port_dying_again_and_again_is_left_to_supervision(doc) ->
    ["A program that dies more than 3 times in 10 s under a Lua behavior stops it "
     "with lua_port_down, and its layer restarts it"];
port_dying_again_and_again_is_left_to_supervision(Config) ->
    faulty(data(Config, "faulty.lua")),
    Ref = erlang:monitor(process, toroco:whereis(f)),
    [begin
         OsPid = toroco_lua_port:os_pid(),
         _ = os:cmd("kill -9 " ++ integer_to_list(OsPid)),
         reattached([f], OsPid)
     end || _ <- lists:seq(1, 3)],
    _ = os:cmd("kill -9 " ++ integer_to_list(toroco_lua_port:os_pid())),
    receive {'DOWN', Ref, process, _, Why} -> ?assertMatch({lua_port_down, _}, Why)
    after ?WAIT -> ct:fail(not_stopped)
    end,
    back(f),
    ok = toroco:inject({s, kind}, <<"again">>),
    await(a, alive, [<<"ok">>, <<"again">>]).

bad_frames_are_answered(doc) ->
    ["A frame the program cannot read is answered with bad_frame, never a crash; a "
     "value that cannot cross (a pid) is dropped and the behavior goes on"];
bad_frames_are_answered(Config) ->
    OsPid = toroco_lua_port:os_pid(),
    ?assertEqual({bad_frame, not_a_term}, toroco_lua_port:raw(<<1, 2, 3>>)),
    ?assertEqual({bad_frame, not_a_term}, toroco_lua_port:raw(term_to_binary(self()))),
    ?assertEqual({bad_frame, not_a_request}, toroco_lua_port:raw(term_to_binary(hello))),
    ?assertEqual({error, {bad_request, 7}}, toroco_lua_port:raw(term_to_binary({launch, 7}))),
    ?assertEqual({error, {unknown_state, 999}}, toroco_lua_port:close(999)),
    ?assertEqual({pong, 1}, toroco_lua_port:ping()),
    ?assertEqual(OsPid, toroco_lua_port:os_pid()),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [echo]),
    %% params that cannot cross: the behavior does not start, nothing is left open
    ?assertMatch({error, _}, toroco_lua:add_behavior(lb, #{file => data(Config, "echo.lua"),
                                                           params => #{me => self()}})),
    ?assertEqual(0, toroco_lua_port:states()),
    ok = toroco_lua:add_behavior(lb, #{file => data(Config, "echo.lua")}),
    ok = toroco:set_inputs(lb, #{value => [{s, value}]}),
    ok = toroco:set_inputs(a, #{echo => [{lb, echo}]}),
    Pid = toroco:whereis(lb),
    ok = toroco:inject({s, value}, self()),
    ok = toroco:inject({s, value}, list_to_tuple(lists:seq(1, 300))),
    ok = toroco:inject({s, value}, 5),
    await(a, echo, [5]),
    ?assertEqual(Pid, toroco:whereis(lb)).

%%% ---------------------------------------------------------------------
%%% Reload
%%% ---------------------------------------------------------------------

%% Lua behavior `v' running a copy (named `Name') of version1.lua, asked
%% by sensor `s' and answering actuator `a'; the copy's path and text.
versioned(Config, Name) ->
    File = filename:join(?config(priv_dir, Config), Name),
    {ok, V1} = file:read_file(data(Config, "version1.lua")),
    ok = file:write_file(File, V1),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [ask]}),
    actuator(a, [answer]),
    ok = toroco_lua:add_behavior(v, #{file => File}),
    ok = toroco:set_inputs(v, #{ask => [{s, ask}]}),
    ok = toroco:set_inputs(a, #{answer => [{v, answer}]}),
    {File, V1}.

reload_all_or_nothing(doc) ->
    ["toroco:reload(Name) (and toroco_lua:reload/1) re-reads the file: the new code "
     "answers; a file that does not compile leaves the old one running and says why"];
reload_all_or_nothing(Config) ->
    {File, V1} = versioned(Config, "versioned.lua"),
    ok = toroco:inject({s, ask}, 1),
    await(a, answer, [{<<"v1">>, 1}]),
    ok = file:write_file(File, binary:replace(V1, <<"'v1'">>, <<"'v2'">>)),
    ok = toroco:reload(v),                    % the runtime's reload, by name
    ok = toroco:inject({s, ask}, 2),
    await(a, answer, [{<<"v1">>, 1}, {<<"v2">>, 2}]),
    ok = file:write_file(File, <<"local x = = 1\n">>),
    ?assertMatch({error, {lua_error, File, 1, _}}, toroco:reload(v)),
    ?assertMatch({error, {lua_error, File, 1, _}}, toroco_lua:reload(v)),
    ok = toroco:inject({s, ask}, 3),
    await(a, answer, [{<<"v1">>, 1}, {<<"v2">>, 2}, {<<"v2">>, 3}]).

reload_under_1khz_input(doc) ->
    ["A reload while the behavior gets 1 kHz input loses nothing: every event is "
     "answered once, in order, by the old code and then by the new"];
reload_under_1khz_input(Config) ->
    {File, V1} = versioned(Config, "busy.lua"),
    N = 1000,
    Load = paced({s, ask}, N),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= 300 end, ?LOADED),
    ok = file:write_file(File, binary:replace(V1, <<"'v1'">>, <<"'v2'">>)),
    ok = toroco_lua:reload(v),
    ok = injected(Load),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= N end, 20000),
    Answers = values(a, answer),
    ?assertEqual(lists:seq(1, N), [K || {_, K} <- Answers]),
    Tags = [T || {T, _} <- Answers],
    {Old, New} = lists:splitwith(fun(T) -> T =:= <<"v1">> end, Tags),
    ct:pal("~b answers by the old code, ~b by the new", [length(Old), length(New)]),
    ?assert(length(Old) >= 300),
    ?assert(length(New) > 0),
    ?assertEqual([], [T || T <- New, T =/= <<"v2">>]).

%%% ---------------------------------------------------------------------
%%% Lockstep
%%% ---------------------------------------------------------------------

lockstep_timers_at_simulated_deadlines(doc) ->
    ["In lockstep a Lua behavior's wait_for_input timeout and sched.sleep fire at "
     "their simulated deadlines, to the millisecond, and its clock is the world's"];
lockstep_timers_at_simulated_deadlines(Config) ->
    {module, _} = code:ensure_loaded(toroco_clock),
    case erlang:function_exported(toroco_clock, lockstep, 1) of
        false -> {skip, "this runtime has no lockstep yet"};
        true -> lockstep(Config)
    end.

lockstep_step_pending_answers_at_once(doc) ->
    ["In lockstep a step that waits for a slow Lua activation holds the world, yet "
     "the behavior answers inspect, suspend and resume at once meanwhile; its emission "
     "is in the step"];
lockstep_step_pending_answers_at_once(Config) ->
    ok = toroco_clock:lockstep(#{}),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [done]),
    ok = toroco_lua:add_behavior(slow, #{file => data(Config, "slow.lua"), budget => 100000000}),
    ok = toroco:set_inputs(slow, #{value => [{s, value}]}),
    ok = toroco:set_inputs(a, #{done => [{slow, done}]}),
    {ok, _} = toroco_clock:tick(100, []),
    Self = self(),
    Ticker = spawn_link(fun() ->
                                ok = toroco:inject({s, value}, 1),
                                Self ! {ticked, toroco_clock:settle()}
                        end),
    %% the step is out while lua_port counts
    toroco_test_lib:wait_until(fun() -> is_map(toroco:inspect(slow))
                                            andalso maps:get(state, maps:get(process, toroco:inspect(slow)))
                                            =:= step_pending end, ?WAIT, step_pending),
    {T, #{behavior := #{waits := {busy, 1}}}} = timer:tc(toroco, inspect, [slow]),
    {T2, ok} = timer:tc(toroco, suspend_behavior, [slow]),
    {T3, ok} = timer:tc(toroco, resume_behavior, [slow]),
    ct:pal("inspect, suspend, resume while a lockstep step waits for Lua: ~w us", [[T, T2, T3]]),
    ?assert(lists:max([T, T2, T3]) < 10000),
    receive {ticked, ok} -> ok after 2 * ?WAIT -> ct:fail({no_tick, Ticker}) end,
    ?assertEqual([{done, 1, 100}], toroco_fake_actuator:history(a)).

lockstep(Config) ->
    ok = toroco_clock:lockstep(#{}),
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [go, more]}),
    actuator(a, [got, more, timeout, tick]),
    ok = toroco_lua:add_behavior(w, #{file => data(Config, "waiter.lua")}),
    ok = toroco:set_inputs(w, #{go => [{s, go}], more => [{s, more}]}),
    ok = toroco:set_inputs(a, #{got => [{w, got}], more => [{w, more}],
                                timeout => [{w, timeout}]}),
    {ok, _} = toroco_clock:tick(100, []),
    ok = toroco:inject({s, go}, 1),
    ok = toroco_clock:settle(),
    {ok, _} = toroco_clock:tick(299, []),
    ?assertEqual([{got, 1, 100}], toroco_fake_actuator:history(a)),
    {ok, _} = toroco_clock:tick(1000, []),
    ?assertEqual([{got, 1, 100}, {timeout, 1, 300}], toroco_fake_actuator:history(a)),
    ok = toroco_fake_actuator:clear(a),
    ok = toroco_lua:add_behavior(t, #{file => data(Config, "sleeper.lua")}),
    ok = toroco:set_inputs(a, #{tick => [{t, tick}]}),
    ok = toroco_clock:settle(),
    {ok, _} = toroco_clock:tick(1200, []),
    %% a tick at start (unwired yet: lost) and then one every 50 ms
    Ticks = [{N, T} || {tick, N, T} <- toroco_fake_actuator:history(a)],
    ?assertEqual([{K + 1, 1000 + 50 * K} || K <- lists:seq(1, 4)], Ticks).

%%% ---------------------------------------------------------------------
%%% Helpers
%%% ---------------------------------------------------------------------

data(Config, Name) ->
    filename:join(?config(data_dir, Config), Name).

actuator(Name, Inputs) ->
    ok = toroco:add_device(Name, toroco_fake_actuator, #{inputs => Inputs}).

values(A, Input) ->
    [V || {I, V, _} <- toroco_fake_actuator:history(A), I =:= Input].

await(A, Input, Want) ->
    case toroco_fake_actuator:await(A, fun(H) -> [V || {I, V, _} <- H, I =:= Input] =:= Want end,
                                    ?WAIT) of
        ok -> ok;
        {error, timeout} -> ct:fail({A, Input, want, Want, got, values(A, Input)})
    end.

%% The load: 1..N injected into Source from a linked process, one a
%% millisecond at most (pacing, not waiting on anything). A loaded machine
%% stretches each millisecond's pause many times over (tens of ms beside two
%% busy loops), so the test waits for the load's end, then for its
%% deliveries.
paced(Source, N) ->
    toroco_test_lib:paced(fun(K) -> ok = toroco:inject(Source, K) end, N, 1).

injected(Load) ->
    _ = toroco_test_lib:await_paced(Load, ?LOADED),
    ok.

%% faulty.lua as behavior f on sensor s, reporting to actuator a, beside an
%% Erlang path e -> a; one good round first.
faulty(File) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [kind]}),
    ok = toroco:add_device(e, toroco_fake_sensor, #{outputs => [value]}),
    actuator(a, [alive, erl]),
    ok = toroco_lua:add_behavior(f, #{file => File, layer => 1}),
    ok = toroco:set_inputs(f, #{kind => [{s, kind}]}),
    ok = toroco:set_inputs(a, #{alive => [{f, alive}], erl => [{e, value}]}),
    ok = toroco:inject({s, kind}, <<"ok">>),
    await(a, alive, [<<"ok">>]),
    ok = toroco:inject({e, value}, 1),
    await(a, erl, [1]).

%% Injects Kind and returns the reason behavior Name stopped with.
fault(Name, Kind) ->
    Ref = erlang:monitor(process, toroco:whereis(Name)),
    ok = toroco:inject({s, kind}, Kind),
    receive {'DOWN', Ref, process, _, Why} -> Why
    after 2 * ?WAIT -> ct:fail({not_stopped, Name, Kind})
    end.

%% Waits (bounded) for a new program (not OsPid) with every behavior of Names
%% answering in it.
reattached(Names, OsPid) ->
    New = fun() -> case toroco_lua_port:os_pid() of
                       P when is_integer(P) -> P =/= OsPid;
                       _ -> false
                   end
          end,
    ok = toroco_test_lib:wait_until(New, ?WAIT, {new_program, OsPid}),
    [back(N) || N <- Names],
    ok.

%% Waits (bounded) for behavior Name to be registered and running again.
back(Name) ->
    Running = fun() -> is_pid(toroco:whereis(Name)) andalso answers(Name) end,
    ok = toroco_test_lib:wait_until(Running, ?WAIT, {back, Name}).

answers(Name) ->
    case catch toroco_lua:waits(Name) of
        {ok, _} -> true;
        _ -> false
    end.
