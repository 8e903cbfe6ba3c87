%% @doc A sensor driven by hand: its outputs are whatever
%% `toroco:inject({Name, Out}, Value)' says, or follow a script.
%%
%% Options: `outputs' (required, the output names) and `script', a list of
%% `{AfterMs, Out, Value}' steps, each `AfterMs' counted from the previous
%% step; a step may carry emit options, `{AfterMs, Out, Value, #{latch => true}}'
%% or `#{hold => Ms}'. Usable from the shell and from tests alike.
-module(toroco_fake_sensor).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, handle_event/4, info/2]).

-spec interface(map()) -> #{inputs := [], outputs := [atom()]}.
interface(#{outputs := Outs}) when is_list(Outs) -> #{inputs => [], outputs => Outs};
interface(Opts) -> error({bad_option, {outputs, maps:get(outputs, Opts, missing)}}).

-spec init(atom(), map()) -> {ok, sensing, map(), toroco_behavior:actions()} | {error, term()}.
init(Name, Opts) ->
    Script = maps:get(script, Opts, []),
    case is_list(Script) andalso lists:all(fun valid_step/1, Script) of
        true -> {ok, sensing, #{name => Name, script => Script, steps => 0}, next(Script)};
        false -> {error, {bad_option, {Name, script}}}
    end.

valid_step({Ms, Out, _V}) -> is_integer(Ms) andalso Ms >= 0 andalso is_atom(Out);
valid_step({Ms, Out, _V, O}) -> valid_step({Ms, Out, x}) andalso is_map(O);
valid_step(_) -> false.

next([]) -> [];
next([Step | _]) -> [{state_timeout, element(1, Step), step}].

-spec handle_input(atom(), term(), sensing, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _Data) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), sensing, map()) -> toroco_behavior:result().
handle_event(state_timeout, step, _State, D = #{script := [Step | Rest], steps := N}) ->
    {keep_state, D#{script := Rest, steps := N + 1}, [action(Step) | next(Rest)]}.

action({_, Out, V}) -> {send, #{Out => V}};
action({_, Out, V, #{latch := true}}) -> {set, #{Out => V}};
action({_, Out, V, Opts}) -> {send, #{Out => V}, maps:with([hold], Opts)}.

-spec info(sensing, map()) -> map().
info(_State, #{steps := N, script := Left}) ->
    #{script_steps_done => N, script_steps_left => length(Left)}.
