%% @doc The `toroco_live' application: what a person looks at. It depends on
%% the runtime (`toroco'); the runtime never depends on it.
-module(toroco_live_app).
-behaviour(application).

-export([start/2, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    toroco_live_sup:start_link().

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
