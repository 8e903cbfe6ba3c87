%% @doc The dashboard's HTTP side: the listener and the routes. Each
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
%% The token is `Authorization: Bearer T' or `?token=T'. Every refusal is a
%% JSON object `{"error": Reason, "message": Why}' with a 4xx status;
%% nothing is read or changed past the refusal.
-module(toroco_live_http).

-export([start_link/1, port/0, loop/1, token/1]).

-define(NAME, ?MODULE).

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
    file(Req, "index.html");
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
    toroco_live_ws:upgrade(Req, toroco_live_config:authorized(token(Req)));
route('POST', "/api/control", Req) ->
    Max = toroco_live_config:get(max_body, 16384),
    Authorized = toroco_live_config:authorized(token(Req)),
    Result = case content_length(Req) of
                 _ when not Authorized -> toroco_live_control:run(false, <<>>, Max);
                 N when is_integer(N), N > Max ->
                     toroco_live_control:too_large(N, Max);
                 undefined ->
                     {error, 411, length_required, <<"send Content-Length">>};
                 _ ->
                     toroco_live_control:run(true, body(Req, Max), Max)
             end,
    case Result of
        {ok, Json} -> json(Req, 200, Json);
        {error, Status, Reason, Message} -> json(Req, Status, error_json(Reason, Message))
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

%% @doc The token a request carried: the bearer token, else `?token='.
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
    toroco_live_json:value(unicode:characters_to_binary(Path)).

error_json(Reason, Message) ->
    #{<<"error">> => toroco_live_json:value(Reason), <<"message">> => Message}.

json(Req, Status, Json) ->
    mochiweb_request:respond({Status, [{"Content-Type", "application/json"},
                                       {"Cache-Control", "no-cache"}],
                              toroco_live_json:encode(Json)}, Req).
