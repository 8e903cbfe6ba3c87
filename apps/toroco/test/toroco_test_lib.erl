%% Helpers shared by the runtime's suites.
-module(toroco_test_lib).
-export([distributed/1, root/0, start/0, stop/0, clear/0, values/1, values/2, await_values/2, await_values/3,
         await_input/4, settle/1, lockstep/0, settle/0, pass/1, await_runtime/3,
         sensor/2, actuator/2, wait_until/2, wait_until/3, poll/2, poll/3]).

%% The project's top folder (this file is apps/toroco/test/toroco_test_lib.erl).
%% Makes this node distributed on loopback (longnames), named `Prefix'
%% and a unique number, unless it is already: whether it started it.
distributed(Prefix) ->
    _ = os:cmd("epmd -daemon"),
    case node() of
        nonode@nohost ->
            Name = list_to_atom(Prefix ++ integer_to_list(erlang:unique_integer([positive]))
                                ++ "@127.0.0.1"),
            {ok, _} = net_kernel:start([Name, longnames]),
            true;
        _ ->
            false
    end.

root() ->
    Source = proplists:get_value(source, ?MODULE:module_info(compile)),
    filename:dirname(filename:dirname(filename:dirname(filename:dirname(Source)))).

start() ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok.

stop() ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
    ok.

%% Every behavior and device removed, the runtime left running.
clear() ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    _ = [toroco:remove_behavior(B) || B <- Bs],
    _ = [toroco:remove_device(D) || D <- Ds],
    ok.

sensor(Name, Outs) -> ok = toroco:add_device(Name, toroco_fake_sensor, #{outputs => Outs}).
actuator(Name, Ins) -> ok = toroco:add_device(Name, toroco_fake_actuator, #{inputs => Ins}).

values(A) -> [V || {_, V, _} <- toroco_fake_actuator:history(A)].

await_values(A, Expected) -> await_values(A, Expected, 3000).

%% Waits until the actuator has received exactly `Expected' (in order).
await_values(A, Expected, Timeout) ->
    case toroco_fake_actuator:await(A, fun(H) -> [V || {_, V, _} <- H] =:= Expected end,
                                    Timeout) of
        ok -> ok;
        {error, timeout} -> ct:fail({expected, Expected, got, values(A)})
    end.

%% The values `Input' of `A' received, in order.
values(A, Input) -> [V || {I, V, _} <- toroco_fake_actuator:history(A), I =:= Input].

%% Waits until the values delivered on `Input' are exactly `Expected'.
await_input(A, Input, Expected, Timeout) ->
    Pred = fun(H) -> [V || {I, V, _} <- H, I =:= Input] =:= Expected end,
    case toroco_fake_actuator:await(A, Pred, Timeout) of
        ok -> ok;
        {error, timeout} -> ct:fail({expected, Input, Expected, got, values(A, Input)})
    end.

%% Returns once everything already sent towards `A' has been handled: the
%% routers of its inputs and the actuator itself answer in order.
settle(A) ->
    _ = toroco:inspect(A),
    _ = toroco_fake_actuator:history(A),
    ok.

%% Whether the runtime runs in lockstep (SPEC §14).
lockstep() -> toroco_clock:mode() =:= lockstep.

%% In lockstep: returns once everything the events so far caused is
%% handled; in real time at once.
settle() ->
    case lockstep() of
        true -> ok = toroco_clock:settle();
        false -> ok
    end.

%% Lets `Ms' of the runtime's time pass: simulated in lockstep, else real.
pass(Ms) ->
    case lockstep() of
        true -> {ok, _} = toroco_clock:tick(toroco_clock:now_ms() + Ms, []), ok;
        false -> timer:sleep(Ms)
    end.

%% Checks `Fun()' every 10 ms of the runtime's time (simulated in lockstep,
%% where each step ticks the clock; else real) until it returns `true', for
%% at most `Timeout' ms; then `Fail()'.
await_runtime(Fun, Timeout, Fail) ->
    settle(),
    runtime_until(Fun, toroco_clock:now_ms() + Timeout, Fail).

runtime_until(Fun, Deadline, Fail) ->
    case Fun() of
        true -> ok;
        _ ->
            case toroco_clock:now_ms() > Deadline of
                true -> Fail();
                false -> pass(10), runtime_until(Fun, Deadline, Fail)
            end
    end.

%% The one bounded wait of the suites: checks `Fun()' every 5 ms until it
%% returns `true', for at most `Timeout' ms of real time. `poll/2' answers
%% `ok' or `timeout'; `wait_until/2,3' fail the case with `{timeout, Ms,
%% What}'. (A wait in the runtime's time, which in lockstep ticks the
%% clock, is await_runtime/3.)
%% `poll/3' checks every `Every' ms, for a check that is costly (a shell
%% command, a call to another node).
-spec poll(fun(() -> term()), non_neg_integer()) -> ok | timeout.
poll(Fun, Timeout) ->
    poll(Fun, Timeout, 5).

-spec poll(fun(() -> term()), non_neg_integer(), pos_integer()) -> ok | timeout.
poll(Fun, Timeout, Every) ->
    poll_until(Fun, erlang:monotonic_time(millisecond) + Timeout, Every).

poll_until(Fun, Deadline, Every) ->
    case Fun() of
        true -> ok;
        _ ->
            case erlang:monotonic_time(millisecond) >= Deadline of
                true -> timeout;
                false -> receive after Every -> poll_until(Fun, Deadline, Every) end
            end
    end.

wait_until(Fun, Timeout) ->
    wait_until(Fun, Timeout, condition_not_met).

wait_until(Fun, Timeout, What) ->
    case poll(Fun, Timeout) of
        ok -> ok;
        timeout -> ct:fail({timeout, Timeout, What})
    end.
