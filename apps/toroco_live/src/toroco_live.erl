%% @doc The public API of `toroco_live' (SPEC §11): starts and stops the
%% dashboard, the HTTP + WebSocket server a person opens in a browser.
%%
%% {@link start/1} sets the configuration (`toroco_live_config') and
%% restarts the children of `toroco_live_sup' that read it: the dashboard's
%% own supervisor (`toroco_live_dashboard_sup': the hub that feeds the
%% pages and the HTTP listener), then every bridge (`toroco_live_bridge':
%% the Foxglove bridge, and the rosbridge server of `toroco_ros'), each
%% listening when its option is a port. {@link stop/0} terminates them
%% again. The application `toroco_live' calls {@link start/1} with its app
%% env (the same keys).
%%
%% <b>Built on it</b> (documented as API): `toroco_live_listener' (a bounded
%% port), `toroco_live_ws_conn' (a WebSocket connection, a behaviour),
%% `toroco_live_ws_frame' (frames, server
%% and client side), `toroco_live_clients' (a hub's clients, per-client
%% bounds and the tap), `toroco_live_bridge', `toroco_live_extensions',
%% `toroco_live_metrics:family/4', and the helpers `toroco_live_world',
%% `toroco_live_auth' and `toroco_live_http:peer/1', `token/1', and the
%% digests and random bytes of `toroco_live_digest' (doc/dashboard.md,
%% "Built on toroco_live"). The JSON of terms, the
%% channels, the tap's client and recordings are the application
%% `toroco_rec''s, which this one is built on (`toroco_rec').
%%
%% <b>ROS 2</b> (SPEC §15) is the application `toroco_ros', built on this
%% one: its rosbridge server is a bridge (`toroco_live_bridge') that listens
%% on the option `rosbridge', its client mode is reached from here too
%% ({@link rosbridge_connect/2}, {@link rosbridge_disconnect/1}, {@link
%% rosbridge_clients/0}, which call what it added with
%% `toroco_live_extensions'), and its recording profile `ros2' is a
%% `toroco_rec_profile'.
%%
%% <b>Recordings</b> (SPEC §12) are the application `toroco_rec''s, which
%% `toroco_live' depends on (so it runs whenever this one does): {@link
%% record/2}, {@link stop_recording/0}, {@link dump/1} and {@link replay/2}
%% call `toroco_rec''s functions of the same names.
%%
%% Options (SPEC §11): `ip' (default `{127,0,0,1}'), `http' (default 8080,
%% 0 = any free port), `foxglove' (default 8765, 0 = any free port, or
%% `off'), `rosbridge' (the rosbridge v2 server's port, 0 = any free port,
%% or `off', the default), `token' (a binary, or `auto', the default: a
%% random one; publishing through rosbridge needs it too). Two
%% more keys of this implementation: `max_clients' (WebSocket clients at
%% once, default 64) and `max_body' (bytes of a control request or frame,
%% default 16384). The bounds on strangers, for each of the two ports
%% (`toroco_live_listener'): `request_timeout' (default 5000 ms to complete
%% a request or WebSocket handshake), `idle_timeout' (default 30000 ms
%% between requests), `max_connections' (default 128), `max_per_peer'
%% (default 32 per client address) and `min_age' (default 2000 ms: the
%% youngest a longest-idle connection may be to be shed for a newcomer).
%%
%% <b>On a network</b>: `tls' (`#{certfile => F, keyfile => K}', PEM files,
%% `scripts/tls-cert' makes a pair) puts every port, the dashboard's, the
%% Foxglove bridge's and the rosbridge server's, behind TLS (OTP's `ssl':
%% `https://', `wss://'). An `ip' that is not a loopback address without
%% `tls' is refused (`{error, {tls_required, Detail}}') unless `insecure =>
%% true', which logs a warning at every start.
-module(toroco_live).

-export([start/1, stop/0, info/0, url/0]).
-export([record/2, stop_recording/0, dump/1, replay/2]).
-export([rosbridge_connect/2, rosbridge_disconnect/1, rosbridge_clients/0]).

-export_type([opts/0, info/0]).

-type opts() :: #{ip => inet:ip_address(),
                  http => inet:port_number(),
                  foxglove => inet:port_number() | off,
                  rosbridge => inet:port_number() | off,
                  token => binary() | auto,
                  max_clients => pos_integer(),
                  max_body => pos_integer(),
                  request_timeout => pos_integer(),
                  idle_timeout => pos_integer(),
                  max_connections => pos_integer(),
                  max_per_peer => pos_integer(),
                  min_age => non_neg_integer(),
                  tls => toroco_live_listener:tls(),
                  insecure => boolean()}.
-type info() :: #{http := inet:port_number(), foxglove := inet:port_number() | off,
                  rosbridge := inet:port_number() | off, token := binary(), tls => boolean()}.

