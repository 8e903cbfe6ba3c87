%% @doc The thesis' verification programs (§5.3) and its line follower
%% (§4.1.6), each runnable with one call from `rebar3 shell':
%% ```
%% 1> torobot_examples:run(inhibition_suppression).
%% 2> torobot_examples:click(left).
%% 3> torobot_examples:stop().
%% '''
%% {@link run/1} starts the applications, adds the example's devices and
%% behaviors and wires them; {@link stop/0} removes what it added (running an
%% example stops the one before). {@link network/2} returns an example's
%% network as data, in the terms of a wiring file.
%%
%% The programs are driven by a mouse, `mouse', with outputs `left' and
%% `right' carrying `pressed' and `released'. It is a `toroco_fake_sensor'
%% ("fake mouse") that {@link click/1}, {@link press/1} and {@link release/1}
%% drive, or the real `toroco_mouse' on an evdev device with option
%% `#{mouse => "/dev/input/eventN"}'. What reaches the actuator is recorded by
%% `actuator', a `toroco_fake_actuator' (`toroco_fake_actuator:history(actuator)'),
%% and printed by `console', a `toroco_console' wired the same way, as lines
%% `console.Input <- Value'.
%%
%% <b>sensor_signalling</b>: `signaller' passes each button event on.
%% Click left: `console.signal <- {left,pressed}', then `{left,released}';
%% the same for right.
%%
%% <b>inhibition_suppression</b>: `lower' (layer 0, `torobot_ex_press_relay')
%% signals each press as `{lower, Button}' on `actuator.signal' and
%% `actuator.monitor'; `upper' (layer 1, `torobot_ex_takeover') takes over
%% for 2.5 s (option `window_ms') when a click completes. Wiring:
%% `actuator.signal <- [upper.signal, lower.signal]', `actuator.monitor <-
%% [lower.signal]', and `upper.inhibit' inhibits `lower.signal'.
%% Click left: `{lower,left}' on both inputs, then `signal <- {upper,suppress}'
%% held 2.5 s: presses now show on `monitor' only (suppressed at `signal',
%% where `upper' is wired, not where it is not). Click right: `{lower,right}'
%% on both, then `signal <- {upper,inhibit}': for 2.5 s presses show nowhere
%% (`lower.signal' is inhibited). A click completed inside a window starts a
%% new window. During a suppression window `toroco:inspect(actuator)' shows
%% `upper.signal' as the winner of `signal' with its remaining hold in ms;
%% during an inhibition window `toroco:inspect(lower)' shows `signal' as
%% inhibited by `upper.inhibit'.
%%
%% <b>wait_for_event_trigger</b>: `trigger' (`torobot_ex_trigger'). Click
%% left: `armed'; click right within 2 s (option `timeout_ms'): nothing more.
%% Click left and wait: `timeout' 2 s later.
%%
%% <b>wait_for_event_coroutine</b>: `sequence' (`torobot_ex_sequence'). Click
%% left: `left_seen'; then right within 2 s: `sequence_done', else
%% `timeout'. Out-of-order clicks show nothing.
%%
%% <b>beh_suspend_resume</b>: `counter' latches the number of clicks, which
%% `display' shows as `signal <- {count,N}'; `suspender' (layer 1) suspends
%% `display' on a left press (`status <- suspended') and resumes it on a right
%% press (`status <- resumed'). Click right: `{count,1}'. Click left: the
%% click is counted but not shown. Click left again: still nothing. Click
%% right: `resumed' and at once `{count,3}' (the latch re-delivered on
%% resume), then `{count,4}' for this click's release.
%%
%% <b>beh_add_remove</b>: `echo' signals each release as
%% `{released, Button, N}', N counted from its start; `controller' (layer 1)
%% removes `echo' on a left press (`status <- removed') and adds it back and
%% re-wires it on a right press (`status <- added'). Click right:
%% `{released,right,1}'. Click left: `removed', and its release echoes
%% nothing. Click right: `added', then `{released,right,1}' from the new
%% echo. Click right again: `{released,right,2}'.
%%
%% <b>line_follower</b>: `forward' latches `{50,50}' on `motors.velocity';
%% `turn_left' and `turn_right' (layer 1) read the grey sensors `grey_left'
%% and `grey_right' (output `reading': `black' or `white') and hold
%% `{0,50}' / `{50,0}' while theirs reads black. Try
%% `toroco:inject({grey_left, reading}, black)' (motors turn left) and
%% `white' (back to `{50,50}'), or run it with `#{trace => true}' to play a
%% scripted lap, one reading a second.
%%
%% Options of {@link run/2}: `console' (default `true'), `out' (the console's
%% io device, default `user'), `mouse' (`fake', a script `{script, Steps}'
%% for the fake mouse, or an evdev path), `window_ms', `timeout_ms', `trace'
%% (`true' or the ms between readings).
-module(torobot_examples).

-export([run/1, run/2, stop/0, examples/0, network/2,
         click/1, press/1, release/1]).
-export_type([example/0, opts/0, step/0]).

-type example() :: sensor_signalling | inhibition_suppression | wait_for_event_trigger
                 | wait_for_event_coroutine | beh_suspend_resume | beh_add_remove
                 | line_follower.
-type opts() :: #{console => boolean(), out => io:device(),
                  mouse => fake | {script, list()} | file:filename(),
                  window_ms => non_neg_integer(), timeout_ms => non_neg_integer(),
                  trace => boolean() | pos_integer()}.
%% One step of a network, in the terms of a wiring file (`toroco:load_wiring/1').
-type step() :: {device, atom(), module(), map()}
              | {behavior, atom(), module(), toroco:behavior_opts()}
              | {inputs, atom(), #{atom() => toroco:input_spec()}}
              | {inhibitors, atom(), #{atom() => [toroco:source_spec()]}}.

-define(ENV, running_example).

%%====================================================================
%% Running
%%====================================================================

%% @doc Runs `Example' with the default options.
-spec run(example()) -> ok | {error, term()}.
run(Example) ->
    run(Example, #{}).

%% @doc Starts the applications, stops the example running before, if any,
%% and adds and wires `Example'. A refused step undoes the steps before it.
-spec run(example(), opts()) -> ok | {error, term()}.
run(Example, Opts) ->
    case lists:member(Example, examples()) of
        false ->
            {error, {unknown_example, Example}};
        true ->
            case application:ensure_all_started(torobot) of
                {ok, _} ->
                    ok = stop(),
                    apply_steps(Example, network(Example, Opts), []);
                {error, Reason} ->
                    {error, {start_failed, Reason}}
            end
    end.

apply_steps(Example, [], Added) ->
    application:set_env(torobot, ?ENV, {Example, Added});
apply_steps(Example, [Step | Rest], Added) ->
    case apply_step(Step) of
        ok ->
            apply_steps(Example, Rest, added(Step, Added));
        {error, Reason} ->
            remove_all(Added),
            {error, {Example, Step, Reason}}
    end.

apply_step({device, Name, Module, Opts}) -> toroco:add_device(Name, Module, Opts);
apply_step({behavior, Name, Module, Opts}) -> toroco:add_behavior(Name, Module, Opts);
apply_step({inputs, Receiver, Inputs}) -> toroco:set_inputs(Receiver, Inputs);
apply_step({inhibitors, Emitter, Outputs}) -> toroco:set_inhibitors(Emitter, Outputs).

added({device, Name, _, _}, Added) -> [{device, Name} | Added];
added({behavior, Name, _, _}, Added) -> [{behavior, Name} | Added];
added(_, Added) -> Added.

%% @doc Removes what the running example added (behaviors first, the newest
%% first), whatever the example did to its own network since.
-spec stop() -> ok.
stop() ->
    case application:get_env(torobot, ?ENV) of
        {ok, {_Example, Added}} ->
            remove_all(Added),
            application:unset_env(torobot, ?ENV);
        undefined ->
            ok
    end.

remove_all(Added) ->
    {Behaviors, Devices} = lists:partition(fun({K, _}) -> K =:= behavior end, Added),
    _ = [catch toroco:remove_behavior(N) || {_, N} <- Behaviors],
    _ = [catch toroco:remove_device(N) || {_, N} <- Devices],
    ok.

%% @doc The examples, in the thesis' order.
-spec examples() -> [example()].
examples() ->
    [sensor_signalling, inhibition_suppression, wait_for_event_trigger,
     wait_for_event_coroutine, beh_suspend_resume, beh_add_remove, line_follower].

%%====================================================================
%% Driving the fake mouse
%%====================================================================

%% @doc A click as a hand makes it: a press, 100 ms, a release.
-spec click(left | right) -> ok | {error, term()}.
click(Button) ->
    case press(Button) of
        ok -> timer:sleep(100), release(Button);
        Err -> Err
    end.

-spec press(left | right) -> ok | {error, term()}.
press(Button) -> toroco:inject({mouse, Button}, pressed).

-spec release(left | right) -> ok | {error, term()}.
release(Button) -> toroco:inject({mouse, Button}, released).

%%====================================================================
%% The networks
%%====================================================================

%% @doc `Example''s network as the steps `run/2' applies, in order.
-spec network(example(), opts()) -> [step()].
network(sensor_signalling, Opts) ->
    [mouse(Opts),
     {behavior, signaller, torobot_ex_signaller, #{layer => 0}},
     {inputs, signaller, buttons()}
     | actuators(actuator, #{signal => [{signaller, signal}]}, Opts)];
network(inhibition_suppression, Opts) ->
    Window = maps:get(window_ms, Opts, 2500),
    [mouse(Opts),
     {behavior, lower, torobot_ex_press_relay, #{layer => 0}},
     {behavior, upper, torobot_ex_takeover, #{layer => 1, params => #{window_ms => Window}}},
     {inputs, lower, buttons()},
     {inputs, upper, buttons()},
     {inhibitors, lower, #{signal => [{upper, inhibit}]}}
     | actuators(actuator, #{signal => [{upper, signal}, {lower, signal}],
                             monitor => [{lower, signal}]}, Opts)];
network(wait_for_event_trigger, Opts) ->
    [mouse(Opts),
     {behavior, trigger, torobot_ex_trigger, #{layer => 0, params => timeout(Opts)}},
     {inputs, trigger, buttons()}
     | actuators(actuator, #{signal => [{trigger, signal}]}, Opts)];
network(wait_for_event_coroutine, Opts) ->
    [mouse(Opts),
     {behavior, sequence, torobot_ex_sequence, #{layer => 0, params => timeout(Opts)}},
     {inputs, sequence, buttons()}
     | actuators(actuator, #{signal => [{sequence, signal}]}, Opts)];
network(beh_suspend_resume, Opts) ->
    [mouse(Opts),
     {behavior, counter, torobot_ex_click_counter, #{layer => 0}},
     {behavior, display, torobot_ex_display, #{layer => 0}},
     {behavior, suspender, torobot_ex_suspender, #{layer => 1, params => #{target => display}}},
     {inputs, counter, buttons()},
     {inputs, display, #{count => [{counter, count}]}},
     {inputs, suspender, buttons()}
     | actuators(actuator, #{signal => [{display, signal}], status => [{suspender, status}]},
                 Opts)];
network(beh_add_remove, Opts) ->
    EchoOpts = #{layer => 0},
    Fed = #{signal => [{echo, signal}]},
    Rewire = [{echo, buttons()} | [{A, Fed} || A <- actuator_names(Opts)]],
    [mouse(Opts),
     {behavior, echo, torobot_ex_release_echo, EchoOpts},
     {behavior, controller, torobot_ex_add_remove,
      #{layer => 1, params => #{target => echo, module => torobot_ex_release_echo,
                                opts => EchoOpts, wiring => Rewire}}},
     {inputs, echo, buttons()},
     {inputs, controller, buttons()}
     | actuators(actuator, maps:merge(Fed, #{status => [{controller, status}]}), Opts)];
network(line_follower, Opts) ->
    %% The sensors come last, so that a trace's first reading finds them wired.
    {Left, Right} = traces(maps:get(trace, Opts, false)),
    [{behavior, forward, torobot_ex_forward, #{layer => 0, params => #{velocity => {50, 50}}}},
     {behavior, turn_left, torobot_ex_turn, #{layer => 1, params => #{velocity => {0, 50}}}},
     {behavior, turn_right, torobot_ex_turn, #{layer => 1, params => #{velocity => {50, 0}}}}]
    ++ actuators(motors, #{velocity => [{turn_left, velocity}, {turn_right, velocity},
                                        {forward, velocity}]}, Opts)
    ++ [{device, grey_left, toroco_fake_sensor, #{outputs => [reading], script => Left}},
        {device, grey_right, toroco_fake_sensor, #{outputs => [reading], script => Right}},
        {inputs, turn_left, #{grey => [{grey_left, reading}]}},
        {inputs, turn_right, #{grey => [{grey_right, reading}]}}].

mouse(Opts) ->
    case maps:get(mouse, Opts, fake) of
        fake ->
            {device, mouse, toroco_fake_sensor, #{outputs => [left, right]}};
        {script, Steps} ->
            {device, mouse, toroco_fake_sensor, #{outputs => [left, right], script => Steps}};
        Path ->
            {device, mouse, toroco_mouse, #{device => Path}}
    end.

buttons() ->
    #{left => [{mouse, left}], right => [{mouse, right}]}.

timeout(Opts) ->
    #{timeout_ms => maps:get(timeout_ms, Opts, 2000)}.

%% The recording actuator `Name' and, unless told not to, the console, each
%% with inputs `Inputs' wired alike.
actuators(Name, Inputs, Opts) ->
    Ins = maps:keys(Inputs),
    Console = case maps:get(console, Opts, true) of
                  true ->
                      [{device, console, toroco_console,
                        #{inputs => Ins, out => maps:get(out, Opts, user)}},
                       {inputs, console, Inputs}];
                  false ->
                      []
              end,
    [{device, Name, toroco_fake_actuator, #{inputs => Ins}}, {inputs, Name, Inputs} | Console].

actuator_names(Opts) ->
    case maps:get(console, Opts, true) of
        true -> [actuator, console];
        false -> [actuator]
    end.

%% A lap over the line: the left sensor finds it, loses it; the right one
%% finds it (and reads it again); the left one finds it too, while the right
%% still holds; then each loses it. One reading every `Step' ms; each script
%% counts from its previous step.
traces(false) ->
    {[], []};
traces(true) ->
    traces(1000);
traces(Step) when is_integer(Step), Step > 0 ->
    {[{Step, reading, black}, {Step, reading, white}, {3 * Step, reading, black},
      {Step, reading, white}],
     [{3 * Step, reading, black}, {Step, reading, black}, {3 * Step, reading, white}]}.
