%% @doc The keeper of the runtime's tables: it owns them and does nothing
%% else, so they outlive a crash of the processes that write them.
%%
%% It is the first child of `toroco_sup'. Its tables:
%% <ul>
%% <li>`toroco_wiring': the wiring server's table (the configuration of each
%%     router and gate, the consumers of each emitter) and its own state, so
%%     that a crashed wiring server comes back with the wiring it had;</li>
%% <li>`toroco_lives': per behavior or device, how often it was started in
%%     its current life and how often it was restarted (`toroco_restarts').</li>
%% </ul>
-module(toroco_store).
-behaviour(gen_server).

-export([start_link/0]).
-export([init/1, handle_call/3, handle_cast/2]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], [{hibernate_after, 1000}]).

-spec init([]) -> {ok, []}.
init([]) ->
    %% Compressed: read when a consumer starts or is re-wired, never per
    %% event, and at ten thousand behaviors its rows are the largest part of
    %% the runtime's memory outside processes (about 560 bytes per behavior
    %% with its router, 320 compressed).
    _ = ets:new(toroco_wiring, [named_table, public, set, compressed, {read_concurrency, true}]),
    _ = ets:new(toroco_lives, [named_table, public, set, {write_concurrency, true}]),
    {ok, []}.

-spec handle_call(term(), gen_server:from(), []) -> {reply, {error, unknown_request}, []}.
handle_call(_Req, _From, S) ->
    {reply, {error, unknown_request}, S}.

-spec handle_cast(term(), []) -> {noreply, []}.
handle_cast(_Msg, S) ->
    {noreply, S}.