-define(DEFAULTS, #{ip => {127, 0, 0, 1}, http => 8080, foxglove => 8765, rosbridge => off,
                    token => auto,
                    max_clients => 64, max_body => 16384}).
-define(DASHBOARD, toroco_live_dashboard_sup).

%% @doc Starts the dashboard (and the bridges whose option is a port) and
%% returns the ports it listens on and the token controls need.
%% `{error, already_started}' when it runs already; `{error, {bad_option,
%% {Key, Value}}}' for an option it cannot use; `{error, {tls, {File,
%% Why}}}' for a certificate or key it cannot read; `{error,
%% {tls_required, Detail}}' for an address beyond loopback without `tls'
%% (nor `insecure => true'); `{error, {http, Reason}}' when the port cannot
%% be opened, `{error, {Bridge, Reason}}' when a bridge's cannot
%% (`foxglove', `rosbridge'); `{error, not_started}' before the
%% application `toroco_live' runs (`application:ensure_all_started/1').
%% The rosbridge server is `toroco_ros''s: without that application
%% running, `rosbridge' is kept for it and {@link info/0} says `off'.
-spec start(opts()) -> {ok, info()} | {error, term()}.
start(Opts) when is_map(Opts) ->
    case {whereis(toroco_live_sup), options(maps:merge(?DEFAULTS, Opts))} of
        {undefined, _} -> {error, not_started};
        {_, {ok, Config}} ->
            %% running already: its configuration is set
            case toroco_live_config:current() of
                undefined -> start_checked(Config);
                _ -> {error, already_started}
            end;
        {_, {error, _} = Error} -> Error
    end;
start(Other) ->
    {error, {bad_option, Other}}.

start_checked(Config) ->
    case exposure(Config) of
        ok -> start_dashboard(Config);
        {error, _} = Error -> Error
    end.

%% @doc Stops the dashboard and the bridges; `ok' also when nothing ran.
-spec stop() -> ok.
stop() ->
    _ = [toroco_live_bridge:close(B) || {_, B} <- lists:reverse(toroco_live_bridge:bridges())],
    _ = supervisor:terminate_child(toroco_live_sup, ?DASHBOARD),
    toroco_live_config:clear(),
    ok.

%% @doc What {@link start/1} returned, while the dashboard runs.
-spec info() -> info() | not_running.
info() ->
    case toroco_live_config:current() of
        undefined -> not_running;
        #{http := Http, token := Token} = Config ->
            Ports = maps:from_list([{foxglove, off}, {rosbridge, off}
                                    | [{Key, toroco_live_bridge:port(Id)}
                                       || {Key, #{id := Id}} <- toroco_live_bridge:bridges()]]),
            Ports#{http => Http, token => Token, tls => maps:is_key(tls, Config)}
    end.

%% @doc The page's address with the token, for a person to open once:
%% the first visit trades the token for a session cookie and drops it from
%% the address (`toroco_live_http'). Printed, never logged.
-spec url() -> binary() | not_running.
url() ->
    case toroco_live_config:current() of
        undefined -> not_running;
        #{token := Token} = Config ->
            <<(base_url(Config))/binary, "?token=", Token/binary>>
    end.

%% The page's address without the token (`https' under TLS).
base_url(#{ip := Ip, http := Port} = Config) ->
    Host = case Ip of
               {0, 0, 0, 0} -> "127.0.0.1";
               {0, 0, 0, 0, 0, 0, 0, 0} -> "[::1]";
               {_, _, _, _} -> inet:ntoa(Ip);
               _ -> ["[", inet:ntoa(Ip), "]"]
           end,
    Scheme = case Config of
                 #{tls := _} -> "https";
                 #{} -> "http"
             end,
    iolist_to_binary(io_lib:format("~s://~s:~b/", [Scheme, Host, Port])).

%%====================================================================
%% Recordings
%%====================================================================

%% @doc Records the events of `kinds' (default all) about `names' (default
%% all) to an MCAP file: `toroco_rec:record/2'. `profile' `foxglove' (the
%% default): the Foxglove bridge's channels and JSON Schemas; `ros2' (SPEC
%% §15, while `toroco_ros' runs): the MCAP profile `ros2', the robot's ROS
%% 2 topics with `ros2msg' schemas and `cdr' messages, `std_msgs/msg/String'
%% for the rest. `{error, {bad_option, {profile, V}}}' for another profile.
-spec record(file:filename_all(), #{kinds => [emit | deliver | router | lifecycle],
                                    names => all | [atom()],
                                    profile => foxglove | ros2}) -> ok | {error, term()}.
record(Path, Opts) ->
    toroco_rec:record(Path, Opts).

%% @doc Ends the recording and completes the file: `toroco_rec:stop_recording/0'.
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer(),
                                 unencodable => non_neg_integer()}} | {error, term()}.
