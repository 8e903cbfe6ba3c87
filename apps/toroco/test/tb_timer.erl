%% A test behavior with a named timeout and a partial handle_event/4: on
%% input `arm' it sets `{timeout, tick}' (param `ms', default 200), which
%% sends `ticked' when it fires; `handle_event/4' has a clause for the
%% timeout and for the info message `ping' (answered with `pong' on `out'),
%% nothing else.
-module(tb_timer).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4, handle_event/4]).

interface() -> #{inputs => [in], outputs => [out]}.

init(P) -> {ok, idle, P}.

handle_input(in, arm, _S, P) ->
    {next_state, armed, P, [{{timeout, tick}, maps:get(ms, P, 200), fire}]};
handle_input(in, _V, _S, _P) ->
    keep_state_and_data.

handle_event({timeout, tick}, fire, _S, _P) ->
    {keep_state_and_data, [{send, #{out => ticked}}]};
handle_event(info, ping, _S, _P) ->
    {keep_state_and_data, [{send, #{out => pong}}]}.
