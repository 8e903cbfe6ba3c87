%% @doc The public API of `toroco_live' (SPEC §11): starts and stops the
%% dashboard, the HTTP + WebSocket server a person opens in a browser.
%%
%% {@link start/1} adds one child to `toroco_live_sup', the dashboard's own
%% supervisor (`toroco_live_dashboard_sup': the hub that feeds the pages and
%% the HTTP listener), and then the Foxglove bridge when it is asked for and
%% its module (`toroco_live_foxglove') is part of the node: see {@link
%% foxglove/2}, the one place the bridge is started from, and the rosbridge
%% server (SPEC §15, `toroco_live_rosbridge') when asked for. {@link stop/0}
%% takes them all away again. The application `toroco_live' calls {@link
%% start/1} with its app env (the same keys).
%%
%% <b>Client mode</b> (SPEC §15): {@link rosbridge_connect/2} dials a
%% rosbridge server and keeps the robot's topics there
%% (`toroco_live_rosclient', under `toroco_live_rosclient_sup'),
%% {@link rosbridge_disconnect/1} ends it, {@link rosbridge_clients/0}
%% says how each is doing. The app env `rosbridge_connect' (a URL, `{Url,
%% Opts}', or a list of them) dials when the application starts.
%%
%% <b>Recordings</b> (SPEC §12): {@link record/2}, {@link stop_recording/0}
%% (MCAP files, `toroco_live_recorder'), {@link dump/1} (the flight
%% recorder, `toroco_live_flight'), {@link replay/2} (`toroco_live_replay').
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
-define(FOXGLOVE, toroco_live_foxglove).
-define(ROSBRIDGE, toroco_live_rosbridge).

%% @doc Starts the dashboard (and the Foxglove bridge, if present and not
%% `off') and returns the ports it listens on and the token controls need.
%% `{error, already_started}' when it runs already; `{error, {bad_option,
%% {Key, Value}}}' for an option it cannot use; `{error, {tls, {File,
%% Why}}}' for a certificate or key it cannot read; `{error,
%% {tls_required, Detail}}' for an address beyond loopback without `tls'
%% (nor `insecure => true'); `{error, {http, Reason}}' when the port cannot
%% be opened; `{error, not_started}' before the application `toroco_live'
%% runs (`application:ensure_all_started/1').
-spec start(opts()) -> {ok, info()} | {error, term()}.
start(Opts) when is_map(Opts) ->
    case {whereis(toroco_live_sup), options(maps:merge(?DEFAULTS, Opts))} of
        {undefined, _} -> {error, not_started};
        {_, {ok, Config}} ->
            case exposure(Config) of
                ok -> start_dashboard(Config);
                {error, _} = Error -> Error
            end;
        {_, {error, _} = Error} -> Error
    end;
start(Other) ->
    {error, {bad_option, Other}}.

%% @doc Stops the dashboard and the bridge; `ok' also when nothing ran.
-spec stop() -> ok.
stop() ->
    _ = [begin
             _ = supervisor:terminate_child(toroco_live_sup, Id),
             supervisor:delete_child(toroco_live_sup, Id)
         end || Id <- [?ROSBRIDGE, ?FOXGLOVE, ?DASHBOARD]],
    toroco_live_config:clear(),
    ok.

%% @doc What {@link start/1} returned, while the dashboard runs.
-spec info() -> info() | not_running.
info() ->
    case toroco_live_config:current() of
        undefined -> not_running;
        #{http := Http, foxglove := Fox, token := Token} = Config ->
            #{http => Http, foxglove => Fox, rosbridge => maps:get(rosbridge, Config, off),
              token => Token, tls => maps:is_key(tls, Config)}
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
%% all) to an MCAP file. `profile' `foxglove' (the default): the Foxglove
%% bridge's channels and JSON Schemas; `ros2' (SPEC §15): the MCAP profile
%% `ros2', the robot's ROS 2 topics with `ros2msg' schemas and `cdr'
%% messages, `std_msgs/msg/String' for the rest (`toroco_live_recorder').
%% Writing never holds up the robot: past a bounded buffer events are
%% dropped and counted. `{error, {bad_option, {profile, V}}}' for another
%% profile.
-spec record(file:filename_all(), #{kinds => [emit | deliver | router | lifecycle],
                                    names => all | [atom()],
                                    profile => foxglove | ros2}) -> ok | {error, term()}.
record(Path, Opts) ->
    toroco_live_flight:record(Path, Opts).

%% @doc Ends the recording and completes the file.
-spec stop_recording() -> {ok, #{path := file:filename_all(), messages := non_neg_integer(),
                                 dropped := non_neg_integer(),
                                 unencodable => non_neg_integer()}} | {error, term()}.
stop_recording() ->
    toroco_live_flight:stop_recording().

%% @doc Writes the flight recorder's last `flight_seconds' to `Path'.
-spec dump(file:filename_all()) -> {ok, #{messages := non_neg_integer(), path := file:filename_all()}}
                                       | {error, term()}.
dump(Path) ->
    toroco_live_flight:dump(Path).

%% @doc Re-emits a recording's events of `sources' into the running wiring
%% at their recorded pace and compares the actuators' deliveries.
-spec replay(file:filename_all(), #{sources := [atom()]}) ->
          {ok, #{replayed := non_neg_integer(), matched := non_neg_integer(),
                 differed := [map()]}} | {error, term()}.
replay(Path, Opts) ->
    toroco_live_replay:replay(Path, Opts).

%%====================================================================
%% Client mode
%%====================================================================

%% @doc Dials the rosbridge v2 server at `Url' (`ws://host:port/path' or
%% `wss://...' with `cacertfile' or a pinned `fingerprint' to check the
%% server's certificate; `?token=T' for a server that asks for one, never
%% shown), advertises the robot's
%% topics there, publishes its messages, subscribes to its inbound topics
%% (`/cmd_vel') and reconnects with backoff when the connection goes.
%% `{ok, Pid}' at once, connected or not (see {@link rosbridge_clients/0});
%% `{error, {bad_url, Url}}', `{error, {unsupported_scheme, S}}',
%% `{error, {unverified_wss, Why}}' or `{error, {bad_option, {Key,
%% Value}}}' (options: `max_queue', `backoff_min', `backoff_max',
%% `connect_timeout', `max_message', `cacertfile', `fingerprint', see
%% `toroco_live_rosclient'). A server whose certificate does not match is
%% never sent a byte: `last_error' says `{tls, Why}'.
-spec rosbridge_connect(binary() | string(), toroco_live_rosclient:opts()) ->
          {ok, pid()} | {error, term()}.
rosbridge_connect(Url, Opts) ->
    case toroco_live_rosclient:options(Url, Opts) of
        {ok, _, _} when is_map(Opts) ->
            try toroco_live_rosclient_sup:start_client(Url, Opts)
            catch exit:{noproc, _} -> {error, not_started}
            end;
        {error, _} = E -> E
    end.

%% @doc Ends a client: it closes its connection and is not dialled again.
-spec rosbridge_disconnect(pid()) -> ok | {error, not_found}.
rosbridge_disconnect(Pid) ->
    try toroco_live_rosclient_sup:stop_client(Pid)
    catch exit:{noproc, _} -> {error, not_found}
    end.

%% @doc Each client: its URL, `state' (`connected', `connecting' or
%% `waiting' to dial again), `attempts' since it was last connected,
%% `connects', messages `sent' and `received', `dropped' (the robot's
%% messages it could not send), `refused' (the server's messages that did
%% not fit their type or the `ros' device could not take), `refused_topics'
%% (the topics the server said it does not take, on this connection),
%% `last_error'.
-spec rosbridge_clients() -> [toroco_live_rosclient:info()].
rosbridge_clients() ->
    [I || Pid <- toroco_live_rosclient_sup:clients(),
          I <- [try toroco_live_rosclient:info(Pid) catch exit:_ -> none end], I =/= none].

%%====================================================================
%% Starting
%%====================================================================

start_dashboard(Config0) ->
    Config = Config0#{token := token(maps:get(token, Config0)),
                      %% the key of the pages' session cookies (toroco_live_auth)
                      session_key => crypto:strong_rand_bytes(32)},
    %% The secrets are not in the children's start arguments, so that no
    %% supervisor report carries them: handlers read them from
    %% toroco_live_config.
    Children = maps:without([token, session_key], Config),
    Spec = #{id => ?DASHBOARD, start => {?DASHBOARD, start_link, [Children]},
             type => supervisor, restart => permanent},
    case supervisor:start_child(toroco_live_sup, Spec) of
        {ok, _} ->
            Http = toroco_live_http:port(),
            case {foxglove(maps:get(foxglove, Config), Children),
                  rosbridge(maps:get(rosbridge, Config), Children)} of
                {{ok, Fox}, {ok, Ros}} ->
                    Info = #{http => Http, foxglove => Fox, rosbridge => Ros,
                             token => maps:get(token, Config)},
                    toroco_live_config:set(maps:merge(Config, Info)),
                    {ok, Info};
                {{error, Reason}, _} ->
                    stop(),
                    {error, {foxglove, Reason}};
                {_, {error, Reason}} ->
                    stop(),
                    {error, {rosbridge, listen_reason(Reason)}}
            end;
        {error, {already_started, _}} ->
            {error, already_started};
        {error, already_present} ->
            _ = supervisor:delete_child(toroco_live_sup, ?DASHBOARD),
            start_dashboard(Config0);
        {error, {{shutdown, {failed_to_start_child, _, Reason}}, _}} ->
            {error, {http, listen_reason(Reason)}};
        {error, Reason} ->
            {error, {http, listen_reason(Reason)}}
    end.

listen_reason({shutdown, {failed_to_start_child, _, R}}) -> listen_reason(R);
listen_reason({{shutdown, {failed_to_start_child, _, R}}, _}) -> listen_reason(R);
listen_reason(R) -> R.

%% The Foxglove bridge (SPEC §12) is its own child of `toroco_live_sup',
%% started here when its module is in the node: `toroco_live_foxglove'
%% exports `child_spec(Config)' (Config as here, with `foxglove' the port
%% asked for) and `port()', the port it listens on once started.
foxglove(off, _Config) ->
    {ok, off};
foxglove(_Port, Config) ->
    Bridge = bridge(),
    case code:ensure_loaded(Bridge) of
        {module, Bridge} ->
            case supervisor:start_child(toroco_live_sup, Bridge:child_spec(Config)) of
                {ok, _} -> {ok, Bridge:port()};
                {error, Reason} -> {error, Reason}
            end;
        {error, _} ->
            {ok, off}
    end.

%% The rosbridge server (SPEC §15), its own child of `toroco_live_sup'.
rosbridge(off, _Config) ->
    {ok, off};
rosbridge(_Port, Config) ->
    case supervisor:start_child(toroco_live_sup, toroco_live_rosbridge:child_spec(Config)) of
        {ok, _} -> {ok, toroco_live_rosbridge:port()};
        %% The supervisor adds the child it could not start: the reason is enough.
        {error, {Reason, Child}} when element(1, Child) =:= child -> {error, Reason};
        {error, Reason} -> {error, Reason}
    end.

%% Named at run time: a node built without the bridge is a normal case.
bridge() -> ?FOXGLOVE.

token(auto) ->
    base64url(crypto:strong_rand_bytes(18));
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
