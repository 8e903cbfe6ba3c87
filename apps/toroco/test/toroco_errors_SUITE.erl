%% Every API error is a value naming the culprit, and a refused change changes
%% nothing (SPEC §4 "Errors", "Wiring changes").
-module(toroco_errors_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [values/1, await_values/2, settle/1, sensor/2, actuator/2]).

suite() -> [{timetrap, {seconds, 30}}].

all() -> [bad_api_calls_name_the_culprit, refused_wiring_changes_nothing,
          malformed_wiring_files_are_refused_whole, inhibition_cycles_are_refused,
          hierarchy_is_checked, read_wiring_says_what_a_file_adds].

init_per_testcase(_TC, Config) ->
    toroco_test_lib:start(),
    ok = toroco:add_behavior(hi, tb_relay, #{layer => 1, params => #{latch => high}}),
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => low}}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {lo, out}]}),
    await_values(a, [high]),
    Config.

end_per_testcase(_TC, _Config) ->
    toroco_test_lib:stop().

%% The state a refused call must leave untouched.
snapshot() ->
    {toroco:inspect(), toroco:inspect(a), toroco:inspect(hi), toroco:inspect(lo), values(a)}.

bad_api_calls_name_the_culprit() ->
    [{doc, "Each bad API call returns {error, Reason} naming the offender and changes nothing."}].
