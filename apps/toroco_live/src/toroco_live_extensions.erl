%% @doc What other applications add to `toroco_live' (API): the places
%% where an application built on `toroco_live' (`toroco_ros', SPEC §15)
%% plugs in, so that `toroco_live' offers its features without naming its
%% modules (the dependency goes one way: `toroco_ros' lists `toroco_live'
%% among its `applications', never the reverse).
%%
%% <table>
%% <tr><th>kind</th><th>name</th><th>value</th><th>used by</th></tr>
%% <tr><td>`metrics'</td><td>any atom</td><td>`{M, F}': `M:F()' returns the
%%   families it adds to `/metrics' (`toroco_live_metrics:family/4')</td><td>`GET /metrics'</td></tr>
%% <tr><td>`bridge'</td><td>its option key (`rosbridge')</td><td>`#{supervisor => Sup, id =>
%%   Id}': a `toroco_live_bridge' child of the other application's own supervisor</td>
%%   <td>`toroco_live:start/1', `stop/0' and `info/0' (the bridge listens on the
%%   key's port)</td></tr>
%% <tr><td>`client'</td><td>`rosbridge'</td><td>a module with `connect/2', `disconnect/1'
%%   and `clients/0'</td><td>`toroco_live:rosbridge_connect/2', `rosbridge_disconnect/1',
%%   `rosbridge_clients/0', `/api/state'</td></tr>
%% </table>
%%
%% An application adds its extensions when it starts and removes them when
%% it stops. They are kept in `persistent_term' (written at a start, read on
%% every request), so that reading them asks no process.
-module(toroco_live_extensions).

-export([add/3, remove/2, find/2, all/1]).

-export_type([kind/0]).

-type kind() :: metrics | bridge | client.

%% @doc Adds (or replaces) extension `Name' of `Kind'.
-spec add(kind(), atom(), term()) -> ok.
add(Kind, Name, Value) when is_atom(Name) ->
    persistent_term:put(key(Kind), maps:put(Name, Value, map(Kind))).

%% @doc Removes extension `Name' of `Kind'; `ok' also when there is none.
-spec remove(kind(), atom()) -> ok.
remove(Kind, Name) ->
    case map(Kind) of
        #{Name := _} = M -> persistent_term:put(key(Kind), maps:remove(Name, M));
        #{} -> ok
    end.

%% @doc Extension `Name' of `Kind'.
-spec find(kind(), atom()) -> {ok, term()} | error.
find(Kind, Name) ->
    maps:find(Name, map(Kind)).

%% @doc The extensions of `Kind', by name.
-spec all(kind()) -> [{atom(), term()}].
all(Kind) ->
    lists:sort(maps:to_list(map(Kind))).

key(Kind) -> {?MODULE, Kind}.

map(Kind) -> persistent_term:get(key(Kind), #{}).
