%% @doc `toroco:reload/1': hot code reload of the behaviors running a module.
%%
%% `reload(Module)' takes the module's new object code from the code path
%% (the `.beam' just compiled or copied in), pauses every behavior and device
%% running `Module' with `sys:suspend/1' (inputs wait in their mailboxes;
%% this is not `toroco:suspend_behavior/1'), loads the new code, has each of
%% them convert its state with the module's `code_change/4' (through
%% `sys:change_code/4'; `OldVsn' is the old module's `vsn' attribute, `Extra'
%% is `[]'), and resumes them. Nothing is lost: latches live in the
%% behaviors' state, holds in the routers, and the inputs that queued up
%% while they were paused are handled after the resume, by the new code.
%%
%% <b>All or nothing.</b> The BEAM keeps one current version of a module for
%% all processes, so a failing `code_change' cannot leave one behavior on the
%% old code while its siblings move on. If any `code_change' fails, every
%% behavior gets its state from before the reload back, the old object code
%% is loaded again, and the call returns
%% `{error, {code_change_failed, [{Name, Reason}]}}' naming the behaviors
%% that failed.
%%
%% <b>Keeping the old code.</b> Loading back needs the old object code, and
%% by the time `reload/1' runs the file on disk is already the new one. So
%% the object code of a module is kept in memory (`persistent_term', one
%% binary per module): by {@link remember/1}, which the wiring server calls
%% when it starts a behavior or device, and after each successful reload. If the old code was
%% not kept (the module was loaded some other way and nothing remembered
%% it), a reload still goes ahead, but a failing `code_change' cannot be
%% undone: the new code stays, the behaviors whose `code_change' failed keep
%% their old state, the others keep their new one, and the error is
%% `{error, {code_change_failed, Failed, old_code_not_kept}}'.
%%
%% Other errors, each changing nothing: `{bad_module, M}', `{no_object_code,
%% M}' (no `.beam' on the code path), `{unchanged, M}' (the `.beam' is the
%% code already loaded), `{old_code_in_use, M}' (a process still runs the
%% code before the current one, so nothing can be loaded),
%% `{suspend_failed, {Name, Reason}}' (a behavior stayed busy in a callback
%% for the whole timeout) and `{load_failed, {M, Reason}}'.
-module(toroco_reload).

-export([reload/1, remember/1, kept/1]).

-define(TIMEOUT, 5000).

-type kept_code() :: {MD5 :: binary(), file:filename(), binary()}.

%%====================================================================
%% API
%%====================================================================

-spec reload(module()) -> ok | {error, term()}.
reload(Module) when is_atom(Module) ->
    case code:get_object_code(Module) of
        error ->
            {error, {no_object_code, Module}};
        {Module, NewBin, File} ->
            case code:is_loaded(Module) of
                false -> load_fresh(Module, File, NewBin);
                {file, _} -> reload(Module, File, NewBin)
            end
    end;
reload(Other) ->
    {error, {bad_module, Other}}.

%% @doc Keeps the object code of `Module' as it is loaded now, if the file
%% on the code path still holds it; called when a behavior or device is
%% started, so that a later failed reload can load it back. Cheap when
%% already kept.
-spec remember(module()) -> ok.
remember(Module) when is_atom(Module) ->
    case loaded_md5(Module) of
        undefined -> ok;
        MD5 ->
            case kept_code(Module) of
                {MD5, _, _} -> ok;
                _ -> keep_from_disk(Module, MD5)
            end
    end.

