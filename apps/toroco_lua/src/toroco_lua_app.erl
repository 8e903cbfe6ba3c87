%% @doc The `toroco_lua' application: starts {@link toroco_lua_sup}.
-module(toroco_lua_app).
-behaviour(application).

-export([start/2, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    toroco_lua_sup:start_link().

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