bad_api_calls_name_the_culprit(_) ->
    Before = snapshot(),
    Cases =
        [{fun() -> toroco:add_behavior(hi, tb_relay, #{}) end, {duplicate_name, hi}},
         {fun() -> toroco:add_device(hi, toroco_fake_sensor, #{outputs => [x]}) end, {duplicate_name, hi}},
         {fun() -> toroco:add_behavior(x, no_such_module, #{}) end, {bad_module, no_such_module}},
         {fun() -> toroco:add_behavior(x, tb_relay, #{layer => -1}) end, {bad_layer, {x, -1}}},
         {fun() -> toroco:add_behavior(x, tb_relay, #{layer => one}) end, {bad_layer, {x, one}}},
         {fun() -> toroco:add_behavior(x, tb_relay, #{colour => red}) end, {bad_option, {x, colour}}},
         {fun() -> toroco:add_behavior(x, tb_relay, #{params => [1]}) end, {bad_params, {x, [1]}}},
         {fun() -> toroco:add_behavior("x", tb_relay, #{}) end, {bad_name, "x"}},
         {fun() -> toroco:add_behavior(x, tb_relay, not_a_map) end, {bad_options, {x, not_a_map}}},
         {fun() -> toroco:remove_behavior(nobody) end, {unknown_name, nobody}},
         {fun() -> toroco:remove_behavior(a) end, {not_a_behavior, a}},
         {fun() -> toroco:remove_device(hi) end, {not_a_device, hi}},
         {fun() -> toroco:suspend_behavior(nobody) end, {unknown_name, nobody}},
         {fun() -> toroco:suspend_behavior(a) end, {not_a_behavior, a}},
         {fun() -> toroco:resume_behavior(nobody) end, {unknown_name, nobody}},
         {fun() -> toroco:set_inputs(nobody, #{in => []}) end, {unknown_name, nobody}},
         {fun() -> toroco:set_inputs(a, #{nope => [{hi, out}]}) end, {unknown_input, {a, nope}}},
         {fun() -> toroco:set_inputs(a, #{in => [{ghost, out}]}) end, {unknown_name, ghost}},
         {fun() -> toroco:set_inputs(a, #{in => [{hi, nope}]}) end, {unknown_output, {hi, nope}}},
         {fun() -> toroco:set_inputs(a, #{in => [{hi, out, #{hold => -5}}]}) end, {bad_hold, {{hi, out}, -5}}},
         {fun() -> toroco:set_inputs(a, #{in => [{hi, out, #{hold => soon}}]}) end, {bad_hold, {{hi, out}, soon}}},
         {fun() -> toroco:set_inputs(a, #{in => [{hi, out, #{priority => 1}}]}) end, {bad_option, {{hi, out}, priority}}},
         {fun() -> toroco:set_inputs(a, #{in => [{hi, out}, {hi, out}]}) end, {duplicate_source, {{a, in}, {hi, out}}}},
         {fun() -> toroco:set_inputs(a, #{in => [hi]}) end, {bad_source, hi}},
         {fun() -> toroco:set_inputs(a, #{in => #{sources => [{hi, out}], buffer => some}}) end,
          {bad_option, {{a, in}, {buffer, some}}}},
         {fun() -> toroco:set_inputs(a, #{in => #{sources => [{hi, out}], size => 3}}) end,
          {bad_option, {{a, in}, size}}},
         {fun() -> toroco:set_inputs(a, [{in, []}]) end, {bad_inputs, {a, [{in, []}]}}},
         {fun() -> toroco:set_inhibitors(lo, #{nope => [{hi, out}]}) end, {unknown_output, {lo, nope}}},
         {fun() -> toroco:set_inhibitors(ghost, #{out => [{hi, out}]}) end, {unknown_name, ghost}},
         {fun() -> toroco:set_inhibitors(lo, #{out => [{hi, out, #{hold => -1}}]}) end, {bad_hold, {{hi, out}, -1}}},
         {fun() -> toroco:set_reset(a, [{hi, out}]) end, {not_a_behavior, a}},
         {fun() -> toroco:set_reset(ghost, [{hi, out}]) end, {unknown_name, ghost}},
         {fun() -> toroco:set_reset(lo, [{hi, gone}]) end, {unknown_output, {hi, gone}}},
         {fun() -> toroco:inject({ghost, out}, 1) end, {unknown_name, ghost}},
         {fun() -> toroco:inject({hi, nope}, 1) end, {unknown_output, {hi, nope}}},
         {fun() -> toroco:inject({hi, out}, 1, #{hold => -1}) end, {bad_hold, {{hi, out}, -1}}},
         {fun() -> toroco:inject({hi, out}, 1, #{louder => true}) end, {bad_option, {{hi, out}, louder}}},
         {fun() -> toroco:inject(hi, 1) end, {bad_source, hi}},
         {fun() -> toroco:inspect(ghost) end, {unknown_name, ghost}},
         {fun() -> toroco:load_wiring("/nonexistent/file.wiring") end,
          {wiring_file, "/nonexistent/file.wiring", enoent}}],
    Results = [{Expected, catch F()} || {F, Expected} <- Cases],
    Wrong = [{E, R} || {E, R} <- Results, R =/= {error, E}],
    ct:pal("~p bad API calls, ~p answered with an unexpected value: ~p",
           [length(Cases), length(Wrong), Wrong]),
    [] = Wrong,
    Before = snapshot().

refused_wiring_changes_nothing() ->
    [{doc, "A call with one bad input among good ones applies none of them."}].
refused_wiring_changes_nothing(_) ->
    actuator(b, [in, in2]),
    Before = {toroco:inspect(b), snapshot()},
    {error, {unknown_output, {lo, nope}}} =
        toroco:set_inputs(b, #{in => [{hi, out}], in2 => [{lo, nope}]}),
    {error, {hierarchy, _}} =
        toroco:set_inputs(b, #{in => [{hi, out}], in2 => [{lo, out}, {hi, out}]}),
    Before = {toroco:inspect(b), snapshot()},
    settle(b),
    [] = values(b).

malformed_wiring_files_are_refused_whole() ->
    [{doc, "At least 20 malformed wiring files are each refused with a reason, and nothing starts."}].
malformed_wiring_files_are_refused_whole(Config) ->
    Dir = ?config(priv_dir, Config),
    Good = "{behavior, extra, tb_relay, #{layer => 0}}.\n",
    Files =
        [{"{behavior, hi, tb_relay, #{}}.", {duplicate_name, hi}},
         {Good ++ "{behavior, extra, tb_relay, #{}}.", {duplicate_name, extra}},
         {Good ++ "{inputs, extra, #{in => [{ghost, out}]}}.", {unknown_name, ghost}},
         {Good ++ "{inputs, extra, #{nope => []}}.", {unknown_input, {extra, nope}}},
         {Good ++ "{inputs, extra, #{in => [{hi, nope}]}}.", {unknown_output, {hi, nope}}},
         {Good ++ "{inputs, extra, #{in => [{hi, out, #{hold => -1}}]}}.", {bad_hold, {{hi, out}, -1}}},
         {Good ++ "{inputs, extra, #{in => [{lo, out}, {hi, out}]}}.",
          {hierarchy, {{extra, in}, {{lo, out}, 0}, {{hi, out}, 1}}}},
         {Good ++ "{inputs, extra, [in]}.", {bad_inputs, {extra, [in]}}},
         {Good ++ "{inhibitors, extra, #{out => [{extra, out}]}}.", {inhibition_cycle, [{extra, out}]}},
         {Good ++ "{inhibitors, hi, #{out => [{extra, out}]}}.",
          {hierarchy, {{hi, out}, {inhibitor, {extra, out}, 0}, {emitter, {hi, out}, 1}}}},
         {Good ++ "{reset, a, [{extra, out}]}.", {not_a_behavior, a}},
         {Good ++ "{robot, torobot}.", {bad_wiring_term, {robot, torobot}}},
         {Good ++ "{behavior, y, tb_relay, #{layer => -2}}.", {bad_layer, {y, -2}}},
         {Good ++ "{behavior, y, nonexistent_module, #{}}.", {bad_module, nonexistent_module}},
         {Good ++ "{behavior, y, tb_relay, #{speed => 3}}.", {bad_option, {y, speed}}},
         {Good ++ "{device, y, toroco_fake_sensor, #{}}.", bad_interface},
         {Good ++ "{device, \"y\", toroco_fake_sensor, #{outputs => [v]}}.", {bad_name, "y"}},
         {Good ++ "{inputs, extra, #{in => #{sources => [{hi, out}], buffer => all, idle => 0, x => 1}}}.",
          {bad_option, {{extra, in}, x}}},
         {Good ++ "{inputs, extra, #{in => [{hi, out}, {hi, out}]}}.", {duplicate_source, {{extra, in}, {hi, out}}}},
         {Good ++ "{inputs, extra, #{in => [hi]}}.", {bad_source, hi}},
         {Good ++ "{inputs, extra}.", {bad_wiring_term, {inputs, extra}}},
         {Good ++ "{inputs, extra, #{in => [{hi, out}]}", syntax}],
    Before = snapshot(),
    Results = [begin
                   F = filename:join(Dir, "bad" ++ integer_to_list(I) ++ ".wiring"),
                   ok = file:write_file(F, Text),
                   {Expected, toroco:load_wiring(F)}
               end || {I, {Text, Expected}} <- lists:zip(lists:seq(1, length(Files)), Files)],
    Wrong = [{E, R} || {E, R} <- Results, not refused_as(E, R)],
    ct:pal("~p malformed wiring files, ~p not refused as expected: ~p",
           [length(Files), length(Wrong), Wrong]),
    [] = Wrong,
    Before = snapshot(),
    undefined = whereis(toroco_names:process(extra)).

refused_as(bad_interface, {error, {bad_interface, _}}) -> true;
refused_as(syntax, {error, {wiring_file, _, {_Line, erl_parse, _}}}) -> true;
refused_as(E, {error, E}) -> true;
refused_as(_, _) -> false.

inhibition_cycles_are_refused() ->
    [{doc, "Inhibition cycles are refused except a same-layer pair inhibiting each other."}].
inhibition_cycles_are_refused(_) ->
    [ok = toroco:add_behavior(N, tb_relay, #{layer => 1}) || N <- [x, y, z, p, q, r]],
    ok = toroco:set_inhibitors(x, #{out => [{y, out}]}),
    ok = toroco:set_inhibitors(y, #{out => [{x, out}]}),            % a pair: allowed
    ok = toroco:set_inhibitors(y, #{out2 => [{z, out}]}),
    ok = toroco:set_inhibitors(z, #{out => [{y, out2}]}),           % another pair
    ok = toroco:set_inhibitors(p, #{out => [{q, out}]}),
    ok = toroco:set_inhibitors(q, #{out => [{r, out}]}),
    {error, {inhibition_cycle, [{p, out}, {q, out}, {r, out}]}} =
        toroco:set_inhibitors(r, #{out => [{p, out}]}),             % a ring of three
    ok = toroco:set_inhibitors(z, #{out2 => [{x, out2}]}),
    ok = toroco:set_inhibitors(x, #{out2 => [{z, out2}]}),          % pair x.out2 <-> z.out2
    {error, {inhibition_cycle, _}} = toroco:set_inhibitors(p, #{out2 => [{p, out2}]}),
    {error, {hierarchy, _}} = toroco:set_inhibitors(hi, #{out => [{lo, out}]}),
    #{outputs := #{out := #{inhibitors := []}}} = toroco:inspect(r).

hierarchy_is_checked() ->
    [{doc, "A source may not sit above one of a higher layer; devices are layer 0."}].
hierarchy_is_checked(_) ->
    sensor(s, [v]),
    {error, {hierarchy, {{a, in}, {{s, v}, 0}, {{hi, out}, 1}}}} =
        toroco:set_inputs(a, #{in => [{s, v}, {hi, out}]}),
    ok = toroco:set_inputs(a, #{in => [{hi, out}, {s, v}, {lo, out}]}),
    ok = toroco:set_inhibitors(lo, #{out => [{hi, out}]}),
    %% the receiver's own layer does not matter
    ok = toroco:set_inputs(lo, #{in => [{hi, out}]}).

read_wiring_says_what_a_file_adds() ->
    [{doc, "read_wiring/1 says what a wiring file adds (behaviors and devices in the file's "
      "order, their modules, the inputs it wires, the other nodes) without loading it; a "
      "file that cannot be read is refused naming it."}].
read_wiring_says_what_a_file_adds(Config) ->
    F = filename:join(?config(priv_dir, Config), "summary.wiring"),
    ok = file:write_file(F, "{device, s2, toroco_fake_sensor, #{outputs => [v]}}.\n"
                            "{behavior, b2, tb_relay, #{layer => 1}}.\n"
                            "{behavior, b1, tb_relay, #{layer => 2}}.\n"
                            "{inputs, b1, #{in => [{s2, v}]}}.\n"
                            "{inputs, b2, #{in => [{s2, v}], other => [{b1, out}]}}.\n"),
    Before = snapshot(),
    ?assertEqual({ok, #{behaviors => [b2, b1], devices => [s2],
                        modules => #{s2 => toroco_fake_sensor, b2 => tb_relay, b1 => tb_relay},
                        inputs => [{b1, in}, {b2, in}, {b2, other}], nodes => [],
                        placement => #{}}},
                 toroco:read_wiring(F)),
    Before = snapshot(),
    ?assertMatch({error, {wiring_file, {"/nonexistent/x.wiring", enoent}}},
                 toroco:read_wiring("/nonexistent/x.wiring")).
