%% Helpers shared by the runtime's suites.
-module(toroco_test_lib).
-export([start/0, stop/0, values/1, await_values/2, await_values/3, settle/1,
         sensor/2, actuator/2, wait_until/2]).

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

%% Polls a condition every 5 ms, at most Timeout ms.
wait_until(Fun, Timeout) when Timeout =< 0 ->
    case Fun() of
        true -> ok;
        _ -> ct:fail(condition_not_met)
    end;
wait_until(Fun, Timeout) ->
    case Fun() of
        true -> ok;
        _ -> timer:sleep(5), wait_until(Fun, Timeout - 5)
    end.
