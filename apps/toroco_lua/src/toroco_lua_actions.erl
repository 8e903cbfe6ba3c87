%% @doc What the answer of a Lua activation asks for, as the engine's
%% actions (SPEC §16): emissions (`send', `set', `unset' on open ports: an
%% output exists once the code emits on it), the tasks' timers as
%% gen_statem timeouts, prints and warnings to the log, and wiring calls
%% (handed to `toroco_lua_main'; a behavior removing, suspending or resuming
%% itself has that done once its callback is over). Beside `toroco_lua'
%% (the callbacks) and `toroco_lua_main'.
-module(toroco_lua_actions).

-export([actions/2, print/2]).

-define(LOG, #{domain => [toroco, lua]}).

%% @doc The port's actions as the engine's: emissions and timers. A behavior
%% removing, suspending or resuming itself would wait on itself from its
%% own callback: that is done once the callback is over, after the calls
%% it made next (the thesis' level2 removes itself, then adds level3).
-spec actions(list(), map()) -> list().
actions(Actions, D) ->
    case lists:keymember(main, 1, Actions) of
        false -> lists:filtermap(fun(A) -> action(A, D) end, Actions);
        true -> wiring_actions(Actions, D)
    end.

wiring_actions(Actions, D = #{name := Name}) ->
    Self = atom_to_binary(Name),
    {Later, Now} = lists:partition(
                     fun({main, Op, _, [B]}) ->
                             B =:= Self andalso lists:member(Op, [<<"remove_behavior">>,
                                                                  <<"suspend_behavior">>,
                                                                  <<"resume_behavior">>]);
                        (_) -> false
                     end, Actions),
    Result = lists:filtermap(fun(A) -> action(A, D) end, Now),
    _ = case Later of
            [] -> ok;
            _ ->
                Ctx = toroco_lua_main:ctx(D),
                spawn(fun() -> [toroco_lua_main:call_logged(Op, Args, Ctx, Name)
                                || {main, Op, _, Args} <- Later] end)
        end,
    Result.

action({send, Out, V, Hold}, D) ->
    with_output(Out, D, fun(O) -> case Hold of
                                      default -> {send, #{O => V}};
                                      _ -> {send, #{O => V}, #{hold => Hold}}
                                  end
                        end);
action({set, Out, V}, D) ->
    with_output(Out, D, fun(O) -> {set, #{O => V}} end);
action({unset, all}, _D) ->
    {true, unset};
action({unset, Out}, D) ->
    with_output(Out, D, fun(O) -> {unset, [O]} end);
action({timer, Task, Seq, Ms}, #{gen := Gen}) ->
    {true, {{timeout, {lua, Task}}, Ms, {lua_timer, Gen, Task, Seq}}};
action({cancel, Task}, _D) ->
    {true, {{timeout, {lua, Task}}, cancel}};
action({print, Text}, D) ->
    print(Text, D),
    false;
action({warning, Text}, #{name := Name}) ->
    logger:warning("toroco_lua: ~p: ~ts", [Name, Text], ?LOG#{name => Name}),
    false;
action({main, Op, _Line, Args}, D = #{name := Name}) ->
    %% a behavior changing the network (the thesis' suspender, add/remove)
    _ = toroco_lua_main:call_logged(Op, Args, toroco_lua_main:ctx(D), Name),
    false.

%% @doc A Lua `print', in the log under the behavior's name.
-spec print(unicode:chardata(), map()) -> ok.
print(Text, #{name := Name}) ->
    logger:notice("~p: ~ts", [Name, Text], ?LOG#{name => Name}).

%% Ports are open: an output exists once the code emits on it. Names are
%% atoms, so a name that no atom has yet is made one while the atom table
%% is less than 90 % full (a program that makes names without end would
%% fill it and take the node down); past that such emissions are dropped
%% with a warning.
with_output(Out, #{name := Name}, Fun) ->
    try binary_to_existing_atom(Out) of
        O -> {true, Fun(O)}
    catch error:badarg ->
            case erlang:system_info(atom_count) < erlang:system_info(atom_limit) * 9 div 10
                andalso byte_size(Out) =< 255 of
                true -> {true, Fun(binary_to_atom(Out))};
                false ->
                    logger:warning("toroco_lua: ~p emitted on new output ~ts with the atom "
                                   "table nearly full; dropped", [Name, Out], ?LOG#{name => Name}),
                    false
            end
    end.
