%% @doc The `toroco' application: starts `toroco_sup'.
-module(toroco_app).
-behaviour(application).

-export([start/2, prep_stop/1, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    toroco_sup:start_link().

%% Layers shut down from here on are being stopped, not taken out.
-spec prep_stop(term()) -> term().
prep_stop(State) ->
    catch toroco_wiring:stopping(),
    State.

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
