%% @doc A test-only behavior for the properties: one output `out', no inputs,
%% driven from outside. `toroco:inject/3' drives its sends and sets; the call
%% `{prop_emit, Actions}' makes it return toroco actions from a callback (the
%% only way to `unset' from outside), so the real action path is exercised.
-module(prop_emitter).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4, handle_event/4, emit/2]).

%% @doc Makes behavior `Name' return `Actions' from a callback.
emit(Name, Actions) ->
    gen_statem:call(toroco_names:process(Name), {prop_emit, Actions}, 5000).

interface() -> #{inputs => [], outputs => [out]}.

init(_Params) -> {ok, emitting, #{}}.

handle_input(_Input, _Value, _State, _Data) -> keep_state_and_data.

handle_event({call, From}, {prop_emit, Actions}, _State, _Data) ->
    {keep_state_and_data, Actions ++ [{reply, From, ok}]};
handle_event(_Type, _Content, _State, _Data) ->
    keep_state_and_data.
