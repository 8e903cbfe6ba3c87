%% @doc The top of `toroco_lua''s tree: one child, {@link toroco_lua_port},
%% the owner of the `lua_port' program that hosts every Lua behavior's state.
%%
%% The Lua behaviors themselves are not here: they are behaviors like any
%% other, in their layers' supervisors under `toroco'. They watch the owner:
%% when the program they live in goes (or the owner with it), each starts
%% its Lua code again in the next one, in its own process, so that their
%% layers see no failure (toroco_lua).
-module(toroco_lua_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> supervisor:startlink_ret().
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    %% one child: the strategy matters only for its restart intensity
    {ok, {#{strategy => one_for_one, intensity => 10, period => 10},
          [#{id => toroco_lua_port, start => {toroco_lua_port, start_link, []},
             restart => permanent, shutdown => 5000, type => worker,
             modules => [toroco_lua_port]}]}}.
