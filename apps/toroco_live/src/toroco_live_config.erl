%% @doc The running dashboard's configuration (ports, token, limits), kept
%% in `persistent_term' so each HTTP request reads it without a call to
%% any process. Written by `toroco_live:start/1' and the dashboard's
%% supervisor, read by the request handlers and the hub. The token is
%% checked by `toroco_live_auth' only.
-module(toroco_live_config).

-export([set/1, current/0, get/2, clear/0]).

-define(KEY, {?MODULE, config}).

-spec set(map()) -> ok.
set(Config) ->
    persistent_term:put(?KEY, Config).

-spec current() -> map() | undefined.
current() ->
    persistent_term:get(?KEY, undefined).

-spec get(atom(), term()) -> term().
get(Key, Default) ->
    case current() of
        undefined -> Default;
        Config -> maps:get(Key, Config, Default)
    end.

-spec clear() -> ok.
clear() ->
    _ = persistent_term:erase(?KEY),
    ok.
