%% @doc The controller of the verification program "suspend and resume"
%% (thesis §5.3): a left press suspends behavior `target' (param, default
%% `display') with `toroco:suspend_behavior/1', a right press resumes it with
%% `toroco:resume_behavior/1'; each change is reported on `status' as
%% `suspended' or `resumed'.
%%
%% Inputs `left' and `right' (the mouse), output `status'. States `running'
%% and `suspended' mirror the target's, so a second left press while it is
%% suspended (or a right press while it runs) does nothing and reports
%% nothing. The calls are made from inside the callback: the runtime lets a
%% behavior drive the API at run time.
-module(torobot_ex_suspender).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [status]}.

-spec init(map()) -> {ok, running, #{target := atom()}}.
init(Params) -> {ok, running, #{target => maps:get(target, Params, display)}}.

-spec handle_input(left | right, term(), running | suspended, map()) ->
          toroco_behavior:result().
handle_input(left, pressed, running, D = #{target := T}) ->
    change(toroco:suspend_behavior(T), suspended, D);
handle_input(right, pressed, suspended, D = #{target := T}) ->
    change(toroco:resume_behavior(T), resumed, D);
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.

change(ok, suspended, D) ->
    {next_state, suspended, D, [{send, #{status => suspended}}]};
change(ok, resumed, D) ->
    {next_state, running, D, [{send, #{status => resumed}}]};
change({error, Reason}, What, #{target := T}) ->
    logger:warning("torobot_ex_suspender: ~p of ~p refused: ~p", [What, T, Reason]),
    keep_state_and_data.
