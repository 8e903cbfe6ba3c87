%% Hot code reload (SPEC §9, toroco:reload/1): the code of a behavior is
%% compiled at test time in versions that differ in what they emit and in
%% the shape of their state, then replaced under a stream of inputs.
-module(toroco_reload_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [values/1, sensor/2, actuator/2, wait_until/2]).

suite() -> [{timetrap, {seconds, 60}}].

all() -> [reload_under_1khz_stream_loses_nothing, failing_code_change_rolls_everything_back,
          code_kept_when_behavior_starts, failure_without_old_code_is_reported,
          refusals_change_nothing, idle_module_and_several_behaviors_reload,
          reload_makes_the_callback_funs_again].

init_per_suite(Config) ->
    Dir = filename:join(?config(priv_dir, Config), "reload_code"),
    ok = filelib:ensure_path(Dir),
    true = code:add_patha(Dir),
    [{code_dir, Dir} | Config].

end_per_suite(Config) ->
    code:del_path(?config(code_dir, Config)),
    ok.

init_per_testcase(TC, Config) ->
    toroco_test_lib:start(),
    [{module, list_to_atom("tb_reload_" ++ atom_to_list(TC))} | Config].

end_per_testcase(_TC, Config) ->
    toroco_test_lib:stop(),
    Mod = ?config(module, Config),
    _ = code:purge(Mod), _ = code:delete(Mod), _ = code:purge(Mod),
    ok.

%%====================================================================
%% Cases
%%====================================================================

reload_under_1khz_stream_loses_nothing() ->
    [{doc, "Inputs streamed at 1 kHz through a behavior while its module is reloaded all arrive, "
           "in order; the ones after the reload are handled by the new code with the converted "
           "state; its latch, the holds at its input and at its receiver survive."}].
