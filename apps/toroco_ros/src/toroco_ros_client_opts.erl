%% @doc A rosbridge client's URL and options (`toroco_ros:connect/2',
%% `toroco_ros_client'), checked before it is started: pure but for
%% starting `ssl' for a `wss://' URL and looking at the CA file.
%%
%% The URL is `ws://host[:port][/path][?query]' or `wss://...'; what is
%% shown of it leaves out the query (it may hold a token). Over `wss://'
%% the server's certificate is checked against `cacertfile' or a pinned
%% SHA-256 `fingerprint', and a `wss://' URL with neither is refused.
-module(toroco_ros_client_opts).

-export([options/2]).

-define(DEFAULTS, #{max_queue => 1000, backoff_min => 250, backoff_max => 30000,
                    connect_timeout => 5000, max_message => 1048576}).

%% @doc The URL parsed (the URL without its query, as shown, the host, the
%% port, the resource asked for) and the options with their defaults (and
%% `verify', how the certificate is checked), or the first thing wrong:
%% `{bad_url, Url}', `{unsupported_scheme, S}', `{bad_option, {Key,
%% Value}}', `{unverified_wss, Why}' (`wss://' without `cacertfile' nor
%% `fingerprint'), `{tls_options_without_wss, Why}'.
-spec options(term(), term()) ->
          {ok, {binary(), string(), inet:port_number(), binary()}, map()} | {error, term()}.
options(Url, Opts) when is_map(Opts) ->
    case parse_url(Url) of
        {ok, {Scheme, Parsed}} ->
            Bad = [{K, V} || {K, V} <- lists:sort(maps:to_list(Opts)), not option(K, V)],
            case {Bad, verify(Scheme, Opts)} of
                {[], {ok, Verify}} -> {ok, Parsed, maps:merge(?DEFAULTS, Opts#{verify => Verify})};
                {[], {error, _} = E} -> E;
                {[First | _], _} -> {error, {bad_option, First}}
            end;
        {error, _} = E -> E
    end;
options(_Url, Opts) ->
    {error, {bad_option, Opts}}.

option(K, V) when K =:= max_queue; K =:= backoff_min; K =:= backoff_max; K =:= connect_timeout;
                  K =:= max_message ->
    is_integer(V) andalso V > 0;
option(cacertfile, F) -> (is_list(F) orelse is_binary(F)) andalso filelib:is_regular(F);
option(fingerprint, F) -> pin(F) =/= error;
option(_, _) -> false.

%% How the server's certificate is checked: not at all for ws://; for
%% wss:// against `cacertfile' or the pinned `fingerprint', and refused
%% with neither (an unchecked certificate is no better than ws://).
verify(<<"ws">>, Opts) ->
    case maps:with([cacertfile, fingerprint], Opts) of
        M when map_size(M) =:= 0 -> {ok, none};
        _ -> {error, {tls_options_without_wss, <<"cacertfile and fingerprint are for wss:// URLs">>}}
    end;
verify(<<"wss">>, #{cacertfile := _, fingerprint := _}) ->
    {error, {bad_option, {fingerprint, <<"give cacertfile or fingerprint, not both">>}}};
verify(<<"wss">>, #{cacertfile := F}) ->
    case application:ensure_all_started(ssl) of
        {ok, _} -> {ok, {cacertfile, F}};
        {error, Why} -> {error, {ssl_not_started, Why}}
    end;
verify(<<"wss">>, #{fingerprint := F}) ->
    case application:ensure_all_started(ssl) of
        {ok, _} -> {ok, {fingerprint, pin(F)}};
        {error, Why} -> {error, {ssl_not_started, Why}}
    end;
verify(<<"wss">>, _) ->
    {error, {unverified_wss, <<"wss:// needs the server's certificate checked: "
                               "#{cacertfile => File} or #{fingerprint => Sha256}">>}}.

%% A SHA-256 fingerprint: 32 bytes, or 64 hex digits (colons allowed, as
%% openssl and scripts/tls-cert print it).
pin(F) when is_binary(F), byte_size(F) =:= 32 -> F;
pin(F) when is_list(F) -> pin(unicode:characters_to_binary(F));
pin(F) when is_binary(F) ->
    Hex = binary:replace(F, <<":">>, <<>>, [global]),
    case byte_size(Hex) =:= 64 andalso
        lists:all(fun(C) -> lists:member(C, "0123456789abcdefABCDEF") end, binary_to_list(Hex)) of
        true -> binary:decode_hex(Hex);
        false -> error
    end;
pin(_) -> error.

parse_url(Url) when is_list(Url) ->
    case unicode:characters_to_binary(Url) of
        B when is_binary(B) -> parse_url(B);
        _ -> {error, {bad_url, Url}}
    end;
parse_url(Url) when is_binary(Url) ->
    case uri_string:parse(Url) of
        #{scheme := Scheme, host := Host} = U when (Scheme =:= <<"ws">> orelse Scheme =:= <<"wss">>),
                                                   Host =/= <<>> ->
            Path = case maps:get(path, U, <<>>) of
                       <<>> -> <<"/">>;
                       P -> P
                   end,
            Resource = case U of
                           #{query := Q} -> <<Path/binary, $?, Q/binary>>;
                           #{} -> Path
                       end,
            %% what is shown (logs, /api/state, /metrics) leaves out the
            %% query: it may hold a token
            Shown = uri_string:recompose(maps:without([query, fragment], U)),
            Default = case Scheme of <<"ws">> -> 80; <<"wss">> -> 443 end,
            {ok, {Scheme, {Shown, binary_to_list(Host), maps:get(port, U, Default), Resource}}};
        #{scheme := Scheme} -> {error, {unsupported_scheme, Scheme}};
        _ -> {error, {bad_url, Url}}
    end;
parse_url(Url) ->
    {error, {bad_url, Url}}.
