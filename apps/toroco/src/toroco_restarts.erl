%% @doc How often each behavior and device was restarted, for
%% `toroco:top()', and whether a starting process is a first start or a
%% restart, for the observer tap's lifecycle events (SPEC §10).
%%
%% The engine asks {@link started/1} as each incarnation starts: the first
%% start after the wiring server added the name is `started', every later
%% one (a supervisor restart, or a reset that re-ran init/1 in a new
%% process) is `restarted' and counted. The counts live in the `toroco_lives'
%% table of `toroco_store', so they are there whatever the log level, and a
%% count survives `remove' and a later `add' of the same name.
-module(toroco_restarts).

-export([added/1, started/1, count/1]).

-define(TABLE, toroco_lives).

%% @doc The wiring server added `Name': its next start is a first start.
-spec added(atom()) -> ok.
added(Name) ->
    _ = ets:update_element(?TABLE, Name, {2, 0}) orelse ets:insert_new(?TABLE, {Name, 0, 0}),
    ok.

%% @doc An incarnation of `Name' is starting: `started' the first time in
%% its life, `restarted' (and counted) after that.
-spec started(atom()) -> started | restarted.
started(Name) ->
    try ets:update_counter(?TABLE, Name, {2, 1}, {Name, 0, 0}) of
        1 -> started;
        _ -> _ = ets:update_counter(?TABLE, Name, {3, 1}), restarted
    catch error:badarg -> started
    end.

%% @doc Restarts of behavior or device `Name' since the node started.
-spec count(atom()) -> non_neg_integer().
count(Name) ->
    try ets:lookup(?TABLE, Name) of
        [{_, _, N}] -> N;
        [] -> 0
    catch error:badarg -> 0
    end.
