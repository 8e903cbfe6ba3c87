%% The thesis' verification programs (§5.3) and line follower (§4.1.6), run
%% through `torobot_examples' as a user runs them, driven by scripted mouse
%% and sensor events, with the exact sequence each actuator input must get.
%%
%% The verification programs and the line follower (whose scripted lap
%% plays two sensors' timed scripts side by side) run in lockstep (SPEC
%% §14): the runtime's clock
%% is virtual, each injected event is followed by quiescence, and waiting
%% means moving simulated time, so their timeouts and holds are checked to
%% the millisecond. The other groups run in real time: events are injected
%% one at a time and each expected delivery awaited before the next, since
%% the runtime promises no order across different sources.
%% Where an event must have no effect, the chain it travels is settled (every
%% process on it answers a call, so what was sent has been handled) before the
%% record is checked; and every case ends with an exact check of the whole
%% record, so a delivery that should never have come fails the case even if
%% it came late.
-module(torobot_examples_SUITE).
-include_lib("common_test/include/ct.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_test_lib, [lockstep/0, settle/0, pass/1]).

suite() -> [{timetrap, {seconds, 60}}].

all() -> [{group, verification}, {group, line_follower}, {group, devices}, {group, runner}].

groups() ->
    [{verification, [], [sensor_signalling, inhibition_suppression, wait_for_event_trigger,
                         wait_for_event_coroutine, beh_suspend_resume, beh_add_remove]},
     {line_follower, [], [line_follower, line_follower_trace]},
     {devices, [], [console_prints_each_delivery, mouse_decodes_button_events,
                    mouse_drives_an_example_from_recorded_events,
                    mouse_follows_and_reopens_its_device]},
     {runner, [], [run_and_stop_every_example, unknown_example_is_refused]}].

init_per_group(G, Config) when G =:= verification; G =:= line_follower ->
    [{lockstep, true} | Config];
init_per_group(_, Config) ->
    Config.

end_per_group(_, _Config) ->
    ok.

init_per_testcase(_TC, Config) ->
    case ?config(lockstep, Config) of
        true ->
            {ok, _} = application:ensure_all_started(torobot),
            ok = toroco_clock:lockstep(#{});
        _ ->
            ok
    end,
    Config.

end_per_testcase(_TC, _Config) ->
    _ = (catch torobot_examples:stop()),
    _ = (catch toroco_clock:realtime()),
    _ = application:stop(torobot),
    toroco_test_lib:stop().

%%--------------------------------------------------------------------
%% Helpers
%%--------------------------------------------------------------------

run(Example) -> run(Example, #{}).

%% The console is left out unless a case is about it: the record is enough.
run(Example, Opts) -> ok = torobot_examples:run(Example, maps:merge(#{console => false}, Opts)).

mouse(Button, Event) -> ok = toroco:inject({mouse, Button}, Event), settle().

%% In lockstep a measured delay is exact; in real time within its bounds.
delay(Ms, Exact, Low, High) ->
    case lockstep() of
        true -> Exact = Ms;
        false -> true = Ms >= Low andalso Ms < High
    end.

grey(Side, Reading) -> ok = toroco:inject({Side, reading}, Reading).

%% What actuator `A' got on each of its inputs, oldest first.
by_input(A) -> by_input(inputs_of(A), toroco_fake_actuator:history(A)).

by_input(Ins, History) ->
    maps:from_list([{In, [V || {I, V, _} <- History, I =:= In]} || In <- Ins]).

inputs_of(A) -> lists:sort(maps:keys(maps:get(inputs, toroco:inspect(A)))).

%% Waits until actuator `A' has got exactly `Expected' (`#{Input => [Value]}',
%% inputs not listed: nothing), or fails showing what it got. The predicate
%% runs in the actuator, so it must not call the actuator.
expect(A, Expected) -> expect(A, Expected, 3000).