%% @doc Whether the object code of `Module' as loaded now is kept, i.e.
%% whether a failed reload of it can be undone.
-spec kept(module()) -> boolean().
kept(Module) when is_atom(Module) ->
    case {loaded_md5(Module), kept_code(Module)} of
        {undefined, _} -> false;
        {MD5, {MD5, _, _}} -> true;
        _ -> false
    end.

%%====================================================================
%% Reloading
%%====================================================================

load_fresh(Module, File, Bin) ->
    case code:load_binary(Module, File, Bin) of
        {module, Module} -> keep(Module, File, Bin);
        {error, Why} -> {error, {load_failed, {Module, Why}}}
    end.

reload(Module, File, NewBin) ->
    Loaded = loaded_md5(Module),
    case beam_lib:md5(NewBin) of
        {ok, {Module, Loaded}} ->
            {error, {unchanged, Module}};
        {ok, {Module, _}} ->
            Old = old_code(Module, Loaded),
            case code:soft_purge(Module) of
                false -> {error, {old_code_in_use, Module}};
                true -> with_suspended(running(Module), Module, File, NewBin, Old)
            end;
        {ok, {Other, _}} ->
            {error, {load_failed, {Module, {module_name, Other}}}};
        {error, beam_lib, Why} ->
            {error, {load_failed, {Module, Why}}}
    end.

%% The behaviors and devices running `Module', by name.
running(Module) ->
    {W, _} = toroco_wiring:call(wiring),
    [{N, P} || {N, #{module := M}} <- lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
               M =:= Module, P <- [whereis(toroco_names:process(N))], is_pid(P)].

with_suspended(Running, Module, File, NewBin, Old) ->
    case suspend(Running, []) of
        {ok, Suspended} ->
            try
                OldVsn = module_vsn(Module),
                Saved = [{N, P, sys:get_state(P, ?TIMEOUT)} || {N, P} <- Suspended],
                case code:load_binary(Module, File, NewBin) of
                    {module, Module} -> change(Module, OldVsn, Saved, Old, {File, NewBin});
                    {error, Why} -> {error, {load_failed, {Module, Why}}}
                end
            after
                resume(Suspended)
            end;
        {error, _} = Err ->
            Err
    end.

%% Suspends in name order; on a failure the ones already suspended go on.
suspend([], Acc) ->
    {ok, lists:reverse(Acc)};
suspend([{N, P} | Rest], Acc) ->
    try sys:suspend(P, ?TIMEOUT) of
        ok -> suspend(Rest, [{N, P} | Acc])
    catch
        exit:{noproc, _} ->
            %% Died meanwhile: its restart runs the new code from init/1.
            suspend(Rest, Acc);
        exit:{Reason, _} ->
            resume(Acc),
            {error, {suspend_failed, {N, Reason}}}
    end.

resume(Suspended) ->
    _ = [catch sys:resume(P, ?TIMEOUT) || {_, P} <- Suspended],
    ok.

change(Module, OldVsn, Saved, Old, {File, NewBin}) ->
    Results = [{N, P, St, catch sys:change_code(P, toroco_behavior, OldVsn, [], ?TIMEOUT)}
               || {N, P, St} <- Saved],
    case [{N, reason(R)} || {N, _, _, R} <- Results, R =/= ok] of
        [] ->
            keep(Module, File, NewBin);
        Failed when Old =:= none ->
            logger:error("toroco: reload of ~p: code_change failed in ~p; the old code was "
                         "not kept, so the new code stays", [Module, Failed],
                         #{domain => [toroco, reload]}),
            {error, {code_change_failed, Failed, old_code_not_kept}};
        Failed ->
            %% States first, while everyone is still suspended: the processes
            %% whose code_change succeeded hold states of the new shape.
            _ = [sys:replace_state(P, fun(_) -> St end, ?TIMEOUT)
                 || {_, P, St, ok} <- Results],
            rollback(Module, Old),
            logger:error("toroco: reload of ~p: code_change failed in ~p; the old code and "
                         "every state are back", [Module, Failed], #{domain => [toroco, reload]}),
            {error, {code_change_failed, Failed}}
    end.

%% What sys:change_code/5 returned or raised, without stack traces.
reason({error, {'EXIT', {Reason, Stack}}}) when is_list(Stack) -> Reason;
reason({error, {'EXIT', Reason}}) -> Reason;
reason({error, Reason}) -> Reason;
reason({'EXIT', {Reason, _}}) -> Reason;
reason(Other) -> Other.

rollback(Module, {File, Bin}) ->
    %% The previous code (the old code now) is run by nobody: every process
    %% of the module is suspended in sys, outside the module.
    _ = code:soft_purge(Module),
    case code:load_binary(Module, File, Bin) of
        {module, Module} -> ok;
        {error, Why} ->
            logger:error("toroco: reload of ~p: the old code could not be loaded back: ~p",
                         [Module, Why], #{domain => [toroco, reload]})
    end.

%%====================================================================
%% Kept object code
%%====================================================================

%% The object code in memory before the reload: kept, or still on disk.
old_code(Module, MD5) ->
    case kept_code(Module) of
        {MD5, F, Bin} -> {F, Bin};
        _ ->
            case disk_code(Module, MD5) of
                {ok, F, Bin} -> {F, Bin};
                none -> none
            end
    end.

keep_from_disk(Module, MD5) ->
    case disk_code(Module, MD5) of
        {ok, F, Bin} -> persistent_term:put({?MODULE, Module}, {MD5, F, Bin});
        none -> ok
    end.

disk_code(Module, MD5) ->
    case code:which(Module) of
        F when is_list(F) ->
            case file:read_file(F) of
                {ok, Bin} ->
                    case beam_lib:md5(Bin) of
                        {ok, {Module, MD5}} -> {ok, F, Bin};
                        _ -> none
                    end;
                {error, _} -> none
            end;
        _ -> none
    end.

keep(Module, File, Bin) ->
    case beam_lib:md5(Bin) of
        {ok, {Module, MD5}} -> persistent_term:put({?MODULE, Module}, {MD5, File, Bin});
        _ -> ok
    end.

-spec kept_code(module()) -> kept_code() | undefined.
kept_code(Module) ->
    persistent_term:get({?MODULE, Module}, undefined).

loaded_md5(Module) ->
    case code:is_loaded(Module) of
        {file, _} ->
            try Module:module_info(md5)
            catch error:_ -> undefined
            end;
        false -> undefined
    end.

module_vsn(Module) ->
    case lists:keyfind(vsn, 1, Module:module_info(attributes)) of
        {vsn, [V]} -> V;
        {vsn, V} -> V;
        false -> undefined
    end.
