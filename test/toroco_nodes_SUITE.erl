%% A robot spanning several nodes (SPEC §13): real nodes started with OTP's
%% `peer' on loopback, each running `toroco'; the cases spread emitters,
%% gates, routers and receivers over two or three of them.
-module(toroco_nodes_SUITE).
-import(toroco_test_lib, [wait_until/2, wait_until/3]).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

suite() -> [{timetrap, {seconds, 60}}].

all() ->
    [placement_and_names, top_and_watch_cover_nodes, suppression_across_nodes, inhibition_gate_on_third_node,
     hierarchy_uses_remote_layers, reset_from_another_node, remote_emitter_restart_caught_up,
     stale_source_dropped_and_back, stale_gate_default_max_age, node_killed_and_restarted, partition_heals_with_wiring_as_before,
     wiring_file_places_on_nodes, clash_after_partition_reported, over_tls,
     remote_behavior_shows_running_with_restarts, remote_events_bounded_and_counted,
     swallowed_sends_counted].

init_per_suite(Config) ->
    ok = toroco_test_lib:stop(),
    _ = os:cmd("epmd -daemon"),
    Started = case node() of
                  nonode@nohost ->
                      Name = list_to_atom("toroco_ct" ++ integer_to_list(erlang:unique_integer([positive]))
                                          ++ "@127.0.0.1"),
                      {ok, _} = net_kernel:start([Name, longnames]),
                      true;
                  _ -> false
              end,
    [{stop_dist, Started} | Config].

end_per_suite(Config) ->
    _ = ?config(stop_dist, Config) andalso net_kernel:stop(),
    ok.

init_per_testcase(_TC, Config) ->
    Config.

end_per_testcase(_TC, Config) ->
    _ = [catch peer:stop(P) || P <- peers_of(Config)],
    ok.

peers_of(Config) ->
    case ?config(peers, Config) of
        undefined -> [];
        Ps -> Ps
    end.

%%====================================================================
%% Nodes
%%====================================================================

%% Starts a peer on loopback with this node's code path and toroco running.
start_peer(Name) ->
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    {ok, Peer, Node} = peer:start_link(#{name => Name, host => "127.0.0.1", longnames => true,
                                         args => ["-setcookie", atom_to_list(erlang:get_cookie()),
                                                  "-connect_all", "false",
                                                  "-pa" | Paths]}),
    {ok, _} = erpc:call(Node, application, ensure_all_started, [toroco_hw]),
    {Peer, Node}.

peer_name(Tag) ->
    list_to_atom(atom_to_list(Tag) ++ integer_to_list(erlang:unique_integer([positive]))).

%% Three peers, connected to each other.
nodes3() ->
    [{PA, A}, {PB, B}, {PC, C}] = [start_peer(peer_name(T)) || T <- [a, b, c]],
    pong = erpc:call(A, net_adm, ping, [B]),
    pong = erpc:call(A, net_adm, ping, [C]),
    pong = erpc:call(B, net_adm, ping, [C]),
    await_peers([A, B, C]),
    {[PA, PB, PC], A, B, C}.

%% Until each node's wiring server knows the others'.
await_peers(Nodes) ->
    wait_until(fun() ->
                 lists:all(fun(N) -> erpc:call(N, toroco_wiring, peers, []) =:= lists:sort(Nodes) end,
                           Nodes)
         end, 5000).

t(Node, F, Args) -> erpc:call(Node, toroco, F, Args).

