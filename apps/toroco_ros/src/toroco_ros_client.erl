%% @doc Client mode (SPEC §15): the robot dials a rosbridge v2 server (in
%% a user's ROS 2 graph, or another robot's `toroco_live'), advertises its
%% topics there, publishes its messages, subscribes to its inbound topics
%% and feeds what comes into the robot (the `ros' device,
%% `toroco_ros_device', as the rosbridge server does). One process per server, a child of
%% `toroco_ros_client_sup', started by `toroco_live:rosbridge_connect/2'.
%%
%% A `gen_statem' with three states:
%% ```
%% connecting --(TCP up, HTTP 101 with the right Sec-WebSocket-Accept)--> connected
%% connecting --(refused, timeout, bad answer)--> waiting
%% connected  --(closed, error, a frame it cannot read)--> waiting
%% waiting    --(backoff elapsed)--> connecting
%% '''
%% The TCP connect runs in a short-lived process that hands the socket
%% over, and the upgrade is read as it comes (`{active, once}'), so the
%% machine keeps answering {@link info/1} while it dials. The backoff
%% doubles from `backoff_min' (default 250 ms) per failed attempt up to
%% `backoff_max' (default 30000 ms), each wait drawn between half and all
%% of it (jitter, so robots that lost one server do not return in step),
%% and starts again from `backoff_min' once connected.
%%
%% Connected: every outbound topic of `toroco_ros_topics:topics/0' is
%% advertised (`op: advertise') and every inbound one subscribed (`op:
%% subscribe'; the operations are `toroco_ros_protocol''s), again when the wiring changes (a lifecycle event, or every
%% `?REFRESH_MS'); topics that went are unadvertised. The robot's
%% messages come from the observer tap (SPEC §10, subscribed only while
%% connected) through `toroco_ros_topics:of_event/1', and from the simulated
%% world's snapshots (`toroco_ros_topics:of_world/2': `/odom'), and are sent
%% as `op: publish'. The tap's buffer (`max_queue', default 1000 events)
%% is the bounded queue: past it the tap drops and counts, and so does
%% this process (`dropped'); a server that stops reading stalls the socket
%% for at most `?SEND_TIMEOUT_MS', after which the connection is dropped
%% and dialled again. A `publish' from the server on an inbound topic
%% enters the robot through {@link inbound/3}; a message that does not fit
%% its type, or that the device cannot take (none runs, or it is behind),
%% is refused and counted (`refused'), never a crash.
%%
%% Each advertise and subscribe carries an `id' (`advertise:<topic>',
%% `subscribe:<topic>'); a server that answers one with a `status' of
%% level `error' (it does not take that topic) is believed: the topic is
%% not published on, nor asked again, until the next connection, and
%% counted (`refused_topics').
%%
%% The URL is `ws://host[:port][/path][?query]' or `wss://...'; the query
%% goes with the upgrade request, so `?token=T' authorises the client with
%% a server that asks for one (this project's, SPEC §15), and is never
%% shown (logs, {@link info/1}, `/metrics'). Over `wss://' the server's
%% certificate is checked, against the CAs of `cacertfile' (and the URL's
%% host) or against a pinned SHA-256 `fingerprint' (self-signed
%% certificates, `scripts/tls-cert'); a `wss://' URL with neither is
%% refused, and a server whose certificate does not match is not sent a
%% byte: the attempt fails with `{tls, Why}' and is dialled again with
%% backoff like any other failure.
%%
%% Options (`toroco_ros_client_opts', with the URL): `max_queue',
%% `backoff_min', `backoff_max', `connect_timeout' (TCP connect, TLS
%% handshake and upgrade, default 5000 ms), `max_message' (largest message
%% read, default 1 MiB), `cacertfile', `fingerprint'.
-module(toroco_ros_client).
-behaviour(gen_statem).

-export([start_link/2, info/1, inbound/3]).
-export([init/1, callback_mode/0, terminate/3, connecting/3, connected/3, waiting/3]).

-export_type([opts/0, info/0]).

-type opts() :: #{max_queue => pos_integer(), backoff_min => pos_integer(),
                  backoff_max => pos_integer(), connect_timeout => pos_integer(),
                  max_message => pos_integer(),
                  cacertfile => file:filename_all(), fingerprint => binary() | string()}.
-type info() :: #{url := binary(), state := connecting | connected | waiting,
                  attempts := non_neg_integer(), connects := non_neg_integer(),
                  sent := non_neg_integer(), received := non_neg_integer(),
                  dropped := non_neg_integer(), refused := non_neg_integer(),
                  refused_topics := [binary()], last_error := term()}.

-define(REFRESH_MS, 2000).
-define(SEND_TIMEOUT_MS, 5000).
-define(MAX_RESPONSE_HEAD, 8192).
-define(LOG, #{domain => [toroco, ros, client]}).

-record(data, {url :: binary(),
               host :: string(),
               port :: inet:port_number(),
               resource :: binary(),
               opts :: map(),
               %% a TCP port, or an ssl socket for wss://
               socket = none :: gen_tcp:socket() | ssl:sslsocket() | none,
               connector = none :: {pid(), reference()} | none,
               key = <<>> :: binary(),
               head = <<>> :: binary(),
               decoder = none :: toroco_live_ws_frame:decoder() | none,
               tap :: toroco_rec_tap:tap(),
               %% topic => type, as advertised or subscribed on this connection
               advertised = #{} :: #{binary() => binary()},
               subscribed = #{} :: #{binary() => binary()},
               %% topics the server refused on this connection
               refused_topics = #{} :: #{binary() => true},
               attempts = 0 :: non_neg_integer(),
               connects = 0 :: non_neg_integer(),
               sent = 0 :: non_neg_integer(),
               received = 0 :: non_neg_integer(),
               dropped = 0 :: non_neg_integer(),
               refused = 0 :: non_neg_integer(),
               last_error = none :: term()}).

%%====================================================================
%% API
%%====================================================================

%% @doc A client of the server at `Url' (options checked by
%% `toroco_ros_client_opts:options/2').
-spec start_link(binary() | string(), opts()) -> {ok, pid()} | {error, term()}.
start_link(Url, Opts) ->
    gen_statem:start_link(?MODULE, {Url, Opts}, []).

%% @doc What the client is doing and what it counted.
-spec info(pid()) -> info().
info(Pid) ->
    gen_statem:call(Pid, info, 2000).

%% @doc Where a message from ROS enters the robot, as the rosbridge server
%% does it: checked against its topic's type (`toroco_ros_topics:normalise/1')
%% and handed to the `ros' device (`toroco_ros_device:publish/3'),
%% which emits it on the output of the topic's name (`/cmd_vel': the
%% source `{ros, cmd_vel}').
-spec inbound(binary(), binary(), term()) -> ok | {error, term()}.
inbound(<<$/, Name/binary>> = Topic, Type, Msg) ->
    case toroco_ros_topics:normalise({Type, Msg}) of
        {ok, M} ->
            try binary_to_existing_atom(Name, utf8) of
                Output -> toroco_ros_device:publish(ros, Output, M)
            catch error:badarg -> {error, {unknown_topic, Topic}}
            end;
        {error, _} = E -> E
    end;
inbound(Topic, _, _) ->
    {error, {unknown_topic, Topic}}.

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> [state_functions | state_enter].
callback_mode() -> [state_functions, state_enter].

-spec init({term(), term()}) -> {ok, connecting, #data{}} | {stop, term()}.
init({Url, Opts}) ->
    process_flag(trap_exit, true),
    case toroco_ros_client_opts:options(Url, Opts) of
        {ok, {U, Host, Port, Resource}, Options} ->
            logger:notice("rosbridge client: connecting to ~ts", [U], ?LOG),
            %% one event at a time: each is a message to the remote end
            Tap = toroco_rec_tap:new(#{kinds => [emit, lifecycle], delivery => event,
                                        buffer => maps:get(max_queue, Options),
                                        retry_ms => ?REFRESH_MS, world => true,
                                        who => <<"rosbridge client">>}),
            {ok, connecting, #data{url = U, host = Host, port = Port, resource = Resource,
                                   opts = Options, tap = Tap}};
        {error, Why} ->
            {stop, Why}
    end.

%% connecting: the TCP connect, then the upgrade.
-spec connecting(gen_statem:event_type(), term(), #data{}) -> gen_statem:state_function_result().
connecting(enter, _, D = #data{host = Host, port = Port, opts = #{connect_timeout := T} = O}) ->
    Owner = self(),
    Verify = maps:get(verify, O),
    Connector = spawn_monitor(fun() -> dial(Owner, Host, Port, T, Verify) end),
    {keep_state, D#data{connector = Connector, head = <<>>}, [{state_timeout, T, timeout}]};
connecting(info, {rosclient_dialled, Pid, {ok, Socket}}, D = #data{connector = {Pid, M}}) ->
    demonitor(M, [flush]),
    Key = base64:encode(toroco_live_digest:random_bytes(16)),
    Request = [<<"GET ">>, D#data.resource, <<" HTTP/1.1\r\nHost: ">>, D#data.host, $:,
               integer_to_binary(D#data.port),
               <<"\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: ">>, Key,
               <<"\r\nSec-WebSocket-Version: 13\r\n\r\n">>],
    D1 = D#data{connector = none, socket = Socket, key = Key},
    case sock_send(Socket, Request) of
        ok ->
            ok = active_once(Socket),
            {keep_state, D1};
        {error, Why} ->
            fail({send, Why}, D1)
    end;
connecting(info, {rosclient_dialled, Pid, {error, {tls, _} = Why}}, D = #data{connector = {Pid, M}}) ->
    demonitor(M, [flush]),
    fail(Why, D#data{connector = none});
connecting(info, {rosclient_dialled, Pid, {error, Why}}, D = #data{connector = {Pid, M}}) ->
    demonitor(M, [flush]),
    fail({connect, Why}, D#data{connector = none});
connecting(info, {'DOWN', M, process, _, Why}, D = #data{connector = {_, M}}) ->
    fail({connect, Why}, D#data{connector = none});
connecting(info, {Data, S, Bytes}, D = #data{socket = S, head = Head}) when Data =:= tcp; Data =:= ssl ->
    upgrade(<<Head/binary, Bytes/binary>>, D);
connecting(info, {Closed, S}, D = #data{socket = S}) when Closed =:= tcp_closed; Closed =:= ssl_closed ->
    fail(closed_during_upgrade, D);
connecting(info, {Error, S, Why}, D = #data{socket = S}) when Error =:= tcp_error; Error =:= ssl_error ->
    fail({Error, Why}, D);
connecting(state_timeout, timeout, D) ->
    fail(timeout, D);
connecting(EventType, Event, D) ->
    common(EventType, Event, connecting, D).

%% connected: messages both ways.
-spec connected(gen_statem:event_type(), term(), #data{}) -> gen_statem:state_function_result().
connected(enter, _, #data{url = Url}) ->
    logger:notice("rosbridge client: connected to ~ts", [Url], ?LOG),
    {keep_state_and_data, [{{timeout, refresh}, ?REFRESH_MS, refresh}]};
connected(info, {Data, S, Bytes}, D = #data{socket = S, decoder = Dec}) when Data =:= tcp; Data =:= ssl ->
    ok = active_once(S),
    case toroco_live_ws_frame:decode(Bytes, Dec) of
        {ok, Messages, Dec1} -> server_messages(Messages, D#data{decoder = Dec1});
        {error, Why} -> fail({frame, Why}, D)
    end;
connected(info, {Closed, S}, D = #data{socket = S}) when Closed =:= tcp_closed; Closed =:= ssl_closed ->
    fail(closed, D);
connected(info, {Error, S, Why}, D = #data{socket = S}) when Error =:= tcp_error; Error =:= ssl_error ->
    fail({Error, Why}, D);
connected(info, {toroco_live_world, changed}, D) ->
    Snapshot = try toroco_live_world:latest() catch exit:_ -> none end,
    publish_all(toroco_ros_topics:of_world(Snapshot, erlang:system_time(nanosecond)), D);
connected({timeout, refresh}, refresh, D) ->
    with_socket(refresh(tap_on(D)), [{{timeout, refresh}, ?REFRESH_MS, refresh}]);
connected(info, Msg, D = #data{tap = Tap}) ->
    case toroco_rec_tap:handle(Msg, Tap) of
        {event, Event} -> send_event(Event, D);
        {down, Tap1} -> {keep_state, D#data{tap = Tap1}};
        {retry, Tap1} -> {keep_state, tap_on(D#data{tap = Tap1})};
        _ -> common(info, Msg, connected, D)
    end;
connected(EventType, Event, D) ->
    common(EventType, Event, connected, D).

%% waiting: the backoff before dialling again.
-spec waiting(gen_statem:event_type(), term(), #data{}) -> gen_statem:state_function_result().
waiting(enter, _, #data{attempts = A, opts = #{backoff_min := Min, backoff_max := Max}}) ->
    Ceiling = min(Max, Min bsl min(A - 1, 20)),
    Wait = Ceiling div 2 + rand:uniform(Ceiling - Ceiling div 2 + 1) - 1,
    {keep_state_and_data, [{state_timeout, max(1, Wait), dial}]};
waiting(state_timeout, dial, D) ->
    {next_state, connecting, D};
waiting(EventType, Event, D) ->
    common(EventType, Event, waiting, D).

common({call, From}, info, State, D) ->
    {keep_state_and_data, [{reply, From, info(State, D)}]};
common({call, From}, _, _State, _D) ->
    {keep_state_and_data, [{reply, From, {error, unknown_call}}]};
common(info, {rosclient_dialled, _, {ok, Socket}}, _State, _D) ->
    %% a connect that finished after its attempt was given up
    _ = sock_close(Socket),
    keep_state_and_data;
common(info, {toroco_event, _, {dropped, N}}, _State, D = #data{dropped = Dr}) ->
    %% from a subscription ended with the connection: not sent, counted
    {keep_state, D#data{dropped = Dr + N}};
common(info, {toroco_event, _, Event}, _State, D = #data{dropped = Dr}) when element(1, Event) =:= emit ->
    {keep_state, D#data{dropped = Dr + 1}};
common(info, {toroco_event, _, _}, _State, _D) ->
    keep_state_and_data;
common(_, _, _State, _D) ->
    keep_state_and_data.

-spec terminate(term(), atom(), #data{}) -> ok.
terminate(_Why, connected, D = #data{socket = S, url = Url}) ->
    _ = sock_send(S, toroco_live_ws_frame:client_close_frame(1000, <<"bye">>)),
    _ = tap_off(D),
    _ = sock_close(S),
    logger:notice("rosbridge client: disconnected from ~ts", [Url], ?LOG),
    ok;
terminate(_Why, _State, #data{socket = S, connector = C}) ->
    S =:= none orelse sock_close(S),
    case C of
        {Pid, _} -> exit(Pid, kill);
        none -> ok
    end,
    ok.

%%====================================================================
%% Dialling
%%====================================================================

%% TCP, then for wss:// the TLS handshake with the server's certificate
%% checked (verify/3), in the dialling process; the socket handed over.
dial(Owner, Host, Port, Timeout, Verify) ->
    Result = case gen_tcp:connect(Host, Port, [binary, {active, false}, {packet, raw}, {nodelay, true},
                                               {send_timeout, ?SEND_TIMEOUT_MS},
                                               {send_timeout_close, true}], Timeout) of
                 {ok, S} when Verify =:= none ->
                     case gen_tcp:controlling_process(S, Owner) of
                         ok -> {ok, S};
                         {error, _} = E -> gen_tcp:close(S), E
                     end;
                 {ok, S} ->
                     case secure(S, Host, Verify, Timeout) of
                         {ok, Ssl} ->
                             case ssl:controlling_process(Ssl, Owner) of
                                 ok -> {ok, Ssl};
                                 {error, _} = E -> _ = ssl:close(Ssl), E
                             end;
                         {error, Why} ->
                             gen_tcp:close(S),
                             {error, {tls, Why}}
                     end;
                 {error, _} = E -> E
             end,
    Owner ! {rosclient_dialled, self(), Result}.

%% The TLS handshake over `S', refused unless the server's certificate is
%% the one asked for: signed by a CA of `cacertfile' for the URL's host
%% (an address is checked as an address), or with the pinned SHA-256
%% fingerprint, compared with the certificate the connection got.
secure(S, Host, Verify, Timeout) ->
    Base = [binary, {active, false}, {verify, verify_peer}, {versions, ['tlsv1.3', 'tlsv1.2']}],
    Opts = case {Verify, inet:parse_address(Host)} of
               {{cacertfile, F}, {ok, Ip}} ->
                   [{cacertfile, F}, {server_name_indication, disable},
                    {verify_fun, {fun check_ip/3, Ip}} | Base];
               {{cacertfile, F}, {error, _}} ->
                   [{cacertfile, F}, {server_name_indication, Host},
                    {customize_hostname_check,
                     [{match_fun, public_key:pkix_verify_hostname_match_fun(https)}]} | Base];
               {{fingerprint, _}, _} ->
                   %% whoever signed it: the pin below is the check
                   [{server_name_indication, disable},
                    {verify_fun, {fun(_, {bad_cert, _}, St) -> {valid, St};
                                     (_, {extension, _}, St) -> {unknown, St};
                                     (_, _, St) -> {valid, St}
                                  end, none}} | Base]
           end,
    case ssl:connect(S, Opts, Timeout) of
        {ok, Ssl} ->
            case {Verify, ssl:peercert(Ssl)} of
                {{cacertfile, _}, _} -> {ok, Ssl};
                {{fingerprint, Pin}, {ok, Der}} ->
                    case toroco_live_digest:sha256(Der) of
                        Pin -> {ok, Ssl};
                        Other ->
                            _ = ssl:close(Ssl),
                            {error, {fingerprint_mismatch, hex(Other)}}
                    end;
                {_, {error, Why}} ->
                    _ = ssl:close(Ssl),
                    {error, {no_peer_certificate, Why}}
            end;
        {error, _} = E -> E
    end.

%% With an address for a host, the chain as OTP checks it, and the
%% server's certificate must name that address.
check_ip(_, {bad_cert, Why}, _) -> {fail, Why};
check_ip(_, {extension, _}, Ip) -> {unknown, Ip};
check_ip(_, valid, Ip) -> {valid, Ip};
check_ip(Cert, valid_peer, Ip) ->
    case public_key:pkix_verify_hostname(Cert, [{ip, Ip}]) of
        true -> {valid, Ip};
        false -> {fail, {bad_cert, hostname_check_failed}}
    end.

hex(Bin) ->
    iolist_to_binary(lists:join(":", [io_lib:format("~2.16.0B", [B]) || <<B>> <= Bin])).

sock_send(S, Data) when is_port(S) -> gen_tcp:send(S, Data);
sock_send(S, Data) -> ssl:send(S, Data).

sock_close(S) when is_port(S) -> gen_tcp:close(S);
sock_close(S) -> ssl:close(S).

active_once(S) when is_port(S) -> inet:setopts(S, [{active, once}]);
active_once(S) -> ssl:setopts(S, [{active, once}]).

%% The server's answer: 101, the upgrade, the accept of our key.
upgrade(Bytes, D = #data{socket = S, key = Key, opts = #{max_message := Max}}) ->
    case binary:match(Bytes, <<"\r\n\r\n">>) of
        nomatch when byte_size(Bytes) > ?MAX_RESPONSE_HEAD ->
            fail(response_too_long, D);
        nomatch ->
            ok = active_once(S),
            {keep_state, D#data{head = Bytes}};
        {At, 4} ->
            <<Head:At/binary, _:4/binary, Rest/binary>> = Bytes,
            case response(<<Head/binary, "\r\n\r\n">>) of
                {101, Headers} ->
                    Want = toroco_live_ws_frame:accept_key(Key),
                    Accept = proplists:get_value(<<"sec-websocket-accept">>, Headers),
                    Upgrade = string:lowercase(proplists:get_value(<<"upgrade">>, Headers, <<>>)),
                    if
                        Accept =/= Want -> fail({bad_accept, Accept}, D);
                        Upgrade =/= <<"websocket">> -> fail({bad_upgrade, Upgrade}, D);
                        true ->
                            Dec = toroco_live_ws_frame:client_decoder(Max),
                            %% frames that came with the answer, once connected
                            self() ! {case is_port(S) of true -> tcp; false -> ssl end, S, Rest},
                            up(D#data{decoder = Dec, head = <<>>})
                    end;
                {Status, _} -> fail({http_status, Status}, D);
                error -> fail(bad_response, D)
            end
    end.

%% The handshake is done: the topics advertised and subscribed, the tap on.
up(D0 = #data{connects = C}) ->
    D = refresh(tap_on(D0#data{attempts = 0, connects = C + 1, last_error = none,
                               advertised = #{}, subscribed = #{}, refused_topics = #{}})),
    case D#data.socket of
        none -> fail(D#data.last_error, D);
        _ -> {next_state, connected, D}
    end.

response(Bin) ->
    case erlang:decode_packet(http_bin, Bin, []) of
        {ok, {http_response, _, Status, _}, Rest} -> headers(Rest, Status, []);
        _ -> error
    end.

headers(Bin, Status, Acc) ->
    case erlang:decode_packet(httph_bin, Bin, []) of
        {ok, {http_header, _, Name, _, Value}, Rest} ->
            Lower = string:lowercase(if is_atom(Name) -> atom_to_binary(Name); true -> Name end),
            headers(Rest, Status, [{Lower, Value} | Acc]);
        {ok, http_eoh, _} -> {Status, Acc};
        _ -> error
    end.

%% Any failure: the socket closed, the subscriptions ended, the backoff.
fail(Why, D = #data{attempts = A, url = Url, socket = S, connector = C}) ->
    S =:= none orelse sock_close(S),
    case C of
        {Pid, M} -> demonitor(M, [flush]), exit(Pid, kill);
        none -> ok
    end,
    Level = case A of 0 -> warning; _ -> info end,
    logger:log(Level, "rosbridge client: ~ts: ~0p (attempt ~b), dialling again with backoff",
               [Url, Why, A + 1], ?LOG),
    D1 = tap_off(D),
    {next_state, waiting, D1#data{socket = none, connector = none, decoder = none,
                                  attempts = A + 1, last_error = Why}}.

%%====================================================================
%% Connected
%%====================================================================

tap_on(D = #data{tap = Tap}) ->
    D#data{tap = toroco_rec_tap:ensure_on(Tap)}.

tap_off(D = #data{tap = Tap}) ->
    D#data{tap = toroco_rec_tap:off(Tap)}.

%% Advertise what appeared, unadvertise what went, subscribe to the inbound.
refresh(D = #data{advertised = Adv, subscribed = Sub, refused_topics = Refused}) ->
    Topics = try toroco_ros_topics:topics() catch _:_ -> [] end,
    Out = maps:from_list([{T, Ty} || #{topic := T, type := Ty, dir := out} <- Topics,
                                     not is_map_key(T, Refused)]),
    In = maps:from_list([{T, Ty} || #{topic := T, type := Ty, dir := in} <- Topics,
                                    not is_map_key(T, Refused)]),
    Ops = [toroco_ros_protocol:advertise(T, Ty) || {T, Ty} <- lists:sort(maps:to_list(Out)),
                                                  maps:get(T, Adv, none) =/= Ty]
        ++ [toroco_ros_protocol:unadvertise(T) || T <- lists:sort(maps:keys(Adv)),
                                                   not maps:is_key(T, Out)]
        ++ [toroco_ros_protocol:subscribe(T, Ty)
            || {T, Ty} <- lists:sort(maps:to_list(In)), not maps:is_key(T, Sub)],
    send_ops(Ops, D#data{advertised = Out, subscribed = maps:merge(Sub, In)}).

send_event({dropped, N}, D = #data{dropped = Dr}) ->
    {keep_state, D#data{dropped = Dr + N}};
send_event({lifecycle, _, _, _}, D) ->
    with_socket(refresh(D), []);
send_event(Event, D) ->
    publish_all(try toroco_ros_topics:of_event(Event) catch _:_ -> [] end, D).

publish_all(Messages, D0) ->
    D = lists:foldl(fun({Topic, _, _}, Acc = #data{refused_topics = R}) when is_map_key(Topic, R) ->
                            Acc;
                       ({Topic, Type, Msg}, Acc = #data{advertised = Adv}) ->
                            Acc1 = case Adv of
                                       #{Topic := Type} -> Acc;
                                       #{} -> send_ops([toroco_ros_protocol:advertise(Topic, Type)],
                                                       Acc#data{advertised = Adv#{Topic => Type}})
                                   end,
                            publish(Topic, Msg, Acc1)
                    end, D0, Messages),
    with_socket(D, []).

publish(_Topic, _Msg, D = #data{socket = none}) ->
    D;
publish(Topic, Msg, D = #data{sent = N, dropped = Dr}) ->
    case toroco_ros_protocol:encode(toroco_ros_protocol:publish(Topic, Msg)) of
        {ok, Json} ->
            case send(Json, D) of
                D1 = #data{socket = none} -> D1#data{dropped = Dr + 1};
                D1 -> D1#data{sent = N + 1}
            end;
        error -> D#data{dropped = Dr + 1}
    end.

send_ops(Ops, D) ->
    lists:foldl(fun(Op, Acc) ->
                        {ok, Json} = toroco_ros_protocol:encode(Op),
                        send(Json, Acc)
                end, D, Ops).

%% A failed send closes the socket; the state function sees `socket = none'
%% and goes to waiting (with_socket/2).
send(_Json, D = #data{socket = none}) ->
    D;
send(Json, D = #data{socket = S}) ->
    case sock_send(S, toroco_live_ws_frame:client_frame(text, Json)) of
        ok -> D;
        {error, Why} ->
            _ = sock_close(S),
            D#data{socket = none, last_error = {send, Why}}
    end.

with_socket(D = #data{socket = none, last_error = Why}, _Actions) ->
    fail(Why, D);
with_socket(D, Actions) ->
    {keep_state, D, Actions}.

server_messages([], D) ->
    with_socket(D, []);
server_messages([{text, Json} | Rest], D) ->
    server_messages(Rest, server_op(Json, D));
server_messages([{ping, P} | Rest], D = #data{socket = S}) ->
    _ = sock_send(S, toroco_live_ws_frame:client_frame(pong, P)),
    server_messages(Rest, D);
server_messages([{close, Code, Reason} | _], D = #data{socket = S}) ->
    _ = sock_send(S, toroco_live_ws_frame:client_close_frame(1000, <<>>)),
    fail({closed_by_server, Code, Reason}, D);
server_messages([_ | Rest], D) ->
    server_messages(Rest, D).

%% A server's op: a publish on a topic subscribed to enters the robot; a
%% status is logged; anything else is not the client's business.
server_op(Json, D = #data{subscribed = Sub, received = N, refused = Refused}) ->
    case toroco_ros_protocol:read(Json) of
        {publish, Topic, Msg} when is_map_key(Topic, Sub) ->
            case inbound(Topic, maps:get(Topic, Sub), Msg) of
                ok -> D#data{received = N + 1};
                {error, Why} ->
                    logger:info("rosbridge client: ~ts: a message on ~ts refused: ~0p",
                                [D#data.url, Topic, Why], ?LOG),
                    D#data{received = N + 1, refused = Refused + 1}
            end;
        {refused, Topic, St} ->
            status(St, D),
            refuse_topic(Topic, D);
        {status, St} ->
            status(St, D),
            D;
        _ ->
            D
    end.

status(Status, D) ->
    logger:info("rosbridge client: ~ts: ~ts status: ~ts", [D#data.url, maps:get(<<"level">>, Status, <<"?">>),
                                                          maps:get(<<"msg">>, Status, <<>>)], ?LOG).

%% The server does not take this topic: not published on, nor asked for
%% again, on this connection.
refuse_topic(Topic, D = #data{refused_topics = R}) ->
    D#data{refused_topics = R#{Topic => true}}.

info(State, #data{url = Url, attempts = A, connects = C, sent = S, received = R,
                  dropped = Dr, refused = Rf, last_error = E, refused_topics = RT}) ->
    #{url => Url, state => State, attempts => A, connects => C, sent => S, received => R,
      dropped => Dr, refused => Rf, refused_topics => lists:sort(maps:keys(RT)), last_error => E}.
