%% @doc `toroco:reload/1': hot code reload of the behaviors running a module.
%%
%% Every behavior running `Module' is paused with `sys:suspend/1' (inputs
%% wait in its mailbox; this is not `toroco:suspend_behavior/1'), the module's
%% new object code is loaded, each behavior's `code_change/4' is called through
%% `sys:change_code/4', and all are resumed. Nothing is lost: latches live in
%% the behaviors' state and holds in the routers, and queued inputs are
%% handled after the resume, by the new code.
%%
%% The BEAM keeps one current version of a module for all processes, so a
%% failing `code_change' cannot leave just one behavior on the old code while
%% its siblings move on. The reload is therefore all or nothing: if any
%% behavior's `code_change' fails, the old object code is loaded back, every
%% behavior gets back its state from before the reload, and the error names
%% the behaviors that failed: `{error, {code_change_failed, [{Name, Reason}]}}'.
-module(toroco_reload).

-export([reload/1]).

-spec reload(module()) -> ok | {error, term()}.
reload(Module) when is_atom(Module) ->
    {W, _} = toroco_wiring:call(wiring),
    Names = [N || {N, #{module := M}} <- maps:to_list(toroco_wiring_core:nodes(W)), M =:= Module],
    Running = [{N, P} || N <- lists:sort(Names),
                         P <- [whereis(toroco_names:node(N))], is_pid(P)],
    case code:get_object_code(Module) of
        error -> {error, {no_object_code, Module}};
        {Module, NewBin, File} ->
            Old = old_code(Module),
            [sys:suspend(P) || {_, P} <- Running],
            try
                Saved = [{N, P, sys:get_state(P)} || {N, P} <- Running],
                _ = code:soft_purge(Module),
                case code:load_binary(Module, File, NewBin) of
                    {module, Module} -> change(Module, Saved, Old);
                    {error, Why} -> {error, {load_failed, {Module, Why}}}
                end
            after
                [catch sys:resume(P) || {_, P} <- Running]
            end
    end;
reload(Other) ->
    {error, {bad_module, Other}}.

change(Module, Saved, Old) ->
    Failed = [{N, R} || {N, P, _} <- Saved,
                        R <- [catch sys:change_code(P, toroco_behavior, undefined, [])],
                        R =/= ok],
    case Failed of
        [] -> ok;
        _ ->
            _ = [sys:replace_state(P, fun(_) -> St end) || {_, P, St} <- Saved],
            rollback(Module, Old),
            logger:error("toroco: reload of ~p failed in ~p; old code kept", [Module, Failed]),
            {error, {code_change_failed, Failed}}
    end.

%% The object code in memory before the reload, when it can be had.
old_code(Module) ->
    case code:is_loaded(Module) of
        {file, F} when is_list(F) ->
            case erlang:get_module_info(Module, md5) =:= beam_md5(F) of
                true -> {ok, F, element(2, file:read_file(F))};
                false -> none
            end;
        _ -> none
    end.

beam_md5(F) ->
    case beam_lib:md5(F) of
        {ok, {_, MD5}} -> MD5;
        _ -> undefined
    end.

rollback(_Module, none) -> ok;
rollback(Module, {ok, F, Bin}) ->
    _ = code:soft_purge(Module),
    _ = code:load_binary(Module, F, Bin),
    ok.
