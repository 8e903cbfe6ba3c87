%% @doc The `toroco_rec' application: the robot's events as data (their
%% JSON, their Foxglove channels, the tap's client) and files of them
%% (MCAP recordings, the flight recorder, replay). It depends on the
%% runtime (`toroco') only; `toroco_live' and `toroco_ros' are built on it.
-module(toroco_rec_app).
-behaviour(application).

-export([start/2, stop/1]).

-spec start(application:start_type(), term()) -> {ok, pid()} | {error, term()}.
start(_Type, _Args) ->
    toroco_rec_sup:start_link().

-spec stop(term()) -> ok.
stop(_State) ->
    ok.
