%% @doc An actuator made of a function, called with each value delivered to
%% one of its inputs (SPEC §7's actuator-function adapter).
%%
%% Options:
%% <ul>
%% <li>`fn' (required): `fun((Input, Value) -> any())' or `{M, F, A}' (called
%%     as `apply(M, F, [Input, Value | A])').</li>
%% <li>`inputs' (required): the input names.</li>
%% </ul>
%% What the function returns is ignored. A call that raises, throws or exits
%% is counted as `crashes' and logged (at most once a second, naming the
%% device); the device goes on with the next value. The function runs in the
%% device's process, in delivery order.
%%
%% `info/2': `calls', `crashes'.
-module(toroco_fun_actuator).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, info/2]).

-spec interface(map()) -> #{inputs := [atom()], outputs := []}.
interface(Opts) ->
    Ins = case maps:get(inputs, Opts, []) of
              L when is_list(L) -> lists:usort([I || I <- L, is_atom(I)]);
              _ -> []
          end,
    #{inputs => Ins, outputs => []}.

-spec init(atom(), map()) -> {ok, acting, map()} | {error, term()}.
init(Name, Opts) ->
    Fn = maps:get(fn, Opts, missing),
    Ins = maps:get(inputs, Opts, missing),
    case [K || K <- maps:keys(Opts), not lists:member(K, [fn, inputs])] of
        [K | _] -> {error, {unknown_option, K}};
        [] ->
            case {valid_fn(Fn), is_list(Ins) andalso Ins =/= [] andalso lists:all(fun is_atom/1, Ins)} of
                {false, _} -> {error, {bad_option, {fn, Fn}}};
                {_, false} -> {error, {bad_option, {inputs, Ins}}};
                {true, true} ->
                    {ok, acting, #{name => Name, fn => Fn, calls => 0,
                                   bad => toroco_bad_input:new(Name)}}
            end
    end.

valid_fn(F) when is_function(F, 2) -> true;
valid_fn({M, F, A}) -> is_atom(M) andalso is_atom(F) andalso is_list(A);
valid_fn(_) -> false.

-spec handle_input(atom(), term(), acting, map()) -> toroco_behavior:result().
handle_input(Input, V, _State, D = #{fn := Fn, calls := N}) ->
    D1 = D#{calls := N + 1},
    try call(Fn, Input, V) of
        _ -> {keep_state, D1}
    catch
        Class:Reason ->
            #{bad := B} = D1,
            {keep_state, D1#{bad := toroco_bad_input:count(crash, {Input, Class, Reason}, B)}}
    end.

call({M, F, A}, Input, V) -> apply(M, F, [Input, V | A]);
call(F, Input, V) -> F(Input, V).

-spec info(acting, map()) -> map().
info(_State, #{calls := N, bad := B}) ->
    #{calls => N, crashes => maps:get(crash, toroco_bad_input:counts(B), 0)}.
