%% Helpers shared by the runtime's suites.
-module(toroco_test_lib).
-export([start/0, stop/0, values/1, await_values/2, await_values/3, settle/1,
         sensor/2, actuator/2, wait_until/2, wait_until/3, poll/2, poll/3]).

start() ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok.

stop() ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
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

%% Returns once everything already sent towards `A' has been handled: the
%% routers of its inputs and the actuator itself answer in order.
settle(A) ->
    _ = toroco:inspect(A),
    _ = toroco_fake_actuator:history(A),
    ok.

%% The one bounded wait of the suites: checks `Fun()' every 5 ms until it
%% returns `true', for at most `Timeout' ms of real time. `poll/2' answers
%% `ok' or `timeout'; `wait_until/2,3' fail the case with `{timeout, Ms,
%% What}'. (A wait in simulated time ticks the lockstep clock instead: see
%% torobot_examples_SUITE.)
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
