%% @doc A console actuator: prints every delivery as `Name.Input <- Value'.
%%
%% The actuator to wire when a program should be watched rather than obeyed:
%% the verification programs of `torobot_examples' print what reaches their
%% actuator here, one line per delivery, in the order the device got them.
%%
%% `toroco:add_device(Name, toroco_console, #{inputs => [In]})'. Options:
%% `inputs' (required, the input names) and `out', the io device the lines go
%% to (default `user', the node's console; a pid from `file:open/2' writes a
%% file). The number of lines printed, in all and per input, shows in
%% `toroco:inspect(Name)' under `device'.
-module(toroco_console).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, info/2]).

-spec interface(map()) -> #{inputs := [atom()], outputs := []}.
interface(#{inputs := Ins}) when is_list(Ins) -> #{inputs => Ins, outputs => []};
interface(Opts) -> error({bad_option, {inputs, maps:get(inputs, Opts, missing)}}).

-spec init(atom(), map()) -> {ok, printing, map()} | {error, term()}.
init(Name, Opts) ->
    case maps:get(out, Opts, user) of
        Out when is_atom(Out); is_pid(Out) ->
            {ok, printing, #{name => Name, out => Out, printed => 0, by_input => #{}}};
        Bad ->
            {error, {bad_option, {Name, {out, Bad}}}}
    end.

-spec handle_input(atom(), term(), printing, map()) -> {keep_state, map()}.
handle_input(In, V, _S, D = #{name := Name, out := Out, printed := N, by_input := By}) ->
    io:format(Out, "~ts.~ts <- ~tp~n", [Name, In, V]),
    {keep_state, D#{printed := N + 1, by_input := maps:update_with(In, fun(C) -> C + 1 end, 1, By)}}.

-spec info(printing, map()) -> #{printed := non_neg_integer(),
                                  by_input := #{atom() => pos_integer()}}.
info(_S, #{printed := N, by_input := By}) ->
    #{printed => N, by_input => By}.
