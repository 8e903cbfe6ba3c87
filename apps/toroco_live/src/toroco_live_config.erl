%% @doc The running dashboard's configuration (ports, token, limits), kept
%% in `persistent_term' so each HTTP request reads it without a call to
%% any process. Written by `toroco_live:start/1' and the dashboard's
%% supervisor, read by the request handlers and the hub.
-module(toroco_live_config).

-export([set/1, current/0, get/2, clear/0, authorized/1]).

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

%% @doc Whether `Presented' (the token a request carried, or `none') is the
%% dashboard's token. Compared in constant time.
-spec authorized(binary() | none) -> boolean().
authorized(none) ->
    false;
authorized(Presented) when is_binary(Presented) ->
    case get(token, undefined) of
        Token when is_binary(Token), byte_size(Token) =:= byte_size(Presented) ->
            crypto:hash_equals(Token, Presented);
        _ ->
            false
    end.
