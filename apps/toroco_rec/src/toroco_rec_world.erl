%% @doc (API) Where the simulated world's snapshots come from, a behaviour:
%% the flight recorder (`toroco_rec_flight') and the taps asking for the
%% world (`toroco_rec_tap', `world => true') subscribe to the source set
%% with {@link set/1}. `toroco_live_world' is one: it sets itself as it
%% starts, so `toroco_rec' reads the world without depending on the
%% application that keeps it.
%%
%% A source is a module whose process is registered under the module's
%% name. A subscriber gets `{Module, changed}' when a snapshot came (then
%% reads it with `latest/0', which re-arms the notification), and from
%% `subscribe_all/0' on every snapshot of a world in lockstep as `{Module,
%% at, Snapshot}' (the snapshot's shape: `toroco_live_world').
-module(toroco_rec_world).

-export([set/1, source/0, subscribe/1]).

-callback subscribe() -> ok.
-callback subscribe_all() -> ok.
-callback unsubscribe() -> ok.
-callback latest() -> map() | none.

-define(KEY, {?MODULE, source}).

%% @doc Makes `Module' the source; the flight recorder subscribes to it.
-spec set(module()) -> ok.
set(Module) when is_atom(Module) ->
    persistent_term:put(?KEY, Module),
    gen_server:cast(toroco_rec_flight, {world_source, Module}).

%% @doc The source set, `none' before any.
-spec source() -> module() | none.
source() ->
    persistent_term:get(?KEY, none).

%% @doc Calls `How' (`subscribe', `subscribe_all', `unsubscribe') of the
%% source for the caller, if its process runs; the source, or `none'.
-spec subscribe(subscribe | subscribe_all | unsubscribe) -> module() | none.
subscribe(How) ->
    case source() of
        none -> none;
        Module ->
            case whereis(Module) of
                undefined -> none;
                _ ->
                    _ = (catch Module:How()),
                    Module
            end
    end.
