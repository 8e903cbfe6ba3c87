%% @doc Supervises the routers (one per wired input) and the inhibition gates
%% (one per inhibited output or same-layer pair). Children are added and
%% removed by `toroco_wiring'; a crashed router or gate is restarted and
%% recovers its latches from its upstreams.
%%
%% All its children are the one consumer shell (`toroco_consumer'), so it
%% keeps them as `simple_one_for_one' children: a pid and its start
%% arguments each (about 200 bytes) instead of a full child record (about
%% 450), which counts at ten thousand wired inputs. A consumer is found by
%% its registered name. One whose configuration is gone from the wiring
%% table when it (re)starts stops at once with reason `normal', and being
%% `transient' it is not started again: that closes the window where a
%% consumer being unwired is restarting at the same moment.
-module(toroco_routers_sup).
-behaviour(supervisor).

-export([start_link/0, start_consumer/3, stop_consumer/2, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

%% @doc Starts the consumer of `Key' run by `Mod' (`toroco_router' or
%% `toroco_gate'); `{error, {already_started, Pid}}' if it runs.
-spec start_consumer(module(), toroco_consumer:key(), pid() | none) ->
          {ok, pid() | undefined} | {error, term()}.
start_consumer(Mod, Key, Caller) ->
    supervisor:start_child(?MODULE, [Mod, Key, Caller]).

%% @doc Stops the consumer of `Key' run by `Mod', if it runs. Its
%% configuration must be gone from the wiring table first, so that a
%% restart racing with this ends at once.
-spec stop_consumer(module(), toroco_consumer:key()) -> ok.
stop_consumer(Mod, Key) ->
    case whereis(Mod:reg(Key)) of
        undefined -> ok;
        Pid -> _ = supervisor:terminate_child(?MODULE, Pid), ok
    end.

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    %% Wires are independent of each other. Routers are mechanical and cheap
    %% to restart, so the intensity is generous (app env
    %% `router_restart_intensity', {MaxRestarts, Seconds}).
    {R, P} = application:get_env(toroco, router_restart_intensity, {1000, 10}),
    {ok, {#{strategy => simple_one_for_one, intensity => R, period => P},
          [#{id => consumer, start => {toroco_consumer, start_link, []},
             restart => transient, shutdown => 1000, type => worker,
             modules => [toroco_consumer, toroco_router, toroco_gate]}]}}.