expect(A, Expected, Timeout) ->
    Ins = inputs_of(A),
    Want = want(Ins, Expected),
    case lockstep() of
        true ->
            %% simulated time moves in 10 ms steps until the record is right
            wait_until(fun() -> by_input(Ins, toroco_fake_actuator:history(A)) =:= Want end,
                       Timeout, fun() -> ct:fail({expected, Want, got, by_input(A)}) end);
        false ->
            case toroco_fake_actuator:await(A, fun(H) -> by_input(Ins, H) =:= Want end, Timeout) of
                ok -> ok;
                {error, timeout} -> ct:fail({expected, Want, got, by_input(A)})
            end
    end.

want(Ins, Expected) ->
    maps:merge(maps:from_list([{In, []} || In <- Ins]), Expected).

%% Settles the processes an event travels through, upstream first: each
%% `toroco:inspect/1' answers after the node and the routers of its inputs
%% (done twice so both are after each other), then checks that `A' got
%% exactly `Expected' and nothing more.
nothing_more(Chain, A, Expected) ->
    settle(),
    _ = [{toroco:inspect(N), toroco:inspect(N)} || N <- Chain ++ [A]],
    Want = want(inputs_of(A), Expected),
    case by_input(A) of
        Want -> ok;
        Got -> ct:fail({expected, Want, got, Got})
    end.

%% The monotonic ms at which `A' got `Value' on `In' (the last time).
delivered_at(A, In, Value) ->
    lists:last([T || {I, V, T} <- toroco_fake_actuator:history(A), I =:= In, V =:= Value]).

%% The runtime's time (simulated in lockstep; the fake actuator stamps
%% deliveries with it).
now_ms() -> toroco_clock:now_ms().

%% Checks a condition every 10 ms of the runtime's time (simulated in
%% lockstep), at most Timeout ms.
wait_until(Fun, Timeout) ->
    wait_until(Fun, Timeout, fun() -> ct:fail({condition_not_met_within, Timeout}) end).

wait_until(Fun, Timeout, Fail) ->
    toroco_test_lib:await_runtime(Fun, Timeout, Fail).

input_info(Name, In) -> maps:get(In, maps:get(inputs, toroco:inspect(Name))).

output_info(Name, Out) -> maps:get(Out, maps:get(outputs, toroco:inspect(Name))).

%%--------------------------------------------------------------------
%% The verification programs
%%--------------------------------------------------------------------

sensor_signalling() ->
    [{doc, "Every button event reaches the actuator as {Button, Event}, a burst in order."}].
sensor_signalling(_) ->
    run(sensor_signalling),
    mouse(left, pressed),
    expect(actuator, #{signal => [{left, pressed}]}),
    mouse(left, released),
    expect(actuator, #{signal => [{left, pressed}, {left, released}]}),
    mouse(right, pressed),
    expect(actuator, #{signal => [{left, pressed}, {left, released}, {right, pressed}]}),
    mouse(right, released),
    Four = [{left, pressed}, {left, released}, {right, pressed}, {right, released}],
    expect(actuator, #{signal => Four}),
    %% One button's events travel one path, so a burst keeps its order.
    Burst = lists:append(lists:duplicate(20, [pressed, released])),
    [mouse(left, E) || E <- Burst],
    expect(actuator, #{signal => Four ++ [{left, E} || E <- Burst]}).

inhibition_suppression() ->
    [{doc, "A left click suppresses the lower behavior at the shared input for 2.5 s, a right click inhibits its output everywhere for 2.5 s; then it is heard again."}].
inhibition_suppression(_) ->
    %% Presses are the lower behavior's stimuli and releases the higher one's
    %% triggers, so the script injects them as separate events, not clicks.
    run(inhibition_suppression),
    %% Before any window: lower's press reaches both inputs.
    mouse(left, pressed),
    expect(actuator, #{signal => [{lower, left}], monitor => [{lower, left}]}),
    %% Window 1, suppression: upper's event holds `actuator.signal' 2.5 s.
    mouse(left, released),
    expect(actuator, #{signal => [{lower, left}, {upper, suppress}], monitor => [{lower, left}]}),
    T1 = delivered_at(actuator, signal, {upper, suppress}),
    Seen = toroco:inspect(actuator),
    ct:pal("inspect(actuator) in the suppression window:~n~p", [Seen]),
    #{inputs := #{signal := #{winner := {upper, signal},
                              holds := [{{upper, signal}, Ms}],
                              sources := [{upper, signal}, {lower, signal}]},
                  monitor := #{winner := none, holds := []}}} = Seen,
    true = Ms > 0 andalso Ms =< 2500,
    %% Lower's presses now reach `monitor' (upper is not wired there) and
    %% must not reach `signal'.
    mouse(right, pressed),
    expect(actuator, #{signal => [{lower, left}, {upper, suppress}],
                       monitor => [{lower, left}, {lower, right}]}),
    mouse(left, pressed),
    expect(actuator, #{signal => [{lower, left}, {upper, suppress}],
                       monitor => [{lower, left}, {lower, right}, {lower, left}]}),
    nothing_more([lower], actuator,
                 #{signal => [{lower, left}, {upper, suppress}],
                   monitor => [{lower, left}, {lower, right}, {lower, left}]}),
    %% The window ends when the hold expires, not before 2.5 s. (Right at
    %% the deadline the router may show no hold yet still the old winner
    %% until its timer has fired: wait for both.)
    wait_until(fun() -> case input_info(actuator, signal) of
                            #{holds := [], winner := none} -> true;
                            _ -> false
                        end end, 5000),
    Held1 = now_ms() - T1,
    ct:pal("suppression hold seen expired ~p ms after upper's event", [Held1]),
    delay(Held1, 2500, 2000, infinity),
    %% Lower is heard at `signal' again.
    mouse(right, pressed),
    Sig2 = [{lower, left}, {upper, suppress}, {lower, right}],
    Mon2 = [{lower, left}, {lower, right}, {lower, left}, {lower, right}],
    expect(actuator, #{signal => Sig2, monitor => Mon2}),
    %% Window 2, inhibition: upper's `inhibit' holds 2.5 s; its `signal'
    %% event is momentary and suppresses nothing.
    mouse(right, released),
    Sig3 = Sig2 ++ [{upper, inhibit}],
    expect(actuator, #{signal => Sig3, monitor => Mon2}),
    T2 = delivered_at(actuator, signal, {upper, inhibit}),
    #{inhibited := true, inhibitors := [{upper, inhibit}]} = output_info(lower, signal),
    SeenInh = {toroco:inspect(actuator), toroco:inspect(lower)},
    ct:pal("inspect(actuator) and inspect(lower) in the inhibition window:~n~p", [SeenInh]),
    #{inputs := #{signal := #{holds := []}}} = element(1, SeenInh),
    %% Nothing of lower arrives anywhere, not even at `monitor'.
    mouse(left, pressed),
    mouse(right, pressed),
    nothing_more([lower], actuator, #{signal => Sig3, monitor => Mon2}),
    wait_until(fun() -> not maps:get(inhibited, output_info(lower, signal)) end, 5000),
    Held2 = now_ms() - T2,
    ct:pal("inhibition seen lifted ~p ms after upper's event", [Held2]),
    delay(Held2, 2500, 2000, infinity),
    %% Lower is heard everywhere again; the whole record is exact.
    mouse(left, pressed),
    expect(actuator, #{signal => Sig3 ++ [{lower, left}],
                       monitor => Mon2 ++ [{lower, left}]}).

wait_for_event_trigger() ->
    [{doc, "After a left press: silence if the right press comes within 2 s, `timeout' 2 s later if it does not."}].
wait_for_event_trigger(_) ->
    run(wait_for_event_trigger),
    Chain = [trigger],
    %% In time: armed, then silence, even once the 2 s have passed.
    mouse(left, pressed),
    expect(actuator, #{signal => [armed]}),
    mouse(left, released),
    mouse(right, pressed),
    mouse(right, released),
    pass(2500),                              % the semantics is time: let the wait run out
    nothing_more(Chain, actuator, #{signal => [armed]}),
    %% A right press with no wait running is ignored.
    mouse(right, pressed),
    nothing_more(Chain, actuator, #{signal => [armed]}),
    %% Not in time: armed, a second left press that does not restart the
    %% wait, then timeout about 2 s after armed.
    mouse(left, pressed),
    expect(actuator, #{signal => [armed, armed]}),
    TArmed = lists:last([T || {signal, armed, T} <- toroco_fake_actuator:history(actuator)]),
    pass(1000),
    mouse(left, pressed),
    expect(actuator, #{signal => [armed, armed, timeout]}, 5000),
    Waited = delivered_at(actuator, signal, timeout) - TArmed,
    ct:pal("timeout came ~p ms after armed", [Waited]),
    delay(Waited, 2000, 1500, 2800),                  % a restarted wait would take 3000
    %% A late right press is ignored; a new wait works again.
    mouse(right, pressed),
    mouse(left, pressed),
    expect(actuator, #{signal => [armed, armed, timeout, armed]}),
    mouse(right, pressed),
    pass(2500),
    nothing_more(Chain, actuator, #{signal => [armed, armed, timeout, armed]}).

wait_for_event_coroutine() ->
    [{doc, "Left then right gives left_seen, sequence_done; out-of-order presses are ignored; no right within 2 s gives timeout."}].
wait_for_event_coroutine(_) ->
    run(wait_for_event_coroutine),
    Chain = [sequence],
    mouse(right, pressed),                   % out of order: waiting for left
    nothing_more(Chain, actuator, #{signal => []}),
    mouse(left, pressed),
    expect(actuator, #{signal => [left_seen]}),
    mouse(left, pressed),                    % out of order: waiting for right
    mouse(left, released),
    mouse(right, released),                  % releases never count
    nothing_more(Chain, actuator, #{signal => [left_seen]}),
    mouse(right, pressed),
    expect(actuator, #{signal => [left_seen, sequence_done]}),
    mouse(right, pressed),                   % back to waiting for left
    nothing_more(Chain, actuator, #{signal => [left_seen, sequence_done]}),
    mouse(left, pressed),
    expect(actuator, #{signal => [left_seen, sequence_done, left_seen]}),
    TSeen = lists:last([T || {signal, left_seen, T} <- toroco_fake_actuator:history(actuator)]),
    expect(actuator, #{signal => [left_seen, sequence_done, left_seen, timeout]}, 5000),
    Waited = delivered_at(actuator, signal, timeout) - TSeen,
    ct:pal("timeout came ~p ms after left_seen", [Waited]),
    delay(Waited, 2000, 1500, 4000),
    mouse(right, pressed),                   % late: waiting for left again
    nothing_more(Chain, actuator, #{signal => [left_seen, sequence_done, left_seen, timeout]}),
    mouse(left, pressed),
    expect(actuator, #{signal => [left_seen, sequence_done, left_seen, timeout, left_seen]}),
    mouse(right, pressed),
    expect(actuator, #{signal => [left_seen, sequence_done, left_seen, timeout, left_seen,
                                  sequence_done]}).

beh_suspend_resume() ->
    [{doc, "A left press suspends `display' (its inputs are dropped), a right press resumes it and the latched count is re-delivered."}].
beh_suspend_resume(_) ->
    run(beh_suspend_resume),
    Chain = [counter, display],
    %% Running: each click's release shows the count.
    mouse(right, pressed),
    mouse(right, released),
    expect(actuator, #{signal => [{count, 1}]}),
    %% Suspended: the counts reach display's router and are dropped.
    mouse(left, pressed),
    expect(actuator, #{signal => [{count, 1}], status => [suspended]}),
    #{status := suspended} = toroco:inspect(display),
    mouse(left, released),
    nothing_more(Chain, actuator, #{signal => [{count, 1}], status => [suspended]}),
    #{latches := [{{counter, count}, 2}]} = input_info(display, count),
    mouse(left, pressed),                    % already suspended: nothing
    mouse(left, released),
    nothing_more(Chain ++ [suspender], actuator,
                 #{signal => [{count, 1}], status => [suspended]}),
    #{latches := [{{counter, count}, 3}]} = input_info(display, count),
    %% Resumed: the latched winner (3) is re-delivered at once; 2 is lost.
    mouse(right, pressed),
    expect(actuator, #{signal => [{count, 1}, {count, 3}], status => [suspended, resumed]}),
    #{status := running} = toroco:inspect(display),
    mouse(right, released),
    expect(actuator, #{signal => [{count, 1}, {count, 3}, {count, 4}],
                       status => [suspended, resumed]}).

beh_add_remove() ->
    [{doc, "A left press removes `echo' from inside a callback (nothing of it arrives), a right press adds and re-wires it (a new echo arrives)."}].
beh_add_remove(_) ->
    run(beh_add_remove),
    mouse(right, pressed),                   % present already: nothing
    mouse(right, released),
    expect(actuator, #{signal => [{released, right, 1}]}),
    %% Removed: stripped from the wiring, and nothing of it arrives.
    mouse(left, pressed),
    expect(actuator, #{signal => [{released, right, 1}], status => [removed]}),
    {error, {unknown_name, echo}} = toroco:inspect(echo),
    #{sources := []} = input_info(actuator, signal),
    mouse(left, released),
    mouse(left, pressed),                    % already removed: nothing
    mouse(left, released),
    nothing_more([controller], actuator, #{signal => [{released, right, 1}], status => [removed]}),
    %% Added back and re-wired by the controller: a new incarnation, counting
    %% from 1 again.
    mouse(right, pressed),
    expect(actuator, #{signal => [{released, right, 1}], status => [removed, added]}),
    #{sources := [{echo, signal}]} = input_info(actuator, signal),
    #{sources := [{mouse, left}]} = input_info(echo, left),
    mouse(right, released),
    expect(actuator, #{signal => [{released, right, 1}, {released, right, 1}],
                       status => [removed, added]}),
    mouse(right, pressed),                   % present already: nothing
    mouse(right, released),
    expect(actuator, #{signal => [{released, right, 1}, {released, right, 1}, {released, right, 2}],
                       status => [removed, added]}).

%%--------------------------------------------------------------------
%% The line follower
%%--------------------------------------------------------------------

-define(LAP, [{50, 50}, {0, 50}, {50, 50}, {50, 0}, {0, 50}, {50, 0}, {50, 50}]).

line_follower() ->
    [{doc, "Turns hold the motors while their sensor reads black; on white forward's latch comes back; turn_left wins over turn_right."}].
line_follower(_) ->
    run(line_follower),
    Lap = ?LAP,
    V = fun(N) -> #{velocity => lists:sublist(Lap, N)} end,
    expect(motors, V(1)),                    % forward's latch, delivered at wiring
    grey(grey_left, black),
    expect(motors, V(2)),
    grey(grey_left, white),
    expect(motors, V(3)),                    % re-delivered latch of forward
    grey(grey_right, black),
    expect(motors, V(4)),
    grey(grey_right, black),                 % no change of reading: nothing
    nothing_more([turn_right], motors, V(4)),
    grey(grey_left, black),                  % both on black: turn_left is listed first
    expect(motors, V(5)),
    #{winner := {turn_left, velocity},
      holds := [{{turn_left, velocity}, infinity}, {{turn_right, velocity}, infinity},
                {{forward, velocity}, infinity}],
      latches := [{{turn_left, velocity}, {0, 50}}, {{turn_right, velocity}, {50, 0}},
                  {{forward, velocity}, {50, 50}}]} = input_info(motors, velocity),
    grey(grey_left, white),
    expect(motors, V(6)),                    % turn_right still holds: its latch comes back
    grey(grey_right, white),
    expect(motors, V(7)),
    #{winner := {forward, velocity}} = input_info(motors, velocity).

line_follower_trace() ->
    [{doc, "The scripted lap of run(line_follower, #{trace => Ms}) drives the motors through the same sequence."}].
line_follower_trace(_) ->
    run(line_follower, #{trace => 150}),
    expect(motors, #{velocity => ?LAP}, 5000).

%%--------------------------------------------------------------------
%% Devices
%%--------------------------------------------------------------------

console_prints_each_delivery() ->
    [{doc, "The console prints `Name.Input <- Value' per delivery to its `out' device and counts them."}].
console_prints_each_delivery(Config) ->
    Path = filename:join(?config(priv_dir, Config), "console.txt"),
    {ok, Out} = file:open(Path, [write]),
    ok = torobot_examples:run(sensor_signalling, #{out => Out}),
    mouse(left, pressed),
    mouse(left, released),
    expect(actuator, #{signal => [{left, pressed}, {left, released}]}),
    wait_until(fun() -> maps:get(device, toroco:inspect(console)) =:=
                            #{printed => 2, by_input => #{signal => 2}} end, 3000),
    ok = file:close(Out),
    {ok, Text} = file:read_file(Path),
    <<"console.signal <- {left,pressed}\nconsole.signal <- {left,released}\n">> = Text.

%% One `struct input_event' of this machine (64-bit: 24 bytes).
ev(Type, Code, Value) -> ev(Type, Code, Value, 8).

ev(Type, Code, Value, Word) ->
    Bits = Word * 8,
    <<1700000000:Bits/native, 123456:Bits/native, Type:16/native, Code:16/native,
      Value:32/native-signed>>.

-define(EV_SYN, 0).
-define(EV_KEY, 1).
-define(EV_REL, 2).
-define(BTN_LEFT, 16#110).
-define(BTN_RIGHT, 16#111).
-define(BTN_MIDDLE, 16#112).

%% A click as a mouse reports it: key, then the report's sync; motion between.
click_events(Code) ->
    [ev(?EV_KEY, Code, 1), ev(?EV_SYN, 0, 0), ev(?EV_REL, 0, -3), ev(?EV_SYN, 0, 0),
     ev(?EV_KEY, Code, 0), ev(?EV_SYN, 0, 0)].

mouse_decodes_button_events() ->
    [{doc, "Left/right key events become press/release; motion, sync, other keys and auto-repeat are ignored; a partial event is kept."}].
mouse_decodes_button_events(_) ->
    Bytes = iolist_to_binary([click_events(?BTN_LEFT), ev(?EV_KEY, ?BTN_MIDDLE, 1),
                              ev(?EV_KEY, ?BTN_RIGHT, 1), ev(?EV_KEY, ?BTN_RIGHT, 2),
                              ev(?EV_KEY, ?BTN_RIGHT, 0)]),
    Events = [{left, pressed}, {left, released}, {right, pressed}, {right, released}],
    {Events, <<>>} = toroco_mouse:decode(Bytes, 24),
    <<Head:30/binary, Tail/binary>> = Bytes,
    {[{left, pressed}], <<_:6/binary>> = Part} = toroco_mouse:decode(Head, 24),
    [_ | Later] = Events,
    {Later, <<>>} = toroco_mouse:decode(<<Part/binary, Tail/binary>>, 24),
    %% The BeagleBone's 32-bit layout: a timeval of two 4-byte longs.
    Bytes32 = iolist_to_binary([ev(?EV_KEY, ?BTN_RIGHT, 1, 4), ev(?EV_SYN, 0, 0, 4),
                                ev(?EV_KEY, ?BTN_RIGHT, 0, 4)]),
    {[{right, pressed}, {right, released}], <<>>} = toroco_mouse:decode(Bytes32, 16).

mouse_drives_an_example_from_recorded_events() ->
    [{doc, "An example run with a mouse device path reads its evdev events: sensor_signalling replays a recorded left and right click."}].
mouse_drives_an_example_from_recorded_events(Config) ->
    Path = filename:join(?config(priv_dir, Config), "recorded.events"),
    %% The recording appears once the example is wired (events read before
    %% would reach no one); the mouse finds it at its next try.
    run(sensor_signalling, #{mouse => Path}),
    %% written aside and renamed, so the mouse never opens a half-written file
    ok = file:write_file(Path ++ ".tmp", [click_events(?BTN_LEFT), click_events(?BTN_RIGHT)]),
    ok = file:rename(Path ++ ".tmp", Path),
    %% Left and right come through two inputs (two routers): each button's
    %% events in order, with no order promised between the two (SPEC §4).
    ok = toroco_fake_actuator:await(actuator, fun(H) -> length(H) >= 4 end, 5000),
    Signals = maps:get(signal, by_input(actuator)),
    [{left, pressed}, {left, released}] = [E || E = {left, _} <- Signals],
    [{right, pressed}, {right, released}] = [E || E = {right, _} <- Signals],
    4 = length(Signals),
    #{module := toroco_mouse, device := #{status := open, button_events := 4}} =
        toroco:inspect(mouse).

mouse_follows_and_reopens_its_device() ->
    [{doc, "A missing device is retried until it appears, without crashing; events appended later are read."}].
mouse_follows_and_reopens_its_device(Config) ->
    Path = filename:join(?config(priv_dir, Config), "later.events"),
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok = toroco:add_device(mouse, toroco_mouse, #{device => Path, retry_ms => 50}),
    ok = toroco:add_device(actuator, toroco_fake_actuator, #{inputs => [left, right]}),
    ok = toroco:set_inputs(actuator, #{left => [{mouse, left}], right => [{mouse, right}]}),
    wait_until(fun() -> case toroco:inspect(mouse) of
                            #{status := running,
                              device := #{status := closed, error := enoent, reopened := R}} ->
                                R >= 2;
                            _ -> false
                        end end, 3000),
    ok = file:write_file(Path, click_events(?BTN_RIGHT)),
    expect(actuator, #{right => [pressed, released]}),
    ok = file:write_file(Path, click_events(?BTN_LEFT), [append]),
    expect(actuator, #{right => [pressed, released], left => [pressed, released]}),
    #{device := #{status := open, error := none, button_events := 4}} = toroco:inspect(mouse),
    ok = toroco:remove_device(mouse).

%%--------------------------------------------------------------------
%% The runner
%%--------------------------------------------------------------------

run_and_stop_every_example() ->
    [{doc, "Every example runs with its defaults (console included) and stop/0 leaves no node behind; a run replaces the one before."}].
run_and_stop_every_example(_) ->
    {ok, Null} = file:open("/dev/null", [write]),
    [begin
         ok = torobot_examples:run(E, #{out => Null}),
         #{behaviors := [_ | _], devices := [_ | _]} = toroco:inspect()
     end || E <- torobot_examples:examples()],
    %% Only the last one is left running.
    #{behaviors := [forward, turn_left, turn_right],
      devices := [console, grey_left, grey_right, motors]} = toroco:inspect(),
    ok = torobot_examples:stop(),
    #{behaviors := [], devices := []} = toroco:inspect(),
    ok = torobot_examples:stop(),
    ok = file:close(Null).

unknown_example_is_refused() ->
    [{doc, "An unknown example is refused by name and nothing is added."}].
unknown_example_is_refused(_) ->
    {error, {unknown_example, dance}} = torobot_examples:run(dance),
    {ok, _} = application:ensure_all_started(torobot),
    #{behaviors := [], devices := []} = toroco:inspect().