stop_recording() ->
    toroco_rec:stop_recording().

%% @doc Writes the flight recorder's last `flight_seconds' to `Path':
%% `toroco_rec:dump/1'.
-spec dump(file:filename_all()) ->
          {ok, #{messages := non_neg_integer(), path := file:filename_all()}} | {error, term()}.
dump(Path) ->
    toroco_rec:dump(Path).

%% @doc Re-emits a recording's events of `sources' into the running wiring
%% at their recorded pace and compares the actuators' deliveries:
%% `toroco_rec:replay/2'.
-spec replay(file:filename_all(), #{sources := [atom()]}) ->
          {ok, #{replayed := non_neg_integer(), matched := non_neg_integer(),
                 differed := [map()]}} | {error, term()}.
replay(Path, Opts) ->
    toroco_rec:replay(Path, Opts).

%%====================================================================
%% Client mode
%%====================================================================

%% @doc Dials the rosbridge v2 server at `Url' (SPEC §15): the client mode
%% of the application `toroco_ros' (`toroco_ros:connect/2', where the URL
%% and the options are described), which this calls. `{error,
%% not_started}' when `toroco_ros' does not run.
-spec rosbridge_connect(binary() | string(), map()) -> {ok, pid()} | {error, term()}.
rosbridge_connect(Url, Opts) ->
    client(connect, [Url, Opts], {error, not_started}).