%% hi (latched `high') on A over lo (latched `low') on B, into act on B.
hi_over_lo(A, B, Input) ->
    sensor(A, hi),
    sensor(B, lo),
    ok = t(B, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(B, set_inputs, [act, #{in => Input}]),
    ok = t(B, inject, [{lo, out}, low, #{latch => true}]),
    ok = t(A, inject, [{hi, out}, high, #{latch => true}]),
    await_values(B, act, [low, high]).

%% act on B has had `low', then `high' from A: quiet for longer than the
%% max age, high stays (keep-alives); A frozen, `low' comes within Bound ms;
%% A thawed, `high' comes back.
frozen_let_go_within(A, B, Bound, What) ->
    ok = toroco_test_lib:stays(fun() -> values(B, act) end, [low, high], 700, {act, B}),
    OsPid = erpc:call(A, os, getpid, []),
    T0 = erpc:call(B, erlang, monotonic_time, [millisecond]),
    _ = os:cmd("kill -STOP " ++ OsPid),
    try
        await_values(B, act, [low, high, low]),
        [_, _, {in, low, T1}] = erpc:call(B, toroco_fake_actuator, history, [act]),
        ct:pal("~ts: let go ~b ms after the freeze", [What, T1 - T0]),
        true = T1 - T0 =< Bound
    after
        os:cmd("kill -CONT " ++ OsPid)
    end,
    await_values(B, act, [low, high, low, high]).

%% The wiring of a receiver's inputs as inspect shows it.
wiring_of(Node, R) ->
    maps:map(fun(_, #{sources := Srcs}) -> Srcs end, maps:get(inputs, t(Node, inspect, [R]))).

sensor(At, Name) ->
    ok = t(At, add_device, [Name, toroco_fake_sensor, #{outputs => [out]}]).

values(Node, A) ->
    [V || {_, V, _} <- erpc:call(Node, toroco_fake_actuator, history, [A])].

%% A look at `Receiver''s input `In' (on `Node') taken once `Pred' held of
%% an earlier one: for a `Pred' that stays true once it holds (a latch that
%% arrived), it holds of this one too.
wait_router(Node, Receiver, In, Pred) ->
    Look = fun() -> maps:get(In, maps:get(inputs, t(Node, inspect, [Receiver]))) end,
    wait_until(fun() -> Pred(Look()) end, 3000, {router, Receiver, In}),
    Look().

await_values(Node, A, Expected) ->
    wait_until(fun() -> values(Node, A) =:= Expected end, 3000, {expected, Expected}),
    ok.

%%====================================================================
%% Cases
%%====================================================================

placement_and_names() -> [{doc, "node => N places a thing there; names are unique across nodes; every call works from any node and inspect says where"}].
placement_and_names(Config) ->
    {Ps, A, B, C} = nodes3(),
    Config1 = [{peers, Ps} | Config],
    ok = t(A, add_device, [s, toroco_fake_sensor, #{outputs => [out], node => B}]),
    #{node := B, kind := device} = t(A, inspect, [s]),
    #{node := B} = t(B, inspect, [s]),
    {error, {name_taken, s, B}} = t(A, add_device, [s, toroco_fake_sensor, #{outputs => [out]}]),
    {error, {nodedown, 'nowhere@127.0.0.1'}} =
        t(A, add_device, [s2, toroco_fake_sensor, #{outputs => [out], node => 'nowhere@127.0.0.1'}]),
    ok = t(A, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    #{devices := [act, s], nodes := #{act := A, s := B}} = t(B, inspect, []),
    %% Wired from a third node, acted on where the receiver lives.
    ok = t(C, set_inputs, [act, #{in => [{s, out}]}]),
    ok = t(C, inject, [{s, out}, 7, #{latch => true}]),
    await_values(A, act, [7]),
    ok = t(C, remove_device, [s]),
    {error, {unknown_name, s}} = t(A, inspect, [s]),
    #{in := #{sources := []}} = maps:get(inputs, t(A, inspect, [act])),
    end_per_testcase(x, Config1).

suppression_across_nodes() -> [{doc, "holds, latches, suppression and idle across three nodes: the higher source's hold suppresses the lower, whose latch comes back when it ends"}].
suppression_across_nodes(Config) ->
    {Ps, A, B, C} = nodes3(),
    sensor(A, hi),
    sensor(B, lo),
    ok = t(C, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(C, set_inputs, [act, #{in => #{sources => [{hi, out}, {lo, out}], idle => stop}}]),
    ok = t(B, inject, [{lo, out}, 1, #{latch => true}]),
    await_values(C, act, [1]),
    ok = t(A, inject, [{hi, out}, 2, #{hold => 300}]),
    await_values(C, act, [1, 2]),
    ok = t(B, inject, [{lo, out}, 3, #{latch => true}]),
    %% suppressed while hi holds: one look at the router once lo's latch is
    %% there shows hi's hold and hi's value delivered, not lo's
    Router = wait_router(C, act, in, fun(#{latches := Ls}) -> lists:member({{lo, out}, 3}, Ls) end),
    case lists:keyfind({hi, out}, 1, maps:get(holds, Router)) of
        {_, Left} when is_integer(Left) ->
            ct:log("hi holds for ~b ms more; lo suppressed", [Left]),
            #{winner := {hi, out}, last := {value, 2}} = Router;
        false ->
            ct:log("hi's hold of 300 ms was over before lo's latch reached the router")
    end,
    await_values(C, act, [1, 2, 3]),              % the hold ends: lo's latch
    ok = t(A, inject, [{hi, out}, 4, #{latch => true}]),
    ok = t(B, inject, [{lo, out}, 5, #{}]),       % a send clears lo's latch
    ok = t(A, inject, [{hi, out}, 6, #{hold => 0}]),
    await_values(C, act, [1, 2, 3, 4, 6, stop]),
    end_per_testcase(x, [{peers, Ps} | Config]).

inhibition_gate_on_third_node() -> [{doc, "an output on node A inhibited by a source on node B (its gate on A) feeding a receiver on node C: silenced, then its latch re-enters"}].
inhibition_gate_on_third_node(Config) ->
    {Ps, A, B, C} = nodes3(),
    sensor(A, e),
    sensor(B, i),
    ok = t(C, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(C, set_inputs, [act, #{in => #{sources => [{e, out}], idle => stop}}]),
    ok = t(B, set_inhibitors, [e, #{out => [{i, out}]}]),
    #{outputs := #{out := #{inhibitors := [{i, out}], inhibited := false}}} = t(C, inspect, [e]),
    ok = t(A, inject, [{e, out}, go, #{latch => true}]),
    await_values(C, act, [go]),
    %% quiet past max_age, but the gate lives
    ok = toroco_test_lib:stays(fun() -> values(C, act) end, [go], 600, {act, C}),
    ok = t(B, inject, [{i, out}, on, #{latch => true}]),
    await_values(C, act, [go, stop]),
    #{outputs := #{out := #{inhibited := true}}} = t(B, inspect, [e]),
    ok = t(A, inject, [{e, out}, go2, #{latch => true}]),   % latched while inhibited
    ok = toroco_test_lib:stays(fun() -> values(C, act) end, [go, stop], 100, {act, C}),
    ok = t(B, inject, [{i, out}, off, #{hold => 0}]),       % a send clears i's latch
    await_values(C, act, [go, stop, go2]),
    end_per_testcase(x, [{peers, Ps} | Config]).

hierarchy_uses_remote_layers() -> [{doc, "wiring is refused when a source sits above one of a higher layer on another node, and an inhibitor of a lower layer on another node"}].
hierarchy_uses_remote_layers(Config) ->
    {Ps, A, B, C} = nodes3(),
    ok = t(A, add_behavior, [high, tb_relay, #{layer => 2}]),
    ok = t(B, add_behavior, [low, tb_relay, #{layer => 1}]),
    ok = t(C, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    {error, {hierarchy, _}} = t(C, set_inputs, [act, #{in => [{low, out}, {high, out}]}]),
    ok = t(C, set_inputs, [act, #{in => [{high, out}, {low, out}]}]),
    {error, {hierarchy, _}} = t(C, set_inhibitors, [high, #{out => [{low, out}]}]),
    end_per_testcase(x, [{peers, Ps} | Config]).

reset_from_another_node() -> [{doc, "a reset source on another node restarts the behavior from init/1, clearing its latch"}].
reset_from_another_node(Config) ->
    {Ps, A, B, _C} = nodes3(),
    sensor(A, kick),
    ok = t(B, add_behavior, [r, tb_relay, #{layer => 1, params => #{latch => fresh}}]),
    sensor(A, feed),
    ok = t(B, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(B, set_inputs, [r, #{in => [{feed, out}]}]),
    ok = t(B, set_inputs, [act, #{in => [{r, out}]}]),
    await_values(B, act, [fresh]),
    ok = t(A, inject, [{feed, out}, {set, other}, #{}]),
    await_values(B, act, [fresh, other]),
    ok = t(A, set_reset, [r, [{kick, out}]]),
    ok = t(A, inject, [{kick, out}, now, #{}]),
    await_values(B, act, [fresh, other, fresh]),
    end_per_testcase(x, [{peers, Ps} | Config]).

remote_emitter_restart_caught_up() -> [{doc, "a remote emitter that crashes ends its holds at once, and its new incarnation is heard again (the router subscribes again)"}].
remote_emitter_restart_caught_up(Config) ->
    {Ps, A, B, _C} = nodes3(),
    hi_over_lo(A, B, [{hi, out}, {lo, out}]),
    Old = erpc:call(A, erlang, whereis, [toroco_names:process(hi)]),
    true = erpc:call(A, erlang, exit, [Old, kill]),
    await_values(B, act, [low, high, low]),
    wait_until(fun() -> case erpc:call(A, erlang, whereis, [toroco_names:process(hi)]) of
                      P when is_pid(P) -> P =/= Old;
                      _ -> false
                  end
         end, 3000),
    ok = t(A, inject, [{hi, out}, again, #{latch => true}]),
    await_values(B, act, [low, high, low, again]),
    end_per_testcase(x, [{peers, Ps} | Config]).

remote_behavior_shows_running_with_restarts() ->
    [{doc, "a behavior on another node is running in inspect/1 and on the dashboard's page "
      "state, with its restarts, and toroco:restart_behavior/1 from here restarts it there"}].
remote_behavior_shows_running_with_restarts(Config) ->
    {Ps, A, B, _C} = nodes3(),
    ok = t(A, add_behavior, [far, tb_relay, #{layer => 1, node => B}]),
    #{status := running, node := B, restarts := 0, process := #{state := relaying}} =
        t(A, inspect, [far]),
    ok = t(A, restart_behavior, [far]),
    #{status := running, restarts := 1} = t(A, inspect, [far]),
    %% the dashboard's reading of it, on the node where it does not run
    {_, Readings} = erpc:call(A, toroco_live_state, readings, []),
    [#{restarts := 1, state := {value, relaying}, info := #{status := running}}] =
        [R || R = #{name := far} <- Readings],
    end_per_testcase(x, [{peers, Ps} | Config]).

stale_source_dropped_and_back() -> [{doc, "a frozen node's latched source is let go within max_age + 50 ms (the lower source takes over) and comes back when the node thaws; a quiet live one is kept"}].
stale_source_dropped_and_back(Config) ->
    {Ps, A, B, _C} = nodes3(),
    hi_over_lo(A, B, [{hi, out, #{max_age => 200}}, {lo, out}]),
    frozen_let_go_within(A, B, 250, "max_age 200"),
    end_per_testcase(x, [{peers, Ps} | Config]).

node_killed_and_restarted() -> [{doc, "a node that dies lets the lower layers take over at once; restarted with its part, the wiring is as before and its latch is delivered again"}].
node_killed_and_restarted(Config) ->
    {[PA | Ps], A, B, _C} = nodes3(),
    hi_over_lo(A, B, #{sources => [{hi, out}, {lo, out}], idle => stop}),
    Before = wiring_of(B, act),
    peer:stop(PA),
    await_values(B, act, [low, high, low]),
    #{in := #{sources := [{hi, out}, {lo, out}]}} = maps:get(inputs, t(B, inspect, [act])),
    %% The same node again, running its part.
    [_, Host] = string:split(atom_to_list(A), "@"),
    {PA2, A} = start_peer(list_to_atom(hd(string:split(atom_to_list(A), "@")))),
    "127.0.0.1" = Host,
    pong = erpc:call(A, net_adm, ping, [B]),
    sensor(A, hi),
    ok = t(A, inject, [{hi, out}, high, #{latch => true}]),
    await_values(B, act, [low, high, low, high]),
    Before = wiring_of(B, act),
    end_per_testcase(x, [{peers, [PA2 | Ps]} | Config]).

clash_after_partition_reported() -> [{doc, "a name added on both sides of a partition is reported when the nodes meet again, not merged"}].
clash_after_partition_reported(Config) ->
    {Ps, A, B, C} = nodes3(),
    %% Only A and B: the test node and C would carry the partition over.
    _ = [true = erpc:call(X, erlang, disconnect_node, [C]) || X <- [A, B]],
    true = erpc:call(A, erlang, disconnect_node, [B]),
    wait_until(fun() -> erpc:call(A, toroco_wiring, peers, []) =:= [A] end, 3000),
    sensor(A, twin),
    sensor(B, twin),
    pong = erpc:call(A, net_adm, ping, [B]),
    wait_until(fun() -> maps:get(name_clashes, t(A, inspect, []), []) =/= [] end, 3000),
    #{name_clashes := Clashes} = t(B, inspect, []),
    true = lists:member({twin, A}, Clashes) orelse lists:member({twin, B}, Clashes),
    %% Resolved by removing one side's: no longer listed.
    ok = t(B, remove_device, [twin]),
    wait_until(fun() -> maps:get(name_clashes, t(A, inspect, []), []) =:= [] end, 3000),
    end_per_testcase(x, [{peers, Ps} | Config]).

top_and_watch_cover_nodes() -> [{doc, "top on one node lists the whole robot with the node of each thing; the observer tap hears other nodes; watch/2 of a receiver on another node prints here"}].
top_and_watch_cover_nodes(Config) ->
    {Ps, A, B, _C} = nodes3(),
    sensor(A, s),
    ok = t(B, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(A, set_inputs, [act, #{in => [{s, out}]}]),
    Top = lists:flatten(io_lib:format("~ts", [erpc:call(A, toroco_top, iodata, [])])),
    [_ | _] = [L || L <- string:split(Top, "\n", all), string:find(L, "act") =/= nomatch,
                    string:find(L, atom_to_list(B)) =/= nomatch],
    [_ | _] = [L || L <- string:split(Top, "\n", all), string:find(L, "ON") =/= nomatch],
    %% The tap on A hears B's deliveries too.
    Me = self(),
    Sub = erpc:call(A, erlang, spawn,
                    [fun() ->
                             {ok, Ref} = toroco:subscribe_events(#{kinds => [deliver]}),
                             Me ! {subscribed, self()},
                             receive {toroco_event, Ref, Ev} -> Me ! {tapped, Ev} end,
                             receive stop -> toroco:unsubscribe_events(Ref) end
                     end]),
    receive {subscribed, Sub} -> ok after 5000 -> ct:fail(no_subscription) end,
    ok = t(A, inject, [{s, out}, 41, #{}]),
    receive {tapped, {deliver, _, {act, in}, 41}} -> ok after 3000 -> ct:fail(not_tapped) end,
    Sub ! stop,
    Io = capture(),
    ok = t(A, watch, [act, #{max => 1, io => Io, notify => self()}]),
    ok = t(A, inject, [{s, out}, 42, #{}]),
    receive {toroco_watch, stopped, {max, 1}} -> ok after 3000 -> ct:fail(no_watch) end,
    Io ! {get, self()},
    receive {Io, Out} -> true = nomatch =/= string:find(Out, "act.in <- 42") after 1000 -> ct:fail(no_output) end,
    end_per_testcase(x, [{peers, Ps} | Config]).

remote_events_bounded_and_counted() -> [{doc, "A subscriber that does not read keeps at most about `buffer' of another node's events too; each is received, in order, or counted in {dropped, N}"}].
remote_events_bounded_and_counted(Config) ->
    [{PA, A}, {PB, B}] = [start_peer(peer_name(T)) || T <- [a, b]],
    pong = erpc:call(A, net_adm, ping, [B]),
    await_peers([A, B]),
    sensor(B, s),
    Me = self(),
    N = 1000,
    Buffer = 50,
    Sub = erpc:call(A, erlang, spawn,
                    [fun() ->
                             {ok, Ref} = toroco:subscribe_events(#{kinds => [emit], names => [s],
                                                                   buffer => Buffer}),
                             Me ! {subscribed, self()},
                             receive read -> ok end,
                             Me ! {counted, self(), remote_count(Ref, N, 0, 0, [])}
                     end]),
    receive {subscribed, Sub} -> ok after 5000 -> ct:fail(no_subscription) end,
    [ok = t(B, inject, [{s, out}, I, #{}]) || I <- lists:seq(1, N)],
    wait_until(fun() -> queue_len(A, Sub) > 0 end, 3000),
    true = queue_len(A, Sub) =< Buffer + 1,
    Sub ! read,
    receive {counted, Sub, {Received, Dropped, Seq}} ->
            ct:pal("received ~b, dropped ~b of ~b (buffer ~b)", [Received, Dropped, N, Buffer]),
            N = Received + Dropped,
            true = Dropped > 0,
            Seq = lists:sort(Seq)
    after 10000 -> ct:fail(no_count)
    end,
    end_per_testcase(x, [{peers, [PA, PB]} | Config]).

queue_len(Node, Pid) ->
    {message_queue_len, L} = erpc:call(Node, erlang, process_info, [Pid, message_queue_len]),
    L.

remote_count(_Ref, N, R, D, Seq) when R + D >= N ->
    {R, D, lists:reverse(Seq)};
remote_count(Ref, N, R, D, Seq) ->
    receive
        {toroco_event, Ref, {dropped, K}} -> remote_count(Ref, N, R, D + K, Seq);
        {toroco_event, Ref, {emit, _, _, send, I}} -> remote_count(Ref, N, R + 1, D, [I | Seq])
    after 3000 -> {R, D, lists:reverse(Seq)}
    end.

capture() ->
    spawn(fun() -> capture([]) end).

capture(Acc) ->
    receive
        {io_request, From, Ref, {put_chars, _Enc, Chars}} ->
            From ! {io_reply, Ref, ok},
            capture([Acc, Chars]);
        {io_request, From, Ref, {put_chars, _Enc, M, F, Args}} ->
            From ! {io_reply, Ref, ok},
            capture([Acc, apply(M, F, Args)]);
        {io_request, From, Ref, _} ->
            From ! {io_reply, Ref, ok},
            capture(Acc);
        {get, Pid} ->
            Pid ! {self(), unicode:characters_to_list(Acc)},
            capture(Acc)
    end.

partition_heals_with_wiring_as_before() -> [{doc, "a partition wedges nothing: each side runs on, the board side takes over at once; when the nodes meet again the wiring is as it was and the remote latch is delivered again"}].
partition_heals_with_wiring_as_before(Config) ->
    {Ps, A, B, C} = nodes3(),
    sensor(A, laptop),
    sensor(B, board),
    ok = t(B, add_device, [motors, toroco_fake_actuator, #{inputs => [setvel]}]),
    ok = t(A, add_device, [screen, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(B, set_inputs, [motors, #{setvel => #{sources => [{laptop, out}, {board, out}],
                                                 idle => {0, 0}}}]),
    ok = t(A, set_inputs, [screen, #{in => [{laptop, out}]}]),
    ok = t(B, inject, [{board, out}, wander, #{latch => true}]),
    ok = t(A, inject, [{laptop, out}, follow_red, #{latch => true}]),
    await_values(B, motors, [wander, follow_red]),
    Before = wiring_of(B, motors),
    T0 = erpc:call(B, erlang, monotonic_time, [millisecond]),
    %% The partition: only A and B, the test node keeps talking to both.
    _ = [true = erpc:call(X, erlang, disconnect_node, [C]) || X <- [A, B]],
    true = erpc:call(A, erlang, disconnect_node, [B]),
    await_values(B, motors, [wander, follow_red, wander]),
    %% Each side keeps running its own behaviors.
    ok = t(A, inject, [{laptop, out}, follow_red2, #{latch => true}]),
    await_values(A, screen, [follow_red, follow_red2]),
    ok = t(B, inject, [{board, out}, wander2, #{latch => true}]),
    await_values(B, motors, [wander, follow_red, wander, wander2]),
    pong = erpc:call(A, net_adm, ping, [B]),
    await_values(B, motors, [wander, follow_red, wander, wander2, follow_red2]),
    Before = wiring_of(B, motors),
    History = erpc:call(B, toroco_fake_actuator, history, [motors]),
    ct:pal("board motors: ~p", [[{V, T - T0} || {_, V, T} <- History]]),
    end_per_testcase(x, [{peers, Ps} | Config]).

wiring_file_places_on_nodes() -> [{doc, "a wiring file with node options, loaded on one node, places things on others and wires them where they live"}].
wiring_file_places_on_nodes(Config) ->
    {Ps, A, B, _C} = nodes3(),
    File = filename:join(?config(priv_dir, Config), "split.wiring"),
    Terms = [{device, far, toroco_fake_sensor, #{outputs => [out], node => A}},
             {device, near, toroco_fake_sensor, #{outputs => [out], node => B}},
             {device, act, toroco_fake_actuator, #{inputs => [in], node => B}},
             {inputs, act, #{in => [{far, out}, {near, out}]}}],
    ok = file:write_file(File, [io_lib:format("~p.~n", [T]) || T <- Terms]),
    ok = t(A, load_wiring, [File]),
    #{nodes := #{far := A, near := B, act := B}} = t(A, inspect, []),
    ok = t(A, inject, [{far, out}, 1, #{latch => true}]),
    await_values(B, act, [1]),
    end_per_testcase(x, [{peers, Ps} | Config]).

over_tls() -> [{doc, "the two-node suppression case with distribution over TLS (inet_tls_dist), certificates made by scripts/dist-certs"}].
over_tls(Config) ->
    Script = filename:join(repo_root(), "scripts/dist-certs"),
    Dir = filename:join(?config(priv_dir, Config), "certs"),
    Conf = lists:last(string:split(string:trim(os:cmd(Script ++ " " ++ Dir)), "\n", all)),
    true = filelib:is_regular(Conf),
    Paths = [P || P <- code:get_path(), string:find(P, "_build") =/= nomatch],
    Start = fun(Tag) ->
                    {ok, P, N} = peer:start_link(
                                   #{name => peer_name(Tag), host => "127.0.0.1", longnames => true,
                                     connection => standard_io,
                                     args => ["-proto_dist", "inet_tls", "-ssl_dist_optfile", Conf,
                                              "-setcookie", "toroco_tls_test", "-connect_all", "false",
                                              "-pa" | Paths]}),
                    {ok, _} = peer:call(P, application, ensure_all_started, [toroco_hw]),
                    {P, N}
            end,
    {PA, A} = Start(tla),
    {PB, B} = Start(tlb),
    Config1 = [{peers, [PA, PB]} | Config],
    pong = peer:call(PA, net_adm, ping, [B]),
    [{B, _}] = peer:call(PA, erlang, system_info, [dist_ctrl]),
    {ok, [["inet_tls"]]} = peer:call(PA, init, get_argument, [proto_dist]),
    T = fun(P, F, Args) -> peer:call(P, toroco, F, Args) end,
    wait_until(fun() -> peer:call(PA, toroco_wiring, peers, []) =:= lists:sort([A, B]) end, 5000),
    ok = T(PA, add_device, [hi, toroco_fake_sensor, #{outputs => [out]}]),
    ok = T(PB, add_device, [lo, toroco_fake_sensor, #{outputs => [out]}]),
    ok = T(PB, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = T(PA, set_inputs, [act, #{in => [{hi, out}, {lo, out}]}]),
    ok = T(PB, inject, [{lo, out}, 1, #{latch => true}]),
    ok = T(PA, inject, [{hi, out}, 2, #{hold => 300}]),
    ok = T(PB, inject, [{lo, out}, 3, #{latch => true}]),
    Values = fun() -> [V || {_, V, _} <- peer:call(PB, toroco_fake_actuator, history, [act])] end,
    wait_until(fun() -> Values() =:= [1, 2, 3] end, 3000, {tls, Values()}),
    end_per_testcase(x, Config1).

repo_root() ->
    up(filename:dirname(code:which(?MODULE))).

up("/") -> ct:fail(no_repo_root);
up(Dir) ->
    case filelib:is_regular(filename:join(Dir, "scripts/dist-certs")) of
        true -> Dir;
        false -> up(filename:dirname(Dir))
    end.

stale_gate_default_max_age() -> [{doc, "a gated output whose gate's node freezes is let go after remote_max_age_ms (default 300) + 50 ms, its quiet latch kept alive before, and back on thaw"}].
stale_gate_default_max_age(Config) ->
    {Ps, A, B, C} = nodes3(),
    sensor(A, e),
    sensor(C, i),
    sensor(B, lo),
    ok = t(B, add_device, [act, toroco_fake_actuator, #{inputs => [in]}]),
    ok = t(A, set_inhibitors, [e, #{out => [{i, out}]}]),
    ok = t(B, set_inputs, [act, #{in => [{e, out}, {lo, out}]}]),
    ok = t(B, inject, [{lo, out}, low, #{latch => true}]),
    ok = t(A, inject, [{e, out}, high, #{latch => true}]),
    await_values(B, act, [low, high]),
    frozen_let_go_within(A, B, 350, "gated, default max age 300"),
    end_per_testcase(x, [{peers, Ps} | Config]).

swallowed_sends_counted() ->
    [{doc, "An event sent to a node whose connection is not up (or is congested) is swallowed, "
      "as a cut wire would; it is counted, logged, and top says how many"}].
swallowed_sends_counted(_Config) ->
    ok = toroco_test_lib:start(),
    try
        #{not_connected := Before} = toroco_wire:swallowed(),
        Ghost = list_to_atom("ghost" ++ integer_to_list(erlang:unique_integer([positive])) ++ "@127.0.0.1"),
        [ok = toroco_wire:send({toroco_router_x, Ghost}, {event, I}) || I <- lists:seq(1, 3)],
        #{not_connected := After} = toroco_wire:swallowed(),
        3 = After - Before,
        Top = unicode:characters_to_list(toroco_top:iodata()),
        true = string:find(Top, "swallowed  ") =/= nomatch
    after
        toroco_test_lib:stop()
    end.
