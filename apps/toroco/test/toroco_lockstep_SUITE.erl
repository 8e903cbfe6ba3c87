%% Lockstep virtual time (SPEC §14, "Lockstep") at the runtime's level:
%% `toroco_clock:lockstep/1' makes the node's clock virtual, `tick/2' moves
%% it, and the event path runs one step at a time. These cases pin what a
%% simulated world relies on: a cascade ends within its tick whatever the
%% machine's load, timers and holds count simulated milliseconds and fire
%% at their deadlines, tap events carry simulated time, and two runs of the
%% same stimuli give the same trace.
-module(toroco_lockstep_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-include_lib("toroco/src/toroco_wire.hrl").

-compile([export_all, nowarn_export_all]).

suite() ->
    [{timetrap, {minutes, 3}}].

all() ->
    [cascade_of_20_ends_in_its_tick, timers_fire_at_simulated_deadlines,
     holds_end_in_simulated_time, tap_carries_simulated_time, same_stimuli_same_trace,
     speed_is_refused_in_lockstep, name_resolved_when_sent, trace_terms_as_io_lib_writes_them].

init_per_testcase(_TC, Config) ->
    toroco_test_lib:start(),
    Config.

end_per_testcase(_TC, _Config) ->
    _ = toroco_clock:realtime(),
    toroco_test_lib:stop().

%%====================================================================
%% Cases
%%====================================================================

cascade_of_20_ends_in_its_tick() ->
    [{doc, "A chain of 20 behaviors, each doing real work, reaches the motors within the "
      "same tick, every tick, with both cores kept busy by burners: quiescence waits for "
      "the whole cascade."}].
cascade_of_20_ends_in_its_tick(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    chain(20),
    Burners = [spawn(fun burn/0) || _ <- [1, 2]],
    try
        [begin
             T = K * 50,
             {ok, _} = toroco_clock:tick(T, []),
             ok = toroco:inject({s, o}, K * 100),
             ok = toroco_clock:settle(),
             %% no wait: what quiescence promises is there when it answers
             ?assertEqual({T, K * 100 + 20}, last(motors))
         end || K <- lists:seq(1, 20)]
    after
        [exit(B, kill) || B <- Burners]
    end,
    ?assertEqual(20, length(toroco_fake_actuator:history(motors))).

timers_fire_at_simulated_deadlines() ->
    [{doc, "A behavior's {timeout, Name} of 300 ms fires when the world reaches 300 ms, "
      "not before and not in real time, stamped with the simulated time."}].
timers_fire_at_simulated_deadlines(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    toroco_test_lib:sensor(s, [o]),
    toroco_test_lib:actuator(a, [i]),
    ok = toroco:add_behavior(b, tb_timer, #{params => #{ms => 300}}),
    ok = toroco:set_inputs(b, #{in => [{s, o}]}),
    ok = toroco:set_inputs(a, #{i => [{b, out}]}),
    {ok, _} = toroco_clock:tick(100, []),
    ok = toroco:inject({s, o}, arm),
    ok = toroco_clock:settle(),
    {ok, _} = toroco_clock:tick(399, []),
    ?assertEqual([], toroco_fake_actuator:history(a)),
    {ok, _} = toroco_clock:tick(10000, []),
    ?assertEqual([{i, ticked, 400}], toroco_fake_actuator:history(a)),
    ?assertEqual(10000, toroco_clock:now_ms()).

holds_end_in_simulated_time() ->
    [{doc, "A 500 ms hold of a higher source keeps a lower one out until the world "
      "reaches its end, then the lower one's latch is delivered at exactly that time."}].
holds_end_in_simulated_time(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    toroco_test_lib:sensor(hi, [o]),
    toroco_test_lib:sensor(lo, [o]),
    toroco_test_lib:actuator(a, [i]),
    ok = toroco:set_inputs(a, #{i => [{hi, o}, {lo, o}]}),
    ok = toroco:inject({hi, o}, high, #{hold => 500}),
    ok = toroco:inject({lo, o}, low, #{latch => true}),
    ok = toroco_clock:settle(),
    {ok, _} = toroco_clock:tick(499, []),
    ?assertEqual([{i, high, 0}], toroco_fake_actuator:history(a)),
    {ok, _} = toroco_clock:tick(2000, []),
    ?assertEqual([{i, high, 0}, {i, low, 500}], toroco_fake_actuator:history(a)).

tap_carries_simulated_time() ->
    [{doc, "Tap events in lockstep carry the simulated time since the run began, in ns."}].
tap_carries_simulated_time(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    toroco_test_lib:sensor(s, [o]),
    toroco_test_lib:actuator(a, [i]),
    ok = toroco:set_inputs(a, #{i => [{s, o}]}),
    {ok, Ref} = toroco:subscribe_events(#{}),
    {ok, _} = toroco_clock:tick(1234, []),
    ok = toroco:inject({s, o}, x),
    ok = toroco_clock:settle(),
    receive
        {toroco_event, Ref, {emit, T, {s, o}, send, x}} -> ?assertEqual(1234000000, T)
    after 5000 -> ct:fail(no_tap_event)
    end.

same_stimuli_same_trace() ->
    [{doc, "The same network and stimuli, built twice, give byte-identical traces."}].
same_stimuli_same_trace(_Config) ->
    Trace = fun() ->
                    ok = toroco_clock:lockstep(#{trace => true}),
                    chain(5),
                    {ok, L0} = toroco_clock:tick(0, []),
                    Lines = [begin
                                 ok = toroco:inject({s, o}, K),
                                 {ok, L} = toroco_clock:tick(K * 10, []),
                                 L
                             end || K <- lists:seq(1, 10)],
                    ok = toroco_clock:realtime(),
                    toroco_test_lib:stop(),
                    toroco_test_lib:start(),
                    iolist_to_binary([L0 | Lines])
            end,
    A = Trace(),
    B = Trace(),
    ?assert(byte_size(A) > 0),
    ?assertEqual(A, B),
    ?assertNotEqual(nomatch, binary:match(A, <<"deliver in 6">>)).

speed_is_refused_in_lockstep() ->
    [{doc, "The world moves time in lockstep: setting a speed is refused, and real time "
      "comes back with realtime/0."}].
speed_is_refused_in_lockstep(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    ?assertEqual(lockstep, toroco_clock:mode()),
    ?assertEqual({error, lockstep}, toroco_clock:set_speed(10)),
    ok = toroco_clock:realtime(),
    ?assertEqual(realtime, toroco_clock:mode()),
    ?assertEqual(ok, toroco_clock:set_speed(1)).

name_resolved_when_sent() ->
    [{doc, "A step queued for a registered name goes to the process that had the name when "
      "it was sent, as `Name ! Msg' would: not to one that took the name while the step "
      "waited its turn (a behavior removed and added again must not get the "
      "unsubscription meant for the one before)."}].
name_resolved_when_sent(_Config) ->
    ok = toroco_clock:lockstep(#{}),
    Me = self(),
    Blocker = stepper(ls_blocker, fun(Token, _Msg) ->
                                          Me ! blocked,
                                          receive release -> toroco_lockstep:done(Token) end
                                  end),
    Old = stepper(ls_target, fun(Token, Msg) -> Me ! {old, Msg}, toroco_lockstep:done(Token) end),
    try
        %% the blocker holds the queue, so the next step waits behind it
        ok = toroco_wire:send({ls_blocker, node()}, ?WIRE_ACK(first)),
        receive blocked -> ok after 5000 -> ct:fail(blocker_not_stepped) end,
        ok = toroco_wire:send({ls_target, node()}, ?WIRE_ACK(for_old)),
        Ref = erlang:monitor(process, Old),
        exit(Old, kill),
        receive {'DOWN', Ref, process, Old, _} -> ok end,
        New = stepper(ls_target, fun(Token, Msg) -> Me ! {new, Msg}, toroco_lockstep:done(Token) end),
        Blocker ! release,
        ok = toroco_clock:settle(),
        %% quiescent: the queued step was handled (lost with the old one)
        receive {new, Stray} -> ct:fail({new_process_got, Stray}) after 0 -> ok end,
        ok = toroco_wire:send({ls_target, node()}, ?WIRE_ACK(for_new)),
        ok = toroco_clock:settle(),
        receive {new, Got} -> ?assertEqual(?WIRE_ACK(for_new), Got) after 0 -> ct:fail(no_step) end,
        exit(New, kill)
    after
        exit(Blocker, kill)
    end.

%%====================================================================
%% Helpers
%%====================================================================

%% A process registered as `Name' that hands every step to `Fun(Token, Msg)'.
stepper(Name, Fun) ->
    Me = self(),
    Pid = spawn(fun() ->
                        true = register(Name, self()),
                        Me ! {registered, self()},
                        step_loop(Fun)
                end),
    receive {registered, Pid} -> Pid after 5000 -> ct:fail({not_registered, Name}) end.

step_loop(Fun) ->
    receive ?WIRE_STEP(Token, Msg) -> Fun(Token, Msg) end,
    step_loop(Fun).

%% sensor s -> w1 -> ... -> wN -> actuator motors
chain(N) ->
    toroco_test_lib:sensor(s, [o]),
    toroco_test_lib:actuator(motors, [setvel]),
    Names = [list_to_atom("w" ++ integer_to_list(I)) || I <- lists:seq(1, N)],
    [ok = toroco:add_behavior(W, tb_work, #{}) || W <- Names],
    Sources = [{s, o} | [{W, out} || W <- lists:droplast(Names)]],
    [ok = toroco:set_inputs(W, #{in => [Src]}) || {W, Src} <- lists:zip(Names, Sources)],
    ok = toroco:set_inputs(motors, #{setvel => [{lists:last(Names), out}]}).

last(A) ->
    case toroco_fake_actuator:history(A) of
        [] -> none;
        H -> {_, V, T} = lists:last(H), {T, V}
    end.

burn() -> burn(0).
burn(N) -> burn(N + 1).

trace_terms_as_io_lib_writes_them() ->
    [{doc, "The trace writes values as io_lib's ~0tp does, character for character, for "
      "hand-picked terms and 2,000 generated ones: the trace's SHA-256 does not depend on "
      "how a line is built."}].
trace_terms_as_io_lib_writes_them(_Config) ->
    Same = fun(T) -> lists:flatten(io_lib:format("~ts", [toroco_lockstep:term(T)]))
                         =:= lists:flatten(io_lib:format("~0tp", [T])) end,
    Picked = [0, -5, 12345678901234567890, a, 'A b', '\x{e9}', {}, {{}}, {1, 2}, [], "abc",
              [1, 2], <<>>, <<"bin">>, 1.5, -0.0, #{a => 1}, {x, <<"\x{e9}"/utf8>>},
              {a, {b, [1, 2]}, "str", <<"bin">>, 1.5, #{k => {v}}}, {[], {}}],
    ?assertEqual([], [T || T <- Picked, not Same(T)]),
    ?assert(proper:quickcheck(proper:forall(proper_types:any(), Same),
                              [{numtests, 2000}, quiet])).
