%% @doc A sensor made of a function: polled every `every_ms', emitted on
%% change (SPEC §7's polled-function adapter).
%%
%% Options:
%% <ul>
%% <li>`fn' (required): `fun(() -> Value)' or `{M, F, A}' (called as
%%     `apply(M, F, A)').</li>
%% <li>`every_ms' (default 1000): the polling period; the first poll is at
%%     start.</li>
%% <li>`output' (default `value'): the one output.</li>
%% <li>`latch' (default `false'): `true' emits with `set' (the value stays
%%     latched until it changes), `false' with `send'.</li>
%% </ul>
%% The first value is always emitted, then only values that differ from the
%% last one emitted. A poll that raises, throws or exits is counted as
%% `crashes' and logged (at most once a second, naming the device); the
%% device keeps polling. The function runs in the device's process, so it
%% should not block for long.
%%
%% `info/2': `polls', `emitted', `crashes', `last' (`{value, V}' | `none'),
%% `every_ms'.
%%
%% The call `{toroco_poll, every_ms, Ms}' (`toroco_device:call/3') changes
%% the period, the next poll `Ms' from now: a polled device's answer to the
%% original Torocó's `configure_polling' (SPEC §16). Devices that emit by
%% themselves answer it with the engine's `unknown_call'.
-module(toroco_poll_sensor).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, handle_event/4, info/2]).

-spec interface(map()) -> #{inputs := [], outputs := [atom()]}.
interface(Opts) ->
    case maps:get(output, Opts, value) of
        Out when is_atom(Out) -> #{inputs => [], outputs => [Out]};
        _ -> #{inputs => [], outputs => []}
    end.

-spec init(atom(), map()) -> {ok, polling, map(), toroco_behavior:actions()} |
                                {error, term()}.
init(Name, Opts) ->
    Fn = maps:get(fn, Opts, missing),
    Every = maps:get(every_ms, Opts, 1000),
    Out = maps:get(output, Opts, value),
    Latch = maps:get(latch, Opts, false),
    case [K || K <- maps:keys(Opts), not lists:member(K, [fn, every_ms, output, latch])] of
        [K | _] -> {error, {unknown_option, K}};
        [] ->
            case valid_fn(Fn) of
                false -> {error, {bad_option, {fn, Fn}}};
                true when not is_integer(Every); Every < 1 -> {error, {bad_option, {every_ms, Every}}};
                true when not is_atom(Out) -> {error, {bad_option, {output, Out}}};
                true when not is_boolean(Latch) -> {error, {bad_option, {latch, Latch}}};
                true ->
                    {ok, polling, #{name => Name, fn => Fn, every_ms => Every, output => Out,
                                    latch => Latch, last => none, polls => 0, emitted => 0,
                                    bad => toroco_bad_input:new(Name)},
                     [{state_timeout, 0, poll}]}
            end
    end.

valid_fn(F) when is_function(F, 0) -> true;
valid_fn({M, F, A}) -> is_atom(M) andalso is_atom(F) andalso is_list(A);
valid_fn(_) -> false.

-spec handle_input(atom(), term(), polling, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), polling, map()) ->
          toroco_behavior:result().
handle_event({call, From}, {toroco_poll, every_ms, Ms}, _State, D) ->
    case is_integer(Ms) andalso Ms >= 1 of
        true -> {keep_state, D#{every_ms := Ms}, [{reply, From, ok}, {state_timeout, Ms, poll}]};
        false -> {keep_state_and_data, [{reply, From, {error, {bad_option, {every_ms, Ms}}}}]}
    end;
handle_event(state_timeout, poll, _State, D = #{fn := Fn, every_ms := Every, polls := P}) ->
    Next = {state_timeout, Every, poll},
    D1 = D#{polls := P + 1},
    try call(Fn) of
        V -> changed(V, D1, Next)
    catch
        Class:Reason ->
            #{bad := B} = D1,
            {keep_state, D1#{bad := toroco_bad_input:count(crash, {Class, Reason}, B)}, [Next]}
    end.

call({M, F, A}) -> apply(M, F, A);
call(F) -> F().

changed(V, D = #{last := {value, V}}, Next) ->
    {keep_state, D, [Next]};
changed(V, D = #{output := Out, latch := Latch, emitted := N}, Next) ->
    Emit = case Latch of
               true -> {set, #{Out => V}};
               false -> {send, #{Out => V}}
           end,
    {keep_state, D#{last := {value, V}, emitted := N + 1}, [Emit, Next]}.

-spec info(polling, map()) -> map().
info(_State, D = #{bad := B}) ->
    (maps:with([polls, emitted, last, every_ms], D))#{
      crashes => maps:get(crash, toroco_bad_input:counts(B), 0)}.
