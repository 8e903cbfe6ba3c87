%% @doc Keeps the wiring server running: the last child of `toroco_sup'.
%%
%% The wiring server keeps nothing it cannot read back from `toroco_store',
%% so restarting it is cheap and harmless; its own supervisor lets it
%% restart often (`wiring_restart_intensity', default 100 in 10 s) without
%% taking the robot with it. Past that it is a crash loop, and `toroco_sup'
%% decides.
-module(toroco_wiring_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    {R, P} = application:get_env(toroco, wiring_restart_intensity, {100, 10}),
    {ok, {#{strategy => one_for_one, intensity => R, period => P},
          [#{id => toroco_wiring, start => {toroco_wiring, start_link, []},
             type => worker, shutdown => 5000, modules => [toroco_wiring]}]}}.
