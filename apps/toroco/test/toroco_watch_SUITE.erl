%% Live inspection from a shell (SPEC §6, §9): the bounded trace of
%% toroco:watch/2, the toroco:top() table and the wiring picture; and the
%% simulated world's snapshots as the runtime hands them on (SPEC §10).
-module(toroco_watch_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [sensor/2, actuator/2, await_values/2, wait_until/2]).

suite() -> [{timetrap, {seconds, 30}}].

all() -> [{group, watch}, {group, top}, {group, picture}, {group, world}].

groups() ->
    [{watch, [], [stops_by_itself_at_max, stops_by_itself_at_rate, stops_by_itself_after_seconds,
                  watches_one_input, unwatch_stops_and_untraces, follows_a_restart,
                  stops_when_its_shell_goes, refuses_bad_requests]},
     {top, [], [top_shows_the_whole_network, top_counts_restarts]},
     {picture, [], [dot_draws_suppression_and_inhibition, wiring_svg_through_graphviz]},
     {world, [], [world_snapshot_to_each_subscriber_once, world_snapshot_made_only_for_a_subscriber,
                  world_subscriber_that_dies_is_unsubscribed,
                  world_subscription_down_with_the_runtime]}].

init_per_testcase(_TC, Config) ->
    toroco_test_lib:start(),
    sensor(s, [v, w]),
    ok = toroco:add_behavior(b, tb_relay, #{layer => 1}),
    ok = toroco:set_inputs(b, #{in => [{s, v}], in2 => [{s, w}]}),
    Config.

end_per_testcase(_TC, _Config) ->
    toroco:unwatch(),
    toroco_test_lib:stop().

%%====================================================================
%% watch
%%====================================================================

stops_by_itself_at_max() ->
    [{doc, "A watch prints `max' deliveries, then stops by itself, says so and unsubscribes."}].
stops_by_itself_at_max(_Config) ->
    Io = capture(),
    ok = toroco:watch(b, #{max => 5, rate => 1000, io => Io, notify => self()}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 20)],
    {max, 5} = stopped(),
    Lines = lines(Io),
    ["b.in <- 1", "b.in <- 2", "b.in <- 3", "b.in <- 4", "b.in <- 5"] = deliveries(Lines),
    "watch stopped: max after 5 deliveries" = lists:last(Lines),
    untraced(b).

stops_by_itself_at_rate() ->
    [{doc, "A flood of more than `rate' deliveries within a second stops the watch instead of "
           "being printed."}].
stops_by_itself_at_rate(_Config) ->
    Io = capture(),
    ok = toroco:watch(b, #{rate => 10, io => Io, notify => self()}),
    [ok = toroco:inject({s, v}, I) || I <- lists:seq(1, 100)],
    {rate, 10} = stopped(),
    10 = length(deliveries(lines(Io))),
    untraced(b).

stops_by_itself_after_seconds() ->
    [{doc, "A watch with nothing to print stops after `seconds'."}].
stops_by_itself_after_seconds(_Config) ->
    Io = capture(),
    T0 = erlang:monotonic_time(millisecond),
    ok = toroco:watch(b, #{seconds => 0.3, io => Io, notify => self()}),
    {seconds, 0} = stopped(),
    Took = erlang:monotonic_time(millisecond) - T0,
    true = Took >= 300 andalso Took < 2000,
    ["watch stopped: seconds after 0 deliveries"] = lines(Io),
    untraced(b).

watches_one_input() ->
    [{doc, "Watching {Receiver, Input} prints that input's deliveries and no other's."}].
watches_one_input(_Config) ->
    Io = capture(),
    ok = toroco:watch({b, in2}, #{max => 2, io => Io, notify => self()}),
    ok = toroco:inject({s, v}, skipped),
    ok = toroco:inject({s, w}, {x, 1}),
    ok = toroco:inject({s, v}, skipped),
    ok = toroco:inject({s, w}, "two"),
    {max, 2} = stopped(),
    ["b.in2 <- {x,1}", "b.in2 <- \"two\""] = deliveries(lines(Io)).

unwatch_stops_and_untraces() ->
    [{doc, "unwatch stops the running watch, which reports it; a new watch replaces the old."}].
unwatch_stops_and_untraces(_Config) ->
    Io = capture(),
    ok = toroco:watch(b, #{io => Io, notify => self()}),
    ok = toroco:watch(b, #{io => Io, notify => self()}),
    {unwatch, 0} = stopped(),
    ok = toroco:inject({s, v}, 1),
    wait_until(fun() -> deliveries(lines(Io)) =:= ["b.in <- 1"] end, 2000),
    ok = toroco:unwatch(),
    {unwatch, 1} = stopped(),
    undefined = whereis(toroco_watch),
    untraced(b),
    ok = toroco:unwatch().

follows_a_restart() ->
    [{doc, "A watched behavior that crashes and is restarted is watched on, and says so."}].
follows_a_restart(_Config) ->
    Io = capture(),
    ok = toroco:watch(b, #{max => 2, io => Io, notify => self()}),
    Old = whereis(toroco_names:process(b)),
    ok = toroco:inject({s, v}, crash),
    wait_until(fun() -> lists:member("watch: b is back", lines(Io)) end, 3000),
    true = whereis(toroco_names:process(b)) =/= Old,
    ok = toroco:inject({s, v}, after_restart),
    {max, 2} = stopped(),
    ["b.in <- crash", "b.in <- after_restart"] = deliveries(lines(Io)).

stops_when_its_shell_goes() ->
    [{doc, "A watch whose output device dies (a remote shell that went away) stops and unsubscribes."}].
stops_when_its_shell_goes(_Config) ->
    Io = capture(),
    ok = toroco:watch(b, #{io => Io, notify => self()}),
    exit(Io, kill),
    {io_gone, 0} = stopped(),
    untraced(b).

refuses_bad_requests() ->
    [{doc, "Unknown names and inputs and bad options are refused with a reason naming them."}].
refuses_bad_requests(_Config) ->
    {error, {unknown_name, nobody}} = toroco:watch(nobody, #{}),
    {error, {unknown_input, {b, out}}} = toroco:watch({b, out}, #{}),
    {error, {bad_watch, "b"}} = toroco:watch("b", #{}),
    {error, {bad_option, {max, 0}}} = toroco:watch(b, #{max => 0}),
    {error, {bad_option, {rate, fast}}} = toroco:watch(b, #{rate => fast}),
    {error, {bad_option, {colour, red}}} = toroco:watch(b, #{colour => red}),
    undefined = whereis(toroco_watch).

%%====================================================================
%% top
%%====================================================================

top_shows_the_whole_network() ->
    [{doc, "top lists layers, every node with kind, layer, status, callback state and queue, "
           "each wired input with winner, holds, latches and last value, the inhibited outputs "
           "and the device counters."}].
top_shows_the_whole_network(_Config) ->
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0, params => #{latch => fwd}}),
    ok = toroco:add_behavior(inh, tb_relay, #{layer => 2}),
    actuator(a, [in]),
    ok = toroco:set_inputs(a, #{in => [{b, out}, {lo, out}]}),
    ok = toroco:set_inhibitors(lo, #{out2 => [{inh, out}]}),
    ok = toroco:inject({inh, out}, on, #{latch => true}),
    ok = toroco:inject({s, v}, {hold, stop, 60000}),
    await_values(a, [fwd, stop]),
    ok = toroco:suspend_behavior(inh),
    Text = unicode:characters_to_list(toroco_top:iodata()),
    ct:pal("~ts", [Text]),
    Lines = string:split(Text, "\n", all),
    ["toroco top" ++ _, "layers     2: inh  1: b  0: lo", "taken out  none", "" | _] = Lines,
    ["NODE", "KIND", "LAYER", "STATUS", "STATE", "QUEUE", "RESTARTS", "MODULE"] = row(Lines, "^NODE "),
    ["inh", "behavior", "2", "suspended", "relaying", "0", "0", "tb_relay"] = row(Lines, "^inh "),
    ["b", "behavior", "1", "running", "relaying", "0", "0", "tb_relay"] = row(Lines, "^b "),
    ["s", "device", "0", "running", _, "0", "0", "toroco_fake_sensor"] = row(Lines, "^s .* device "),
    %% Behaviors from the top layer down, then devices.
    ["inh", "b", "lo", "a", "s"] =
        [hd(string:lexemes(L, " ")) || L <- Lines, re:run(L, " (behavior|device) ") =/= nomatch],
    ["INPUT", "WINNER", "HOLDS", "(ms", "left)", "LATCHED", "LAST"] = row(Lines, "^INPUT "),
    %% b's send holds 60 s; lo's latch holds until unset.
    %% One line per holding or latched source, in priority order.
    {["a.in", "b.out", "b.out=" ++ Ms, "lo.out=fwd", "stop"], [Next | _]} =
        row_and_next(Lines, "^a\\.in "),
    true = list_to_integer(Ms) > 50000,
    ["lo.out=inf"] = string:lexemes(Next, " "),
    ["b.in", "-", "-", "-", "{hold,stop,60000}"] = row(Lines, "^b\\.in "),
    ["b.in2", "-", "-", "-", "-"] = row(Lines, "^b\\.in2 "),
    ["INHIBITED", "OUTPUT", "BY", "LATCH"] = row(Lines, "^INHIBITED "),
    ["lo.out2", "inh.out", "-"] = row(Lines, "^lo\\.out2 "),
    ["a", "deliveries=2", "waiters=0"] = row(Lines, "^a +deliveries="),
    ["s", "script_steps_done=0", "script_steps_left=0"] = row(Lines, "^s +script").

%% The cells of the one line matching Re, and the lines after it.
row_and_next(Lines, Re) ->
    Cells = row(Lines, Re),
    {Cells, tl(lists:dropwhile(fun(L) -> re:run(L, Re, [{capture, none}]) =/= match end, Lines))}.

%% The cells of the one line matching Re.
row(Lines, Re) ->
    case [L || L <- Lines, re:run(L, Re, [{capture, none}]) =:= match] of
        [L] -> string:lexemes(L, " ");
        Other -> ct:fail({Re, matched, Other})
    end.

top_counts_restarts() ->
    [{doc, "The RESTARTS column counts the restarts of each behavior by its supervisor."}].
top_counts_restarts(_Config) ->
    Before = toroco_restarts:count(b),
    [begin
         Pid = whereis(toroco_names:process(b)),
         ok = toroco:inject({s, v}, crash),
         wait_until(fun() -> not lists:member(whereis(toroco_names:process(b)), [undefined, Pid]) end,
                    3000)
     end || _ <- [1, 2]],
    Expected = integer_to_list(Before + 2),
    Text = unicode:characters_to_list(toroco_top:iodata()),
    ["b", "behavior", "1", "running", "relaying", "0", Expected, "tb_relay"] =
        row(string:split(Text, "\n", all), "^b "),
    0 = toroco_restarts:count(s).

%%====================================================================
%% The wiring picture
%%====================================================================

dot_draws_suppression_and_inhibition() ->
    [{doc, "wiring_dot draws nodes with input and output ports, a suppressor node numbering the "
           "sources of an input by priority, an inhibitor node on an inhibited output with a "
           "dashed wire from its inhibitor, and a dotted reset wire."}].
dot_draws_suppression_and_inhibition(_Config) ->
    wire_example(),
    Dot = unicode:characters_to_list(toroco:wiring_dot()),
    ct:pal("~ts", [Dot]),
    Has = fun(Re) -> match = re:run(Dot, Re, [{capture, none}, unicode]) end,
    Has("\"b\" \\[shape=plaintext, label=<<TABLE.*PORT=\"in_in\".*PORT=\"out_out\""),
    Has("\"S:a/in\" \\[shape=circle, label=\"S\""),
    Has("\"b\":out_out:e -> \"S:a/in\" \\[color=blue3, label=\"1\"\\]"),
    Has("\"lo\":out_out:e -> \"S:a/in\" \\[color=blue3, label=\"2 h 500\"\\]"),
    Has("\"S:a/in\" -> \"a\":in_in:w"),
    Has("\"I:lo/out2\" \\[shape=circle, label=\"I\""),
    Has("\"lo\":out_out2:e -> \"I:lo/out2\" \\[arrowhead=none"),
    Has("\"b\":out_out2:e -> \"I:lo/out2\" \\[style=dashed, color=red3, arrowhead=tee\\]"),
    Has("\"I:lo/out2\" -> \"a\":in_in2:w"),
    Has("\"s\":out_w:e -> \"lo\":name:n \\[style=dotted, label=\"reset\"\\]"),
    Has("\"s\" \\[shape=plaintext, label=<<TABLE[^\n]*style=\"rounded\"").

wiring_svg_through_graphviz(Config) ->
    case os:find_executable("dot") of
        false ->
            {skip, "Graphviz dot is not installed (apt-get install graphviz)"};
        _ ->
            wire_example(),
            Svg = filename:join(?config(priv_dir, Config), "wiring.svg"),
            ok = toroco_ops:wiring_svg(Svg),
            {ok, Bin} = file:read_file(Svg),
            {match, _} = re:run(Bin, "<svg"),
            [{match, _} = re:run(Bin, ">" ++ atom_to_list(N) ++ "<") || N <- [a, b, lo, s]],
            {error, {dot_failed, _, _}} = toroco_ops:render("digraph {", svg, Svg),
            ok
    end.

wire_example() ->
    ok = toroco:add_behavior(lo, tb_relay, #{layer => 0}),
    actuator(a, [in, in2]),
    ok = toroco:set_inputs(a, #{in => [{b, out}, {lo, out, #{hold => 500}}], in2 => [{lo, out2}]}),
    ok = toroco:set_inhibitors(lo, #{out2 => [{b, out2}]}),
    ok = toroco:set_reset(lo, [{s, w}]).

%%====================================================================
%% Helpers
%%====================================================================

stopped() ->
    receive {toroco_watch, stopped, Why} -> Why
    after 5000 -> ct:fail(watch_did_not_stop)
    end.

%% A watch that stopped leaves no subscription to the tap, and nothing on
%% the receiver.
untraced(Name) ->
    [] = toroco_tap:current(),
    {flags, []} = erlang:trace_info(whereis(toroco_names:process(Name)), flags),
    ok.

%% The delivery lines of a watch, without their time stamps.
deliveries(Lines) ->
    [Rest || L <- Lines, {match, [Rest]} <- [re:run(L, "^ *[0-9.]+ s  (.*)$",
                                                    [{capture, all_but_first, list}, unicode])]].

lines(Io) ->
    Io ! {get, self()},
    receive {Io, Text} -> [L || L <- string:split(Text, "\n", all), L =/= ""]
    after 2000 -> ct:fail(no_capture)
    end.

%% An io device that keeps what is written to it.
capture() ->
    spawn(fun() -> capture([]) end).

capture(Acc) ->
    receive
        {io_request, From, Ref, Req} ->
            From ! {io_reply, Ref, ok},
            capture([Acc, chars(Req)]);
        {get, Pid} ->
            Pid ! {self(), unicode:characters_to_list(Acc)},
            capture(Acc)
    end.

chars({put_chars, _Enc, Chars}) -> Chars;
chars({put_chars, _Enc, M, F, A}) -> apply(M, F, A);
chars(_) -> [].

%%====================================================================
%% world
%%====================================================================

world_snapshot_to_each_subscriber_once() ->
    [{doc, "A published snapshot reaches each subscriber once (subscribing twice is once), "
      "and none after it unsubscribed."}].
world_snapshot_to_each_subscriber_once(_Config) ->
    Snap = #{run => r, t_ms => 10, robots => []},
    Self = self(),
    Other = spawn_link(fun() ->
                               {ok, _} = toroco:subscribe_world(),
                               Self ! subscribed,
                               receive {toroco_world, S} -> Self ! {other, S} end
                       end),
    receive subscribed -> ok after 5000 -> ct:fail(other_not_subscribed) end,
    {ok, Ref1} = toroco:subscribe_world(),
    {ok, Ref2} = toroco:subscribe_world(),
    ok = toroco:publish_world(Snap),
    [Snap] = world_messages(),
    receive {other, Snap} -> ok after 5000 -> ct:fail({no_snapshot, Other}) end,
    ok = toroco:unsubscribe_world(Ref1),
    ok = toroco:publish_world(Snap#{t_ms := 20}),
    [] = world_messages(),
    ok = toroco:unsubscribe_world(Ref2).

world_snapshot_made_only_for_a_subscriber() ->
    [{doc, "Given a fun, publish_world/1 calls it only when someone subscribed: a world with "
      "nobody watching makes no snapshot."}].
world_snapshot_made_only_for_a_subscriber(_Config) ->
    Self = self(),
    Make = fun() -> Self ! made, #{run => r, t_ms => 0} end,
    ok = toroco:publish_world(Make),
    receive made -> ct:fail(made_without_subscriber) after 0 -> ok end,
    {ok, Ref} = toroco:subscribe_world(),
    ok = toroco:publish_world(Make),
    receive made -> ok after 0 -> ct:fail(not_made) end,
    [#{t_ms := 0}] = world_messages(),
    ok = toroco:unsubscribe_world(Ref).

world_subscriber_that_dies_is_unsubscribed() ->
    [{doc, "A subscriber that dies is unsubscribed: the snapshot is no longer made for it."}].
world_subscriber_that_dies_is_unsubscribed(_Config) ->
    Self = self(),
    {Pid, MRef} = spawn_monitor(fun() -> {ok, _} = toroco:subscribe_world(), Self ! subscribed,
                                         receive stop -> ok end end),
    receive subscribed -> ok after 5000 -> ct:fail(not_subscribed) end,
    Made = fun() ->
                   ok = toroco:publish_world(fun() -> Self ! made, #{run => r, t_ms => 0} end),
                   receive made -> true after 0 -> false end
           end,
    true = Made(),
    Pid ! stop,
    receive {'DOWN', MRef, process, Pid, _} -> ok after 5000 -> ct:fail(not_down) end,
    wait_until(fun() -> not Made() end, 5000).

%% The snapshots in this process's mailbox now (a publish from this
%% process to itself is there when publish_world/1 returns).
world_messages() ->
    receive {toroco_world, S} -> [S | world_messages()] after 0 -> [] end.

world_subscription_down_with_the_runtime() ->
    [{doc, "When the runtime stops, a world subscriber gets a DOWN for its subscription's "
      "reference, and after the runtime is back it can subscribe again."}].
world_subscription_down_with_the_runtime(_Config) ->
    {ok, Ref} = toroco:subscribe_world(),
    toroco_test_lib:stop(),
    receive {'DOWN', Ref, process, _, _} -> ok after 5000 -> ct:fail(no_down) end,
    {error, {not_running, toroco}} = toroco:subscribe_world(),
    toroco_test_lib:start(),
    {ok, Ref2} = toroco:subscribe_world(),
    ok = toroco:publish_world(#{run => r, t_ms => 5}),
    [#{t_ms := 5}] = world_messages(),
    ok = toroco:unsubscribe_world(Ref2).
