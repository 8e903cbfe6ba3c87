%% @doc The dashboard's HTTP side: the listener and the routes ({@link
%% peer/1} and {@link token/1} are API, for the bridges' upgrades). Each
%% connection is a mochiweb process that calls {@link loop/1} per request;
%% the listener (`toroco_live_listener', registered as this module) bounds
%% them: request and idle timeouts, a share per client address, the
%% longest-idle shed when full, closes counted in `/metrics'.
%%
%% <table>
%% <tr><th>route</th><th>answers</th></tr>
%% <tr><td>`GET /'</td><td>the page (`priv/www/index.html')</td></tr>
%% <tr><td>`GET /assets/File'</td><td>the page's scripts and styles, built into `priv/www/assets'</td></tr>
%% <tr><td>`GET /api/state'</td><td>`inspect()' and `inspect(Name)' of every name (`toroco_live_state:api/0')</td></tr>
%% <tr><td>`GET /api/world'</td><td>the simulated world's latest frame, or 404 when none runs</td></tr>
%% <tr><td>`GET /metrics'</td><td>Prometheus text (`toroco_live_metrics')</td></tr>
%% <tr><td>`GET /ws'</td><td>the WebSocket the page lives on (`toroco_live_ws')</td></tr>
%% <tr><td>`POST /api/control'</td><td>a control (`toroco_live_control'); needs the token</td></tr>
%% </table>
%%
%% <b>Who may drive the robot.</b> Tools send `Authorization: Bearer T'. A
%% person opens the page once with `?token=T': that first visit is answered
%% with a session cookie (`HttpOnly', `SameSite=Strict', `Secure' under
%% TLS; `toroco_live_auth:session/1', not the token) and a 303
%% to the same address without the token, so the token leaves the address
%% bar, the history and whatever logs the address; the page's controls and
%% its WebSocket then carry the cookie. Every check goes through
%% `toroco_live_auth' (constant time, wrong tokens per address limited: 429
%% `too_many_failures' for a minute after ten; the WebSocket of a limited
%% address is read-only). A browser's request from
%% another page (its `Origin' not this server's own) may not drive the
%% robot nor open the WebSocket: 403 `cross_origin'. The token is never
%% logged (a handler that fails is logged by the listener by its path,
%% without the query).
%%
%% Every refusal is a JSON object `{"error": Reason, "message": Why}' with
%% a 4xx status; nothing is read or changed past the refusal.
-module(toroco_live_http).

-export([start_link/1, port/0, loop/1, token/1, peer/1]).

-define(NAME, ?MODULE).
-define(COOKIE, "toroco_session").

%% @doc Starts the bounded listener on the configured address and port,
%% with the bounds of `Config' (`toroco_live_listener''s options).
-spec start_link(map()) -> {ok, pid()} | {error, term()}.
start_link(#{http := Port} = Config) ->
    toroco_live_listener:start_link(?NAME, Config, Port, fun ?MODULE:loop/1).

%% @doc The port the listener got (the one asked for, or the free one for 0).
-spec port() -> inet:port_number().
port() ->
    toroco_live_listener:port(?NAME).

%% @doc Handles one request.
-spec loop(term()) -> term().
loop(Req) ->
    Method = mochiweb_request:get(method, Req),
    Path = mochiweb_request:get(path, Req),
    try route(Method, Path, Req)
    catch
        exit:{noproc, _} ->
            json(Req, 503, error_json(not_running, <<"the runtime (toroco) is not running">>));
        exit:{timeout, _} ->
            json(Req, 503, error_json(busy, <<"the runtime did not answer in time">>))
    end.

route('GET', "/", Req) ->
    case proplists:is_defined("token", mochiweb_request:parse_qs(Req)) of
        true -> first_visit(Req);
        false -> file(Req, "index.html")
    end;
route('GET', "/assets/" ++ File, Req) ->
    file(Req, filename:join("assets", File));
route('GET', "/api/state", Req) ->
    json(Req, 200, toroco_live_state:api());
route('GET', "/api/world", Req) ->
    case toroco_live_world:latest() of
        none -> json(Req, 404, error_json(no_world, <<"no simulated world has run here">>));
        Snap -> json(Req, 200, toroco_live_world_json:frame(Snap))
    end;
route('GET', "/metrics", Req) ->
    mochiweb_request:respond({200, [{"Content-Type", "text/plain; version=0.0.4"}],
                              toroco_live_metrics:text()}, Req);
route('GET', "/ws", Req) ->
    case {same_origin(Req), authorize(Req)} of
        {false, _} -> cross_origin(Req);
        %% watching needs no token: a limited address watches read-only
        {true, {limited, _}} -> toroco_live_ws:upgrade(Req, false);
        {true, Authorized} -> toroco_live_ws:upgrade(Req, Authorized)
    end;
route('POST', "/api/control", Req) ->
    case same_origin(Req) of
        true -> control(Req);
        false -> cross_origin(Req)
    end;
route(Method, Path, Req) when Path =:= "/"; Path =:= "/api/state"; Path =:= "/api/world";
                              Path =:= "/metrics"; Path =:= "/ws"; Path =:= "/api/control" ->
    json(Req, 405, error_json(method_not_allowed,
                              iolist_to_binary(io_lib:format("~s is not allowed on ~s",
                                                             [Method, Path]))));
route(_Method, Path, Req) ->
    json(Req, 404, error_json(unknown_route,
                              iolist_to_binary(["no route ", printable(Path),
                                                "; routes: / /api/state /api/world /metrics "
                                                "/ws /api/control"]))).

control(Req) ->
    Max = toroco_live_config:get(max_body, 16384),
    Result = case {authorize(Req), content_length(Req)} of
                 {{limited, Ms}, _} -> {limited, Ms};
                 {false, _} -> toroco_live_control:run(false, <<>>, Max);
                 {true, N} when is_integer(N), N > Max ->
                     toroco_live_control:too_large(N, Max);
                 {true, undefined} ->
                     {error, 411, length_required, <<"send Content-Length">>};
                 {true, _} ->
                     toroco_live_control:run(true, body(Req, Max), Max)
             end,
    case Result of
        {limited, Wait} -> too_many_failures(Req, Wait);
        {ok, Json} -> json(Req, 200, Json);
        {error, Status, Reason, Message} -> json(Req, Status, error_json(Reason, Message))
    end.

%% The first visit, `GET /?token=T': the session cookie for the right
%% token, and either way a 303 to the address without the token (a wrong
%% one gets the read-only page, and counts as a failure).
first_visit(Req) ->
    Token = unicode:characters_to_binary(
              proplists:get_value("token", mochiweb_request:parse_qs(Req))),
    Rest = [{K, V} || {K, V} <- mochiweb_request:parse_qs(Req), K =/= "token"],
    Location = case Rest of
                   [] -> "/";
                   _ -> "/?" ++ mochiweb_util:urlencode(Rest)
               end,
    case toroco_live_auth:authorize(peer(Req), {token, Token}) of
        {limited, Ms} ->
            too_many_failures(Req, Ms);
        Good ->
            Cookie = case Good of
                         true -> [{"Set-Cookie", session_cookie(Req)}];
                         false -> []
                     end,
            mochiweb_request:respond({303, [{"Location", Location}, {"Cache-Control", "no-store"},
                                            {"Referrer-Policy", "no-referrer"} | Cookie], <<>>},
                                     Req)
    end.

session_cookie(Req) ->
    Session = toroco_live_auth:session(toroco_live_config:get(token, <<>>)),
    Secure = case secure(Req) of
                 true -> "; Secure";
                 false -> ""
             end,
    ?COOKIE "=" ++ binary_to_list(Session) ++ "; Path=/; HttpOnly; SameSite=Strict" ++ Secure.

%% The request's credential: the bearer token, else the page's session.
credential(Req) ->
    case mochiweb_request:get_header_value("authorization", Req) of
        "Bearer " ++ T -> {token, list_to_binary(string:trim(T))};
        _ ->
            case mochiweb_request:get_cookie_value(?COOKIE, Req) of
                undefined -> none;
                S -> {session, list_to_binary(S)}
            end
    end.

authorize(Req) ->
    toroco_live_auth:authorize(peer(Req), credential(Req)).

%% @doc The client's address: the socket's peer, never a header a client
%% could write (mochiweb's `peer' believes `X-Forwarded-For').
-spec peer(term()) -> inet:ip_address() | unknown.
peer(Req) ->
    case mochiweb_socket:peername(mochiweb_request:get(socket, Req)) of
        {ok, {Ip, _}} -> Ip;
        {error, _} -> unknown
    end.

%% Whether the request came over TLS.
secure(Req) ->
    case mochiweb_request:get(socket, Req) of
        {ssl, _} -> true;
        _ -> false
    end.

%% A browser names the page a request comes from (`Origin'); a request
%% without one is not a browser's cross-site request (tools, or a page's
%% own navigation). With one, it must be this server as the client
%% reached it: scheme and `Host'.
same_origin(Req) ->
    case mochiweb_request:get_header_value("origin", Req) of
        undefined -> true;
        Origin ->
            Scheme = case secure(Req) of true -> "https://"; false -> "http://" end,
            case mochiweb_request:get_header_value("host", Req) of
                undefined -> false;
                Host -> string:lowercase(Origin) =:= string:lowercase(Scheme ++ Host)
            end
    end.

cross_origin(Req) ->
    json(Req, 403, error_json(cross_origin, <<"a request from another page (its Origin is not "
                                              "this server) may not drive the robot">>)).

too_many_failures(Req, Ms) ->
    Seconds = (Ms + 999) div 1000,
    mochiweb_request:respond(
      {429, [{"Content-Type", "application/json"}, {"Retry-After", integer_to_list(Seconds)}],
       toroco_rec_json:encode(
         error_json(too_many_failures,
                    iolist_to_binary(io_lib:format("too many wrong tokens from this address: "
                                                   "refused for ~b s more", [Seconds]))))},
      Req).

%% @doc The token a request carried: the bearer token, else `?token='
%% (the rosbridge server's upgrade, SPEC §15).
-spec token(term()) -> binary() | none.
token(Req) ->
    case mochiweb_request:get_header_value("authorization", Req) of
        "Bearer " ++ T -> list_to_binary(string:trim(T));
        _ ->
            case proplists:get_value("token", mochiweb_request:parse_qs(Req)) of
                undefined -> none;
                T -> unicode:characters_to_binary(T)
            end
    end.

content_length(Req) ->
    case mochiweb_request:get_header_value("content-length", Req) of
        undefined -> undefined;
        L -> try list_to_integer(L) catch error:badarg -> undefined end
    end.

body(Req, Max) ->
    case mochiweb_request:recv_body(Max, Req) of
        undefined -> <<>>;
        B -> B
    end.

file(Req, Rel) ->
    Root = www(),
    case mochiweb_util:safe_relative_path(Rel) of
        undefined ->
            json(Req, 404, error_json(unknown_route, <<"no such file">>));
        Safe ->
            case filelib:is_regular(filename:join(Root, Safe)) of
                true ->
                    mochiweb_request:serve_file(Safe, Root, [{"Cache-Control", "no-cache"}], Req);
                false when Rel =:= "index.html" ->
                    json(Req, 500, error_json(no_page, <<"the page was not built: run make "
                                                         "(apps/toroco_live/web/build)">>));
                false ->
                    json(Req, 404, error_json(unknown_route,
                                              iolist_to_binary(["no asset ", printable(Rel)])))
            end
    end.

www() ->
    filename:join(code:priv_dir(toroco_live), "www").

printable(Path) ->
    toroco_rec_json:value(unicode:characters_to_binary(Path)).

error_json(Reason, Message) ->
    #{<<"error">> => toroco_rec_json:value(Reason), <<"message">> => Message}.

json(Req, Status, Json) ->
    mochiweb_request:respond({Status, [{"Content-Type", "application/json"},
                                       {"Cache-Control", "no-cache"}],
                              toroco_rec_json:encode(Json)}, Req).
