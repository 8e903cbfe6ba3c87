%% @doc Supervises one `toroco_layer_sup' per layer. Layers are `temporary':
%% a layer that exceeds its restart intensity stays out (graceful degradation:
%% the layers below keep running) and `toroco_wiring' reports it.
-module(toroco_layers_sup).
-behaviour(supervisor).

-export([start_link/0, start_layer/1, restart/2, take_out/1, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

%% @doc Starts the supervisor of layer `L' (a fresh one if `L' was taken out).
-spec start_layer(non_neg_integer()) -> {ok, pid()} | {error, term()}.
start_layer(L) ->
    _ = supervisor:delete_child(?MODULE, {layer, L}),
    supervisor:start_child(?MODULE, #{id => {layer, L},
                                      start => {toroco_layer_sup, start_link, [L]},
                                      restart => temporary, type => supervisor,
                                      shutdown => infinity, modules => [toroco_layer_sup]}).

%% @doc Takes layer `L' out as its supervisor does when its restart
%% intensity is spent (in lockstep, where `toroco_lockstep' counts the
%% restarts in simulated time); the wiring server sees it go.
-spec take_out(non_neg_integer()) -> ok | {error, not_found}.
take_out(L) ->
    supervisor:terminate_child(?MODULE, {layer, L}).

%% @doc Stops behavior `Name' of layer `L' and starts it again, through
%% its layer's supervisor (not a crash: the layer's intensity is not spent).
-spec restart(non_neg_integer(), atom()) -> ok | {error, term()}.
restart(L, Name) ->
    case [Pid || {{layer, L1}, Pid, _, _} <- supervisor:which_children(?MODULE),
                 L1 =:= L, is_pid(Pid)] of
        [Sup] ->
            case supervisor:terminate_child(Sup, Name) of
                ok ->
                    case supervisor:restart_child(Sup, Name) of
                        {ok, _} -> ok;
                        {ok, _, _} -> ok;
                        {error, Reason} -> {error, {restart_failed, {Name, Reason}}}
                    end;
                {error, not_found} -> {error, {not_running, Name}}
            end;
        [] ->
            {error, {layer_removed, {Name, L}}}
    end.

-spec init([]) -> {ok, {supervisor:sup_flags(), []}}.
init([]) ->
    {ok, {#{strategy => one_for_one, intensity => 0, period => 1}, []}}.
