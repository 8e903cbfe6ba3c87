%% @doc The root of the runtime, drawn as the thesis draws a robot:
%%
%% ```
%% toroco_sup (rest_for_one)
%% ├── pg (scope toroco_world_pg) the subscribers to a simulated world's snapshots
%% ├── toroco_store          owns the tables (wiring, lives): they outlive their writers
%% ├── toroco_tap            the observer tap's subscriptions (SPEC §10)
%% ├── pg (scope toroco_tap_pg) where the network's processes hear of subscription changes
%% ├── toroco_lockstep       the clock of a simulated world in lockstep (SPEC §14)
%% ├── toroco_routers_sup    one router per wired input, one gate per inhibited output
%% ├── toroco_devices_sup    sensors and actuators (layer 0)
%% ├── toroco_layers_sup     one supervisor per layer
%% │   ├── toroco_layer_sup 0    behaviors of layer 0
%% │   ├── toroco_layer_sup 1    behaviors of layer 1 ...
%% ├── pg (scope toroco)     where the wiring servers of connected nodes meet (SPEC §13)
%% └── toroco_wiring_sup
%%     └── toroco_wiring     the wiring server: validates and applies changes
%% '''
%%
%% Children are started in that order and depend on the ones before them.
%% The world's scope comes first, so that no other child's restart takes
%% its subscribers away. The wiring server comes last: it is never on the
%% event path, and when it crashes it comes back alone, with the wiring it
%% kept in `toroco_store's table, while the robot keeps running.
-module(toroco_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    %% rest_for_one: everything after the store reads its tables, and the
    %% processes of a wire (routers, gates) must exist before their ends.
    Flags = #{strategy => rest_for_one, intensity => 3, period => 10},
    Sup = fun(Mod) -> #{id => Mod, start => {Mod, start_link, []}, type => supervisor,
                        shutdown => infinity, modules => [Mod]} end,
    Worker = fun(Mod) -> #{id => Mod, start => {Mod, start_link, []}, type => worker,
                           shutdown => 5000, modules => [Mod]} end,
    {ok, {Flags, [#{id => pg_world, start => {pg, start_link, [toroco_world_pg]}, type => worker,
                    shutdown => 5000, modules => [pg]},
                  Worker(toroco_store),
                  Worker(toroco_tap),
                  #{id => pg_tap, start => {pg, start_link, [toroco_tap_pg]}, type => worker,
                    shutdown => 5000, modules => [pg]},
                  Worker(toroco_lockstep),
                  Sup(toroco_routers_sup),
                  Sup(toroco_devices_sup),
                  Sup(toroco_layers_sup),
                  #{id => pg, start => {pg, start_link, [toroco]}, type => worker,
                    shutdown => 5000, modules => [pg]},
                  Sup(toroco_wiring_sup)]}}.
