%% @doc Supervises the behaviors of one layer. When they crash more often than
%% the layer's restart intensity allows (app env `layer_restart_intensity',
%% {MaxRestarts, Seconds}, default {5, 10}), the whole layer is taken out.
%% In lockstep those seconds are simulated ones: `toroco_lockstep' counts
%% the restarts and takes the layer out ({@link toroco_layers_sup:take_out/1}).
-module(toroco_layer_sup).
-behaviour(supervisor).

-export([start_link/1, init/1, mode/1]).

-define(MODE, '$toroco_clock_mode').
-define(LIFTED, 1000000).

-spec start_link(non_neg_integer()) -> {ok, pid()} | {error, term()}.
start_link(L) ->
    supervisor:start_link(?MODULE, L).

-spec init(non_neg_integer()) -> {ok, {supervisor:sup_flags(), []}}.
init(_L) ->
    %% one_for_one: behaviors of a layer are independent; the layer as a whole
    %% fails only by exhausting its intensity.
    %% In lockstep the intensity counts simulated time, and toroco_lockstep
    %% keeps it (SPEC §17): this supervisor's own, in real time, is lifted.
    {R, P} = case toroco_clock:mode() of
                 lockstep -> {?LIFTED, 1};
                 realtime -> application:get_env(toroco, layer_restart_intensity, {5, 10})
             end,
    put(?MODE, toroco_clock:mode()),
    {ok, {#{strategy => one_for_one, intensity => R, period => P}, []}}.

%% @doc The clock the layer's supervisor `Pid' was started under: its
%% restart intensity counts that clock's time.
-spec mode(pid()) -> realtime | lockstep | undefined.
mode(Pid) ->
    case erlang:process_info(Pid, dictionary) of
        {dictionary, D} -> proplists:get_value(?MODE, D);
        undefined -> undefined
    end.
