%% The thesis' verification programs (§5.3) in Lua beside their Erlang
%% versions: each pair runs on the same mouse events and what the actuator
%% gets, input by input, must be the same (Lua has no atoms: its strings,
%% binaries here, are compared as atoms) and what the thesis says.
%%
%% Events are injected one at a time; a delivery is awaited before the next
%% event, and where an event must have no effect every process is settled
%% (each answers `toroco:inspect/1' twice: what was sent has been handled).
%% Windows and timeouts are short (0.4 s) and the pauses that let them run
%% out are the test's input, as in torobot_examples_SUITE.
-module(toroco_lua_examples_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, suite/0, init_per_testcase/2, end_per_testcase/2]).
-export([sensor_signalling/1, inhibition_suppression/1, wait_for_event_trigger/1,
         wait_for_event_coroutine/1, beh_suspend_resume/1, beh_add_remove/1]).

-define(MS, 400).                 % windows and timeouts
-define(PAUSE, 700).              % long enough for one to run out
-define(WAIT, 3000).

suite() ->
    [{timetrap, {seconds, 60}}].

all() ->
    [sensor_signalling, inhibition_suppression, wait_for_event_trigger,
     wait_for_event_coroutine, beh_suspend_resume, beh_add_remove].

init_per_testcase(_Case, Config) ->
    {ok, _} = application:ensure_all_started(torobot),
    {ok, _} = application:ensure_all_started(toroco_lua),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = (catch torobot_examples:stop()),
    _ = application:stop(torobot),
    ok = toroco_test_lib:stop(),
    _ = application:stop(toroco_lua),
    ok.

%%% ---------------------------------------------------------------------
%%% The programs
%%% ---------------------------------------------------------------------

sensor_signalling(doc) ->
    ["Every button event reaches the actuator as {Button, Event}, a burst in order"];
sensor_signalling(_Config) ->
    Burst = lists:append(lists:duplicate(10, [{left, pressed}, {left, released}])),
    same(sensor_signalling, #{},
         [{left, pressed}, {expect, 1}, {left, released}, {expect, 2},
          {right, pressed}, {expect, 3}, {right, released}, {expect, 4}]
         ++ Burst ++ [{expect, 24}],
         #{signal => [{left, pressed}, {left, released}, {right, pressed}, {right, released}]
                     ++ [{left, E} || {_, E} <- Burst]}).

inhibition_suppression(doc) ->
    ["A left click suppresses the lower behavior at the shared input for a window, a "
     "right click inhibits its output everywhere for a window; then it is heard again"];
inhibition_suppression(_Config) ->
    Inhibited = fun(Yes) -> {until, fun() -> inhibited(lower, signal) =:= Yes end} end,
    same(inhibition_suppression, #{upper => 1},
         [{left, pressed}, {expect, 2},
          {left, released}, {expect, 3},
          {right, pressed}, {expect, 4},            % monitor only: signal is held
          {pause, ?PAUSE}, settle,
          {right, pressed}, {expect, 6},
          {right, released}, {expect, 7}, Inhibited(true),
          {left, pressed}, settle, {expect, 7},     % inhibited: nowhere
          Inhibited(false),
          {left, pressed}, {expect, 9}],
         #{signal => [{lower, left}, {upper, suppress}, {lower, right}, {upper, inhibit},
                      {lower, left}],
           monitor => [{lower, left}, {lower, right}, {lower, right}, {lower, left}]}).

wait_for_event_trigger(doc) ->
    ["After a left press: silence if the right press comes in time, timeout if not; "
     "a left press while waiting does not restart the wait"];
wait_for_event_trigger(_Config) ->
    same(wait_for_event_trigger, #{},
         [{left, pressed}, {expect, 1}, {left, released}, settle, {right, pressed},
          {right, released}, {pause, ?PAUSE}, settle, {expect, 1},
          {right, pressed}, settle, {expect, 1},
          {left, pressed}, {expect, 2}, {left, pressed}, {expect, 3},
          {right, pressed}, settle, {left, pressed}, {expect, 4},
          {right, pressed}, {pause, ?PAUSE}, settle, {expect, 4}],
         #{signal => [armed, armed, timeout, armed]}).

wait_for_event_coroutine(doc) ->
    ["Left then right gives left_seen, sequence_done; out-of-order presses are "
     "ignored; no right in time gives timeout"];
wait_for_event_coroutine(_Config) ->
    same(wait_for_event_coroutine, #{},
         [{right, pressed}, settle, {expect, 0},
          {left, pressed}, {expect, 1},
          {left, pressed}, settle, {left, released}, settle, {right, released}, settle,
          {expect, 1},
          {right, pressed}, {expect, 2},
          {right, pressed}, settle, {expect, 2},
          {left, pressed}, {expect, 3}, {expect, 4}],
         #{signal => [left_seen, sequence_done, left_seen, timeout]}).

beh_suspend_resume(doc) ->
    ["Suspended, display shows nothing while clicks are counted; resumed, the "
     "counter's latch is re-delivered at once"];
beh_suspend_resume(_Config) ->
    same(beh_suspend_resume, #{suspender => 1},
         [{right, pressed}, settle, {right, released}, {expect, 1},
          {left, pressed}, {expect, 2}, {left, released}, settle,
          {left, pressed}, settle, {left, released}, settle, {expect, 2},
          {right, pressed}, {expect, 4}, {right, released}, {expect, 5}],
         #{signal => [{count, 1}, {count, 3}, {count, 4}], status => [suspended, resumed]}).

beh_add_remove(doc) ->
    ["A left press removes echo (its releases echo nothing), a right press adds it "
     "back, counting from 1 again"];
beh_add_remove(_Config) ->
    same(beh_add_remove, #{controller => 1},
         [{right, pressed}, settle, {right, released}, {expect, 1},
          {left, pressed}, {expect, 2}, {left, released}, settle, {expect, 2},
          {right, pressed}, {expect, 3}, {right, released}, {expect, 4},
          {right, pressed}, settle, {right, released}, {expect, 5}],
         #{signal => [{released, right, 1}, {released, right, 1}, {released, right, 2}],
           status => [removed, added]}).

%%% ---------------------------------------------------------------------
%%% Running a pair
%%% ---------------------------------------------------------------------

%% Runs the Erlang version, then the Lua one, on the same script; both must
%% give `Want' (inputs not named: nothing).
same(Example, Layers, Script, Want) ->
    Opts = #{console => false, window_ms => ?MS, timeout_ms => ?MS},
    ok = torobot_examples:run(Example, Opts),
    drive(Script),
    Erlang = by_input(),
    ok = torobot_examples:stop(),
    [ok = add_device(S) || S = {device, _, _, _} <- torobot_examples:network(Example, Opts)],
    Main = filename:join([code:priv_dir(toroco_lua), "examples", Example, "main.lua"]),
    {ok, #{behaviors := Loaded}} =
        toroco_lua:load_main(Main, #{layers => Layers,
                                     params => #{window => ?MS / 1000, timeout => ?MS / 1000}}),
    ct:pal("~p: main.lua loaded ~p", [Example, Loaded]),
    drive(Script),
    Lua = normal(by_input()),
    ct:pal("~p, what the actuator got~n Erlang: ~p~n Lua:    ~p", [Example, Erlang, Lua]),
    Full = maps:merge(maps:map(fun(_, _) -> [] end, Erlang), Want),
    ?assertEqual(Full, Erlang),
    ?assertEqual(Erlang, Lua).

add_device({device, Name, Module, Opts}) ->
    toroco:add_device(Name, Module, Opts).

drive([]) -> ok;
drive([Step | Rest]) ->
    step(Step),
    drive(Rest).

step({Button, Event}) when Button =:= left; Button =:= right ->
    ok = toroco:inject({mouse, Button}, Event);
step({expect, N}) ->
    case toroco_fake_actuator:await(actuator, fun(H) -> length(H) =:= N end, ?WAIT) of
        ok -> ok;
        {error, timeout} -> ct:fail({expected, N, deliveries, got, by_input()})
    end;
step(settle) ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    _ = [{toroco:inspect(N), toroco:inspect(N)} || N <- Bs ++ Ds],
    ok;
step({pause, Ms}) ->
    toroco_test_lib:quiet(Ms);              % the semantics is time: let a window run out
step({until, Fun}) ->
    ok = toroco_test_lib:wait_until(Fun, ?WAIT).

inhibited(Emitter, Out) ->
    #{outputs := #{Out := #{inhibited := I}}} = toroco:inspect(Emitter),
    I.

%% What `actuator' got on each of its inputs, oldest first.
by_input() ->
    Ins = maps:keys(maps:get(inputs, toroco:inspect(actuator))),
    H = toroco_fake_actuator:history(actuator),
    maps:from_list([{In, [V || {I, V, _} <- H, I =:= In]} || In <- Ins]).

%% Lua's strings as the atoms the Erlang versions send.
normal(B) when is_binary(B) -> binary_to_atom(B);
normal(T) when is_tuple(T) -> list_to_tuple(normal(tuple_to_list(T)));
normal(L) when is_list(L) -> [normal(X) || X <- L];
normal(M) when is_map(M) -> maps:map(fun(_, V) -> normal(V) end, M);
normal(X) -> X.