reload_under_1khz_stream_loses_nothing(Config) ->
    Mod = ?config(module, Config),
    load(Config, 1),
    sensor(s, [v, l]),
    actuator(a, [out, mark]),
    ok = toroco:add_behavior(b, Mod, #{layer => 1}),
    ok = toroco:set_inputs(b, #{in => [{s, v}], latch => [{s, l}]}),
    ok = toroco:set_inputs(a, #{out => [{b, out}], mark => [{b, mark}]}),
    %% A latch of b (delivered to a), a timed hold at b's input router, and
    %% b's own timed holds at a's router (each of its sends holds 60 s).
    ok = toroco:inject({s, l}, armed, #{hold => 60000}),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:keymember(mark, 1, H) end, 3000),
    OldVsn = vsn(Mod),
    compile(Config, 2),                              % on disk; v1 still runs
    N = 1500,
    Streamer = stream(s, v, N),
    wait_until(fun() -> length(values(a)) >= 300 end, 5000),
    {Micros, ok} = timer:tc(toroco, reload, [Mod]),
    ct:pal("reload of ~p took ~.1f ms, ~p inputs delivered before it",
           [Mod, Micros / 1000, length(values(a)) - 1]),
    {done, Late} = finish(Streamer),
    ok = toroco_fake_actuator:await(a, fun(H) -> length([x || {out, _, _} <- H]) >= N end, 10000),
    Outs = [V || {out, V, _} <- toroco_fake_actuator:history(a)],
    %% Nothing lost, nothing reordered, one switch from v1 to v2.
    Seq = lists:seq(1, N),
    Seq = [I || {_, I} <- Outs],
    {V1, V2} = lists:splitwith(fun({Tag, _}) -> Tag =:= v1 end, Outs),
    true = V1 =/= [] andalso V2 =/= [],
    true = lists:all(fun({Tag, _}) -> Tag =:= v2 end, V2),
    %% The state came across: v2 counts on from v1 and knows where it came from.
    #{count := N, version := 2, from := OldVsn} = gen_statem:call(toroco_names:process(b), state),
    %% Latches and holds.
    #{outputs := #{mark := #{latch := {value, armed}}},
      inputs := #{latch := #{holds := [{{s, l}, InHold}], winner := {s, l}}}} = toroco:inspect(b),
    #{inputs := #{mark := #{latches := [{{b, mark}, armed}], holds := [{{b, mark}, infinity}]},
                  out := #{holds := [{{b, out}, OutHold}]}}} = toroco:inspect(a),
    true = InHold > 50000 andalso OutHold > 50000,
    ct:pal("streamer fell ~p ms behind its schedule at most", [Late]).

failing_code_change_rolls_everything_back() ->
    [{doc, "When code_change fails in one behavior, every behavior is back on the old code with "
           "the state it had, the error names the one that failed, and inputs sent meanwhile "
           "are handled by the old code."}].
failing_code_change_rolls_everything_back(Config) ->
    Mod = ?config(module, Config),
    load(Config, 1),
    sensor(s, [v]),
    actuator(a, [out, out2]),
    ok = toroco:add_behavior(good, Mod, #{layer => 1}),
    ok = toroco:add_behavior(bad, Mod, #{layer => 1, params => #{fail => true}}),
    ok = toroco:set_inputs(good, #{in => [{s, v}]}),
    ok = toroco:set_inputs(bad, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{out => [{good, out}], out2 => [{bad, out}]}),
    compile(Config, 2),
    ok = toroco:reload(Mod),                         % v2 is now loaded and kept
    V2 = Mod:module_info(md5),
    compile(Config, 3),                              % refuses to convert `bad'
    Streamer = stream(s, v, 200),
    {error, {code_change_failed, [{bad, refused_by_test}]}} = toroco:reload(Mod),
    {done, _} = finish(Streamer),
    V2 = Mod:module_info(md5),
    ok = toroco_fake_actuator:await(a, fun(H) -> length(H) >= 400 end, 5000),
    H = toroco_fake_actuator:history(a),
    Seq = lists:seq(1, 200),
    Seq = [I || {out, {v2, I}, _} <- H],
    Seq = [I || {out2, {v2, I}, _} <- H],
    %% `good' converted to v3 before `bad' failed; it has its v2 state back.
    #{version := 2, count := 200} = gen_statem:call(toroco_names:process(good), state),
    #{version := 2, count := 200} = gen_statem:call(toroco_names:process(bad), state).

code_kept_when_behavior_starts() ->
    [{doc, "The code a behavior starts with is kept, so even the first reload of its module can "
           "be undone."}].
code_kept_when_behavior_starts(Config) ->
    Mod = ?config(module, Config),
    load(Config, 1),
    ok = toroco:add_behavior(b, Mod, #{layer => 0, params => #{fail => true}}),
    case toroco_reload:kept(Mod) of
        false ->
            {skip, "the wiring server does not call toroco_reload:remember/1 when it starts a node"};
        true ->
            V1 = Mod:module_info(md5),
            compile(Config, 3),
            {error, {code_change_failed, [{b, refused_by_test}]}} = toroco:reload(Mod),
            V1 = Mod:module_info(md5),
            #{count := 0} = gen_statem:call(toroco_names:process(b), state),
            ok
    end.

failure_without_old_code_is_reported() ->
    [{doc, "If the old code was not kept, a failing code_change cannot be undone and the error "
           "says so; the behavior that failed keeps its old state, the others their new one."}].
failure_without_old_code_is_reported(Config) ->
    Mod = ?config(module, Config),
    %% v1 loaded from a binary whose file is gone: nothing can keep it.
    {ok, Mod, Bin} = compile:file(write_source(Config, 1), [binary, return_errors]),
    {module, Mod} = code:load_binary(Mod, "/nonexistent/" ++ atom_to_list(Mod) ++ ".beam", Bin),
    ok = toroco:add_behavior(good, Mod, #{layer => 0}),
    ok = toroco:add_behavior(bad, Mod, #{layer => 0, params => #{fail => true}}),
    false = toroco_reload:kept(Mod),
    compile(Config, 3),
    {error, {code_change_failed, [{bad, refused_by_test}], old_code_not_kept}} = toroco:reload(Mod),
    {ok, {Mod, V3}} = beam_lib:md5(code:which(Mod)),
    V3 = Mod:module_info(md5),
    #{version := 3} = gen_statem:call(toroco_names:process(good), state),
    #{version := 1} = gen_statem:call(toroco_names:process(bad), state).

refusals_change_nothing() ->
    [{doc, "A module that is not a module, has no object code, or whose object code is the one "
           "loaded is refused with a reason naming it, and nothing is paused or loaded."}].
refusals_change_nothing(Config) ->
    Mod = ?config(module, Config),
    load(Config, 1),
    ok = toroco:add_behavior(b, Mod, #{layer => 0}),
    {error, {bad_module, "b"}} = toroco:reload("b"),
    {error, {no_object_code, tb_reload_nowhere}} = toroco:reload(tb_reload_nowhere),
    {error, {unchanged, Mod}} = toroco:reload(Mod),
    #{status := running} = toroco:inspect(b),
    {status, _, _, [_, running | _]} = sys:get_status(toroco_names:process(b)).

idle_module_and_several_behaviors_reload() ->
    [{doc, "A module nobody runs reloads without pausing anything; a loaded module is reloaded "
           "for every node running it, and reload returns only once they run again."}].
idle_module_and_several_behaviors_reload(Config) ->
    Mod = ?config(module, Config),
    load(Config, 1),
    compile(Config, 2),
    ok = toroco:reload(Mod),                         % nobody runs it
    #{} = Mod:interface(),
    ok = toroco:add_behavior(b1, Mod, #{layer => 0}),
    ok = toroco:add_behavior(b2, Mod, #{layer => 2}),
    #{version := 2} = gen_statem:call(toroco_names:process(b1), state),
    compile(Config, 1),
    ok = toroco:reload(Mod),
    [#{version := 1}, #{version := 1}] =
        [gen_statem:call(toroco_names:process(B), state) || B <- [b1, b2]],
    {status, _, _, [_, running | _]} = sys:get_status(toroco_names:process(b2)).

reload_makes_the_callback_funs_again() ->
    [{doc, "The engine calls a behavior's callbacks through funs made at start and made again "
           "by a reload: a module that gains handle_event/4 answers calls with it afterwards, "
           "and its inputs run the new handle_input/4."}].
reload_makes_the_callback_funs_again(Config) ->
    Mod = ?config(module, Config),
    Src = write_source(Config, 2),
    ok = file:write_file(Src, without_events(Mod)),
    {ok, Mod} = compile:file(Src, [{outdir, ?config(code_dir, Config)}, return_errors]),
    {module, Mod} = code:load_file(Mod),
    sensor(s, [v]),
    actuator(a, [out]),
    ok = toroco:add_behavior(b, Mod, #{layer => 1}),
    ok = toroco:set_inputs(b, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{out => [{b, out}]}),
    ok = toroco:inject({s, v}, 1),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:keymember(out, 1, H) end, 3000),
    B = toroco_names:process(b),
    {error, {unknown_call, {b, state}}} = gen_statem:call(B, state, 3000),
    compile(Config, 2),
    ok = toroco:reload(Mod),
    #{version := 2, count := 0} = gen_statem:call(B, state, 3000),
    ok = toroco:inject({s, v}, 2),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:keymember({v2, 2}, 2, H) end, 3000),
    [{v0, 1}, {v2, 2}] = [V || {out, V, _} <- toroco_fake_actuator:history(a)].

%% Version 0: no handle_event/4; its state counts nothing.
without_events(Mod) ->
    io_lib:format(
      "-module(~w).~n"
      "-behaviour(toroco_behavior).~n"
      "-export([interface/0, init/1, handle_input/4]).~n"
      "interface() -> #{inputs => [in, latch], outputs => [out, mark]}.~n"
      "init(P) -> {ok, relaying, #{count => 0, params => P, version => 0}}.~n"
      "handle_input(in, V, _S, _D) ->~n"
      "    {keep_state_and_data, [{send, #{out => {v0, V}}}]};~n"
      "handle_input(latch, _V, _S, _D) ->~n"
      "    keep_state_and_data.~n", [Mod]).

%%====================================================================
%% The behavior, in three versions
%%====================================================================

%% Version K emits {vK, V} for each input V on `in' (with a 60 s hold) and
%% latches `latch' inputs on `mark'; its state is #{count, params, version};
%% its code_change sets `version' to K and (2 and 3) `from' to the old vsn.
%% Version 3's code_change refuses behaviors started with #{fail => true}.
source(Mod, Version) ->
    io_lib:format(
      "-module(~w).~n"
      "-behaviour(toroco_behavior).~n"
      "-export([interface/0, init/1, handle_input/4, handle_event/4, code_change/4]).~n"
      "interface() -> #{inputs => [in, latch], outputs => [out, mark]}.~n"
      "init(P) -> {ok, relaying, #{count => 0, params => P, version => ~w}}.~n"
      "handle_input(in, V, _S, D = #{count := N}) ->~n"
      "    {keep_state, D#{count := N + 1}, [{send, #{out => {~w, V}}, #{hold => 60000}}]};~n"
      "handle_input(latch, V, _S, _D) ->~n"
      "    {keep_state_and_data, [{set, #{mark => V}}]}.~n"
      "handle_event({call, From}, state, _S, D) ->~n"
      "    {keep_state_and_data, [{reply, From, D}]}.~n"
      "~s",
      [Mod, Version, list_to_atom("v" ++ integer_to_list(Version)), code_change(Version)]).

code_change(1) ->
    "code_change(_Old, S, D, _Extra) -> {ok, S, D#{version => 1}}.\n";
code_change(2) ->
    "code_change(Old, S, D, _Extra) -> {ok, S, D#{version => 2, from => Old}}.\n";
code_change(3) ->
    "code_change(_Old, _S, #{params := #{fail := true}}, _Extra) -> erlang:error(refused_by_test);\n"
    "code_change(Old, S, D, _Extra) -> {ok, S, D#{version => 3, from => Old}}.\n".

write_source(Config, Version) ->
    Mod = ?config(module, Config),
    Src = filename:join(?config(code_dir, Config), atom_to_list(Mod) ++ ".erl"),
    ok = file:write_file(Src, source(Mod, Version)),
    Src.

%% Compiles version `Version' into the code path without loading it.
compile(Config, Version) ->
    Mod = ?config(module, Config),
    {ok, Mod} = compile:file(write_source(Config, Version),
                             [{outdir, ?config(code_dir, Config)}, return_errors]),
    ok.

load(Config, Version) ->
    Mod = ?config(module, Config),
    compile(Config, Version),
    _ = code:purge(Mod),
    {module, Mod} = code:load_file(Mod),
    ok.

vsn(Mod) ->
    {vsn, [V]} = lists:keyfind(vsn, 1, Mod:module_info(attributes)),
    V.

%%====================================================================
%% A 1 kHz stream
%%====================================================================

%% Injects 1..N on {E, Out}, one a millisecond at most.
stream(E, Out, N) ->
    toroco_test_lib:paced(fun(I) -> ok = toroco:inject({E, Out}, I) end, N, 1).

%% How late the stream's latest value was sent, once all are.
finish(Streamer) ->
    {done, toroco_test_lib:await_paced(Streamer, 30000)}.
