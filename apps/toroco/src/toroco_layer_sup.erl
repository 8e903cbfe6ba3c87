%% @doc Supervises the behaviors of one layer. When they crash more often than
%% the layer's restart intensity allows (app env `layer_restart_intensity',
%% {MaxRestarts, Seconds}, default {5, 10}), the whole layer is taken out.
-module(toroco_layer_sup).
-behaviour(supervisor).

-export([start_link/1, init/1]).

-spec start_link(non_neg_integer()) -> {ok, pid()} | {error, term()}.
start_link(L) ->
    supervisor:start_link(?MODULE, L).

-spec init(non_neg_integer()) -> {ok, {supervisor:sup_flags(), []}}.
init(_L) ->
    %% one_for_one: behaviors of a layer are independent; the layer as a whole
    %% fails only by exhausting its intensity.
    {R, P} = application:get_env(toroco, layer_restart_intensity, {5, 10}),
    {ok, {#{strategy => one_for_one, intensity => R, period => P}, []}}.
