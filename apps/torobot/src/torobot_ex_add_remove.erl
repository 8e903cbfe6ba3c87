%% @doc The controller of the verification program "add and remove" (thesis
%% §5.3): a left press removes behavior `target' with
%% `toroco:remove_behavior/1'; a right press adds it back with
%% `toroco:add_behavior/3' and wires it again with `toroco:set_inputs/2', all
%% from inside this behavior's callback. Each change is reported on `status'
%% as `removed' or `added'.
%%
%% Params: `target' (the name), `module' and `opts' (as given to
%% `toroco:add_behavior/3'), and `wiring', a list of `{Receiver, Inputs}'
%% applied with `toroco:set_inputs(Receiver, Inputs)' after the add: both the
%% target's own inputs and the inputs of others that it feeds, since removal
%% strips the name from every list and adding it back does not re-attach it.
%%
%% Inputs `left' and `right' (the mouse), output `status'. States `present'
%% and `absent' mirror the target's, so repeated presses of one button do
%% nothing. An add whose wiring is refused is undone and logged.
-module(torobot_ex_add_remove).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [left, right], outputs => [status]}.

-spec init(map()) -> {ok, present, map()}.
init(Params) ->
    {ok, present, #{target => maps:get(target, Params, echo),
                    module => maps:get(module, Params, torobot_ex_release_echo),
                    opts => maps:get(opts, Params, #{}),
                    wiring => maps:get(wiring, Params, [])}}.

-spec handle_input(left | right, term(), present | absent, map()) ->
          toroco_behavior:result().
handle_input(left, pressed, present, D = #{target := T}) ->
    case toroco:remove_behavior(T) of
        ok ->
            {next_state, absent, D, [{send, #{status => removed}}]};
        {error, Reason} ->
            logger:warning("torobot_ex_add_remove: removing ~p refused: ~p", [T, Reason]),
            keep_state_and_data
    end;
handle_input(right, pressed, absent, D) ->
    case add(D) of
        ok ->
            {next_state, present, D, [{send, #{status => added}}]};
        {error, Reason} ->
            logger:warning("torobot_ex_add_remove: adding ~p back refused: ~p",
                           [maps:get(target, D), Reason]),
            keep_state_and_data
    end;
handle_input(_Button, _Event, _State, _Data) ->
    keep_state_and_data.

add(#{target := T, module := M, opts := Opts, wiring := Wiring}) ->
    case toroco:add_behavior(T, M, Opts) of
        ok ->
            case wire(Wiring) of
                ok -> ok;
                {error, _} = Err -> _ = toroco:remove_behavior(T), Err
            end;
        {error, _} = Err ->
            Err
    end.

wire([]) -> ok;
wire([{Receiver, Inputs} | Rest]) ->
    case toroco:set_inputs(Receiver, Inputs) of
        ok -> wire(Rest);
        {error, _} = Err -> Err
    end.
