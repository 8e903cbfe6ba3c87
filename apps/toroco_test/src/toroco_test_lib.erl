%% What every application's suites share: the runtime's set-up and its
%% fake devices, and the suites' only waits. A suite waits on a message
%% (`receive' with a pattern and a bounded `after') or through this module:
%% on a condition (wait_until/2,3, poll/2,3, wait_fold/4), on the runtime's
%% time (pass/1, await_runtime/3), for a value to stay put (stays/4), for
%% nothing to arrive (nothing_arrives/3), for time itself to pass (quiet/1),
%% or for a paced load's end (paced/3, pace/3, await_paced/2). test/toroco_waits_SUITE
%% fails on a `timer:sleep' or a bare `receive after' anywhere else.
-module(toroco_test_lib).
-export([distributed/1, root/0, start/0, stop/0, clear/0, restore_env/3, values/1, values/2, await_values/2, await_values/3,
         await_input/4, settle/1, lockstep/0, settle/0, pass/1, await_runtime/3,
         sensor/2, actuator/2, wait_until/2, wait_until/3, poll/2, poll/3, wait_fold/4,
         stays/4, nothing_arrives/3, quiet/1, paced/3, pace/3, await_paced/2, stop_paced/1]).

-export_type([paced/0]).

%% A paced load: the process injecting it.
-type paced() :: pid().

%% Makes this node distributed on loopback (longnames), named `Prefix'
%% and a unique number, unless it is already: whether it started it.
-spec distributed(string()) -> boolean().
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

%% The project's top folder (this file is apps/toroco_test/src/toroco_test_lib.erl).
-spec root() -> file:filename().
root() ->
    Source = proplists:get_value(source, ?MODULE:module_info(compile)),
    filename:dirname(filename:dirname(filename:dirname(filename:dirname(Source)))).

-spec start() -> ok.
start() ->
    {ok, _} = application:ensure_all_started(toroco_hw),
    ok.

-spec stop() -> ok.
stop() ->
    _ = application:stop(toroco_hw),
    _ = application:stop(toroco),
    ok.

%% An app env key put back as `application:get_env(App, Key)' found it
%% (`Was'), for the suites after a test that changed it.
-spec restore_env(atom(), atom(), {ok, term()} | undefined) -> ok.
restore_env(App, Key, {ok, V}) -> application:set_env(App, Key, V);
restore_env(App, Key, undefined) -> application:unset_env(App, Key).

%% Every behavior and device removed, the runtime left running.
-spec clear() -> ok.
clear() ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    _ = [toroco:remove_behavior(B) || B <- Bs],
    _ = [toroco:remove_device(D) || D <- Ds],
    ok.

-spec sensor(atom(), [atom()]) -> ok.
sensor(Name, Outs) -> ok = toroco:add_device(Name, toroco_fake_sensor, #{outputs => Outs}).
-spec actuator(atom(), [atom()]) -> ok.
actuator(Name, Ins) -> ok = toroco:add_device(Name, toroco_fake_actuator, #{inputs => Ins}).

%% The values `A' received, in order.
-spec values(atom()) -> [term()].
values(A) -> [V || {_, V, _} <- toroco_fake_actuator:history(A)].

-spec await_values(atom(), [term()]) -> ok.
await_values(A, Expected) -> await_values(A, Expected, 3000).

%% Waits until the actuator has received exactly `Expected' (in order).
-spec await_values(atom(), [term()], non_neg_integer()) -> ok.
await_values(A, Expected, Timeout) ->
    case toroco_fake_actuator:await(A, fun(H) -> [V || {_, V, _} <- H] =:= Expected end,
                                    Timeout) of
        ok -> ok;
        {error, timeout} -> ct:fail({expected, Expected, got, values(A)})
    end.

%% The values `Input' of `A' received, in order.
-spec values(atom(), atom()) -> [term()].
values(A, Input) -> [V || {I, V, _} <- toroco_fake_actuator:history(A), I =:= Input].

%% Waits until the values delivered on `Input' are exactly `Expected'.
-spec await_input(atom(), atom(), [term()], non_neg_integer()) -> ok.
await_input(A, Input, Expected, Timeout) ->
    Pred = fun(H) -> [V || {I, V, _} <- H, I =:= Input] =:= Expected end,
    case toroco_fake_actuator:await(A, Pred, Timeout) of
        ok -> ok;
        {error, timeout} -> ct:fail({expected, Input, Expected, got, values(A, Input)})
    end.

%% Returns once everything already sent towards `A' has been handled: the
%% routers of its inputs and the actuator itself answer in order.
-spec settle(atom()) -> ok.
settle(A) ->
    _ = toroco:inspect(A),
    _ = toroco_fake_actuator:history(A),
    ok.

%% Whether the runtime runs in lockstep (SPEC §14).
-spec lockstep() -> boolean().
lockstep() -> toroco_clock:mode() =:= lockstep.

%% In lockstep: returns once everything the events so far caused is
%% handled; in real time at once.
-spec settle() -> ok.
settle() ->
    case lockstep() of
        true -> ok = toroco_clock:settle();
        false -> ok
    end.

%% Lets `Ms' of the runtime's time pass: simulated in lockstep, else real.
-spec pass(non_neg_integer()) -> ok.
pass(Ms) ->
    case lockstep() of
        true -> {ok, _} = toroco_clock:tick(toroco_clock:now_ms() + Ms, []), ok;
        false -> pause(Ms)
    end.

%% Checks `Fun()' every 10 ms of the runtime's time (simulated in lockstep,
%% where each step ticks the clock; else real) until it returns `true', for
%% at most `Timeout' ms; then `Fail()'.
-spec await_runtime(fun(() -> term()), non_neg_integer(), fun(() -> term())) -> term().
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

%% The one bounded wait on a condition: checks `Fun()' every 5 ms until it
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
    Step = fun(Acc) -> case Fun() of true -> {done, ok}; _ -> {more, Acc} end end,
    case fold_until(Step, none, deadline(Timeout), Every) of
        {done, ok} -> ok;
        {timeout, none} -> timeout
    end.

-spec wait_until(fun(() -> term()), non_neg_integer()) -> ok.
wait_until(Fun, Timeout) ->
    wait_until(Fun, Timeout, condition_not_met).

-spec wait_until(fun(() -> term()), non_neg_integer(), term()) -> ok.
wait_until(Fun, Timeout, What) ->
    case poll(Fun, Timeout) of
        ok -> ok;
        timeout -> ct:fail({timeout, Timeout, What})
    end.

%% A condition wait that carries what it has seen: `Step(Acc)' answers
%% `{done, Result}' (then `Result') or `{more, Acc1}' (checked again 5 ms
%% later); after `Timeout' ms the case fails with `{timeout, Ms, What,
%% LastAcc}'.
-spec wait_fold(fun((Acc) -> {done, Result} | {more, Acc}), Acc, non_neg_integer(), term()) ->
          Result when Acc :: term(), Result :: term().
wait_fold(Step, Acc0, Timeout, What) ->
    case fold_until(Step, Acc0, deadline(Timeout), 5) of
        {done, Result} -> Result;
        {timeout, Acc} -> ct:fail({timeout, Timeout, What, Acc})
    end.

fold_until(Step, Acc, Deadline, Every) ->
    case Step(Acc) of
        {done, _} = Done -> Done;
        {more, Acc1} ->
            case erlang:monotonic_time(millisecond) >= Deadline of
                true -> {timeout, Acc1};
                false -> pause(Every), fold_until(Step, Acc1, Deadline, Every)
            end
    end.

%% That `Fun()' keeps answering `Expected' for `Ms' ms (checked every 5
%% ms): a check that nothing happened, which fails at the first change with
%% `{changed, What, Expected, Got}'.
-spec stays(fun(() -> term()), term(), non_neg_integer(), term()) -> ok.
stays(Fun, Expected, Ms, What) ->
    Step = fun(Acc) ->
                   case Fun() of
                       Expected -> {more, Acc};
                       Got -> {done, {changed, Got}}
                   end
           end,
    case fold_until(Step, none, deadline(Ms), 5) of
        {timeout, none} -> ok;
        {done, {changed, Got}} -> ct:fail({changed, What, Expected, Got})
    end.

%% That no message for which `Match(Msg)' is true arrives in `Ms' ms (one
%% already there counts): fails with `{arrived, What, Msg}'. Messages that
%% do not match stay in the mailbox.
-spec nothing_arrives(fun((term()) -> boolean()), non_neg_integer(), term()) -> ok.
nothing_arrives(Match, Ms, What) ->
    quiet(Ms),
    {messages, Msgs} = erlang:process_info(self(), messages),
    case [M || M <- Msgs, Match(M)] of
        [] -> ok;
        [M | _] -> ct:fail({arrived, What, M})
    end.

%% Lets `Ms' ms of real time pass, for a check whose point is time itself:
%% an age or a window that must run out, a process that must stay idle
%% meanwhile. (In the runtime's time, which lockstep simulates: pass/1.)
-spec quiet(non_neg_integer()) -> ok.
quiet(Ms) ->
    pause(Ms).

pause(Ms) ->
    receive after Ms -> ok end.

deadline(Timeout) ->
    erlang:monotonic_time(millisecond) + Timeout.

%% A load paced in real time: a process linked to the caller calls
%% `Inject(K)' for K in 1..N (`infinity': until stop_paced/1), one call
%% every `Every' ms at most: a call is due `Every' ms after the one before
%% was due, or was made if that was late (a late call is never made up by
%% a burst). await_paced/2 waits for its end.
-spec paced(fun((pos_integer()) -> term()), pos_integer() | infinity, non_neg_integer()) -> paced().
paced(Inject, N, Every) ->
    Test = self(),
    spawn_link(fun() -> Test ! {paced, self(), pace(Inject, N, Every)} end).

%% The same pacing in the caller's process, for calls that wait on what
%% the caller receives: how late, in ms, the latest call was made.
-spec pace(fun((pos_integer()) -> term()), pos_integer() | infinity, non_neg_integer()) ->
          non_neg_integer().
pace(Inject, N, Every) ->
    pace(Inject, 1, N, Every, erlang:monotonic_time(millisecond), 0).

pace(_Inject, K, N, _Every, _Due, Late) when is_integer(N), K > N ->
    Late;
pace(Inject, K, N, Every, Due, Late) ->
    Now = erlang:monotonic_time(millisecond),
    pause(max(0, Due - Now)),
    _ = Inject(K),
    pace(Inject, K + 1, N, Every, max(Due, Now) + Every, max(Late, Now - Due)).

%% Waits for the end of a paced load (at most `Timeout' ms): how late, in
%% ms, its latest call was made.
-spec await_paced(paced(), non_neg_integer()) -> non_neg_integer().
await_paced(Pacer, Timeout) ->
    receive
        {paced, Pacer, Late} -> Late
    after Timeout ->
            ct:fail({timeout, Timeout, {paced_load, Pacer}})
    end.

%% Stops a paced load and returns once its process is gone.
-spec stop_paced(paced()) -> ok.
stop_paced(Pacer) ->
    unlink(Pacer),
    Ref = monitor(process, Pacer),
    exit(Pacer, kill),
    receive
        {'DOWN', Ref, process, Pacer, _} -> ok
    after 5000 ->
            ct:fail({timeout, 5000, {paced_load_stopped, Pacer}})
    end.