%% @doc Ends a client: it closes its connection and is not dialled again
%% (`toroco_ros:disconnect/1').
-spec rosbridge_disconnect(pid()) -> ok | {error, not_found}.
rosbridge_disconnect(Pid) ->
    client(disconnect, [Pid], {error, not_found}).

%% @doc Each client and how it is doing (`toroco_ros:clients/0'); `[]'
%% when `toroco_ros' does not run.
-spec rosbridge_clients() -> [map()].
rosbridge_clients() ->
    client(clients, [], []).

%% The client mode is the module `toroco_ros' added (toroco_live_extensions).
client(F, Args, Otherwise) ->
    case toroco_live_extensions:find(client, rosbridge) of
        {ok, Module} -> apply(Module, F, Args);
        error -> Otherwise
    end.

%%====================================================================
%% Starting
%%====================================================================

start_dashboard(Config0) ->
    Config = Config0#{token := token(maps:get(token, Config0)),
                      %% the key of the pages' session cookies (toroco_live_auth)
                      session_key => toroco_live_digest:random_bytes(32)},
    %% The children read it as they start (toroco_live_bridge).
    toroco_live_config:set(Config),
    case supervisor:restart_child(toroco_live_sup, ?DASHBOARD) of
        {ok, _} ->
            toroco_live_config:set(Config#{http => toroco_live_http:port()}),
            start_bridges(toroco_live_bridge:bridges());
        {error, Reason} ->
            stop(),
            {error, {http, listen_reason(Reason)}}
    end.

start_bridges([]) ->
    {ok, info()};
start_bridges([{Key, _} | Rest]) ->
    case toroco_live_bridge:open(Key) of
        {ok, _} -> start_bridges(Rest);
        {error, Reason} ->
            stop(),
            {error, {Key, listen_reason(Reason)}}
    end.

listen_reason({shutdown, {failed_to_start_child, _, R}}) -> listen_reason(R);
listen_reason({{shutdown, {failed_to_start_child, _, R}}, _}) -> listen_reason(R);
listen_reason(R) -> R.

token(auto) ->
    base64url(toroco_live_digest:random_bytes(18));
token(Token) ->
    Token.

base64url(Bytes) ->
    << <<(case C of $+ -> $-; $/ -> $_; _ -> C end)>> || <<C>> <= base64:encode(Bytes) >>.

%%====================================================================
%% Options
%%====================================================================

options(Opts) ->
    Bad = [{K, V} || {K, V} <- maps:to_list(Opts), not option(K, V)],
    case Bad of
        [] -> {ok, Opts};
        [First | _] -> {error, {bad_option, First}}
    end.

option(ip, Ip) -> is_tuple(Ip) andalso inet:ntoa(Ip) =/= {error, einval};
option(http, P) -> is_port_number(P);
option(foxglove, off) -> true;
option(foxglove, P) -> is_port_number(P);
option(rosbridge, off) -> true;
option(rosbridge, P) -> is_port_number(P);
option(token, auto) -> true;
option(token, T) -> is_binary(T) andalso byte_size(T) >= 8 andalso byte_size(T) =< 256
                        andalso url_safe(T);
option(max_clients, N) -> is_integer(N) andalso N > 0;
option(max_body, N) -> is_integer(N) andalso N >= 256;
option(K, N) when K =:= request_timeout; K =:= idle_timeout; K =:= max_connections;
                  K =:= max_per_peer -> is_integer(N) andalso N > 0;
option(min_age, N) -> is_integer(N) andalso N >= 0;
option(enabled, B) -> is_boolean(B);
option(tls, #{certfile := C, keyfile := K}) -> is_filename(C) andalso is_filename(K);
option(insecure, B) -> is_boolean(B);
option(flight_seconds, _) -> true;
option(_, _) -> false.

is_port_number(P) -> is_integer(P) andalso P >= 0 andalso P =< 65535.

is_filename(F) -> (is_list(F) orelse is_binary(F)) andalso F =/= [] andalso F =/= <<>>.

%% Who can reach the ports: TLS when asked for (its files readable, `ssl'
%% running); beyond loopback, TLS or a warning the operator asked for.
exposure(#{tls := Tls}) ->
    case {pem(maps:get(certfile, Tls), cert), pem(maps:get(keyfile, Tls), key)} of
        {ok, ok} ->
            case application:ensure_all_started(ssl) of
                %% ssl keeps PEM files by name: a certificate renewed in
                %% place is read again at this start, not served stale
                {ok, _} -> ssl:clear_pem_cache();
                {error, Why} -> {error, {tls, {ssl_not_started, Why}}}
            end;
        {{error, _} = E, _} -> E;
        {_, {error, _} = E} -> E
    end;
exposure(#{ip := Ip} = Config) ->
    case {loopback(Ip), maps:get(insecure, Config, false)} of
        {true, _} ->
            ok;
        {false, true} ->
            logger:warning("toroco_live: listening on ~s without TLS (insecure => true): anyone on "
                           "that network can read the robot's state and see its token in transit",
                           [inet:ntoa(Ip)], #{domain => [toroco, live]}),
            ok;
        {false, false} ->
            {error, {tls_required,
                     #{ip => Ip,
                       message => iolist_to_binary(
                                    ["listening on ", inet:ntoa(Ip), " is beyond loopback: give "
                                     "tls => #{certfile => F, keyfile => K} (scripts/tls-cert makes "
                                     "them), or insecure => true to serve plain HTTP anyway"])}}}
    end.

loopback({127, _, _, _}) -> true;
loopback({0, 0, 0, 0, 0, 0, 0, 1}) -> true;
loopback(_) -> false.

%% A PEM file holding a certificate (`cert') or a private key (`key').
pem(File, What) ->
    Key = case What of cert -> certfile; key -> keyfile end,
    case file:read_file(File) of
        {ok, Bin} ->
            Types = [T || {T, _, _} <- try public_key:pem_decode(Bin) catch _:_ -> [] end],
            Wanted = case What of
                         cert -> ['Certificate'];
                         key -> ['RSAPrivateKey', 'ECPrivateKey', 'PrivateKeyInfo',
                                 'DSAPrivateKey']
                     end,
            case [T || T <- Types, lists:member(T, Wanted)] of
                [_ | _] -> ok;
                [] -> {error, {tls, {Key, File, case What of
                                                     cert -> no_certificate_in_file;
                                                     key -> no_private_key_in_file
                                                 end}}}
            end;
        {error, Why} ->
            {error, {tls, {Key, File, Why}}}
    end.

%% A token rides in a URL and a header unescaped: letters, digits, - _ . ~
url_safe(T) ->
    lists:all(fun(C) -> (C >= $a andalso C =< $z) orelse (C >= $A andalso C =< $Z)
                            orelse (C >= $0 andalso C =< $9) orelse lists:member(C, "-_.~")
              end, binary_to_list(T)).
