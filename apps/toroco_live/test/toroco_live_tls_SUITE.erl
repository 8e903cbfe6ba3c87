%% toroco_live on a network: TLS on every port (the page over https, the
%% Foxglove reference client and roslib over wss, all trusting a test CA
%% made at suite start with openssl), plain HTTP beyond loopback refused at
%% start, wrong tokens limited per client address, and the token nowhere
%% a person or a tool could read it afterwards (logs, crash reports,
%% /metrics, /api/state, a recording).
-module(toroco_live_tls_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

-define(TWIST, <<"geometry_msgs/msg/Twist">>).

all() ->
    [plain_http_beyond_loopback_refused, page_and_api_over_https, foxglove_client_over_wss,
     roslib_over_wss, wrong_tokens_limited_per_address, token_nowhere_after_a_session,
     certificate_renewed_in_place].

suite() -> [{timetrap, {seconds, 120}}].

init_per_suite(Config) ->
    Env = tl_live:start(#{}, [toroco_ros]),
    {ok, _} = application:ensure_all_started(ssl),
    {ok, _} = application:ensure_all_started(inets),
    [{env, Env}, {tls, tl_tls:make(?config(priv_dir, Config))} | Config].

end_per_suite(Config) ->
    tl_live:stop(?config(env, Config)).

init_per_testcase(_Case, Config) ->
    tl_live:fake_robot(),
    ok = toroco:add_device(ros, toroco_ros_device, #{}),
    ok = toroco:add_device(cmd, toroco_fake_actuator, #{inputs => [v]}),
    ok = toroco:set_inputs(cmd, #{v => [{ros, cmd_vel}]}),
    Config.

end_per_testcase(_Case, _Config) ->
    toroco_live:stop(),
    [toroco:remove_device(D) || D <- [s, a, ros, cmd]],
    ok.

start_tls(Config, Opts) ->
    {ok, Info} = toroco_live:start(Opts#{tls => tl_tls:tls(?config(tls, Config))}),
    Info.

%%====================================================================
%% Cases
%%====================================================================

plain_http_beyond_loopback_refused() ->
    [{doc, "Without tls an address beyond loopback is refused at start with a reason naming it, "
      "nothing listens; insecure => true starts and warns at every start; a certificate that "
      "cannot be read is refused naming the file"}].
plain_http_beyond_loopback_refused(Config) ->
    {error, {tls_required, #{ip := {0, 0, 0, 0}, message := Message}}} =
        toroco_live:start(#{ip => {0, 0, 0, 0}, http => 0, foxglove => 0, rosbridge => 0}),
    ct:pal("refused: ~ts", [Message]),
    undefined = whereis(toroco_live_http),
    undefined = whereis(toroco_live_foxglove),
    not_running = toroco_live:info(),
    %% loopback is loopback, all of 127/8
    {ok, _} = toroco_live:start(#{ip => {127, 0, 0, 2}, http => 0, foxglove => off}),
    ok = toroco_live:stop(),
    %% insecure: served, and said at each start
    Log = capture_log(?config(priv_dir, Config), "insecure.log"),
    [begin
         {ok, _} = toroco_live:start(#{ip => {0, 0, 0, 0}, http => 0, foxglove => off,
                                       insecure => true}),
         ok = toroco_live:stop()
     end || _ <- [1, 2]],
    Lines = stop_capture(Log),
    Warnings = [L || L <- Lines, string:find(L, "without TLS (insecure => true)") =/= nomatch],
    ?assertEqual(2, length(Warnings)),
    %% TLS with files it cannot use
    Missing = filename:join(?config(priv_dir, Config), "no_such.pem"),
    #{key := Key, cert := Cert} = ?config(tls, Config),
    {error, {tls, {certfile, Missing, enoent}}} =
        toroco_live:start(#{http => 0, tls => #{certfile => Missing, keyfile => Key}}),
    {error, {tls, {keyfile, Cert, no_private_key_in_file}}} =
        toroco_live:start(#{http => 0, tls => #{certfile => Cert, keyfile => Cert}}),
    {error, {bad_option, {tls, #{certfile := _}}}} =
        toroco_live:start(#{http => 0, tls => #{certfile => Cert}}),
    not_running = toroco_live:info(),
    %% with TLS, any address
    #{http := _} = start_tls(Config, #{ip => {0, 0, 0, 0}, http => 0, foxglove => off}),
    <<"https://127.0.0.1:", _/binary>> = toroco_live:url().

page_and_api_over_https() ->
    [{doc, "Over https (the test CA's certificate checked by the client) the page, /api/state "
      "and a control with the bearer token round-trip; a client that does not trust the "
      "certificate fails its handshake, counted as tls_handshake; a plain-HTTP client on "
      "the TLS port is closed without an answer"}].
page_and_api_over_https(Config) ->
    #{http := Port, token := Token} = start_tls(Config, #{http => 0, foxglove => off,
                                                          request_timeout => 3000}),
    Ssl = [{ssl, [{verify, verify_peer}, {cacertfile, maps:get(ca, ?config(tls, Config))},
                  {server_name_indication, "localhost"}]}],
    Url = fun(P) -> "https://localhost:" ++ integer_to_list(Port) ++ P end,
    {ok, {{_, 200, _}, _, Page}} = httpc:request(get, {Url("/"), []}, Ssl, []),
    ?assertNotEqual(nomatch, string:find(Page, "<html")),
    {ok, {{_, 200, _}, _, State}} = httpc:request(get, {Url("/api/state"), []}, Ssl,
                                                  [{body_format, binary}]),
    #{<<"inspect">> := _} = jiffy:decode(State, [return_maps]),
    {ok, {{_, 200, _}, _, _}} =
        httpc:request(post, {Url("/api/control"), [{"authorization", "Bearer " ++ binary_to_list(Token)}],
                             "application/json", jiffy:encode(#{action => inject, source => [s, dist],
                                                                term => <<"7">>})}, Ssl, []),
    %% a client that does not trust the server's certificate does not get through
    {error, _} =
        ssl:connect("localhost", Port, [{verify, verify_peer},
                                        {cacertfile, maps:get(stranger_cert, ?config(tls, Config))}],
                    5000),
    %% plain HTTP on the TLS port: never an answer in clear
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}]),
    ok = gen_tcp:send(S, <<"GET /api/state HTTP/1.1\r\nHost: x\r\n\r\n">>),
    {Answer, Got} = recv_all(S, 5000),
    ?assertEqual({closed, nomatch}, {Answer, binary:match(Got, <<"HTTP/1.1">>)}),
    toroco_test_lib:wait_until(
      fun() -> maps:get(tls_handshake, maps:get(closed_by, toroco_live_listener:stats(toroco_live_http))) >= 1
      end, 5000),
    {ok, {{_, 200, _}, _, Metrics}} = httpc:request(get, {Url("/metrics"), []}, Ssl, []),
    {match, _} = re:run(Metrics, "listener=\"dashboard\",reason=\"tls_handshake\"} [1-9]").

foxglove_client_over_wss() ->
    [{doc, "Foxglove's reference client connects over wss (the test CA trusted) and gets "
      "serverInfo and the channels"}].
foxglove_client_over_wss(Config) ->
    #{foxglove := Fox} = start_tls(Config, #{http => 0, foxglove => 0}),
    C = node_client("fox_driver.js", Config),
    toroco_live_js:send(C, #{cmd => connect, url => url("wss", Fox, "/")}),
    {ok, #{<<"info">> := #{<<"name">> := _}}, _} = toroco_live_js:await(C, ev(<<"serverInfo">>), 15000),
    {ok, #{<<"channels">> := Channels}, _} = toroco_live_js:await(C, ev(<<"advertise">>), 10000),
    true = lists:any(fun(#{<<"topic">> := T}) -> T =:= <<"/toroco/out/s/dist">> end, Channels),
    toroco_live_js:stop(C).

roslib_over_wss() ->
    [{doc, "roslib connects to the rosbridge server over wss, lists the topics and, with the "
      "token, drives /cmd_vel"}].
roslib_over_wss(Config) ->
    #{rosbridge := Port, token := Token} = start_tls(Config, #{http => 0, foxglove => off,
                                                               rosbridge => 0}),
    C = node_client("ros_driver.js", Config),
    toroco_live_js:send(C, #{cmd => connect, url => url("wss", Port, "/")}),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"open">>), 15000),
    toroco_live_js:send(C, #{cmd => getTopics}),
    {ok, #{<<"topics">> := Topics}, _} = toroco_live_js:await(C, ev(<<"topics">>), 10000),
    true = lists:member(<<"/cmd_vel">>, Topics),
    toroco_live_js:send(C, #{cmd => auth, token => Token}),
    Forward = #{linear => #{x => 0.1, y => 0, z => 0}, angular => #{x => 0, y => 0, z => 0}},
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/cmd_vel">>, type => ?TWIST, msg => Forward}),
    toroco_test_lib:wait_until(fun() -> toroco_fake_actuator:history(cmd) =/= [] end, 10000),
    toroco_live_js:stop(C).

wrong_tokens_limited_per_address() ->
    [{doc, "20 wrong tokens from 127.0.0.2: the first ten are 401, the rest 429 with "
      "Retry-After, the right token from there refused too; 127.0.0.3 is served meanwhile; "
      "/metrics counts both; stale session cookies (a page left open across a restart) are "
      "401 and never lock an address out"}].
wrong_tokens_limited_per_address(_Config) ->
    {ok, #{http := Port, token := Token}} = toroco_live:start(#{http => 0, foxglove => off}),
    Wrong = lists:duplicate(byte_size(Token), $x),
    Body = jiffy:encode(#{action => inject, source => [s, dist], term => <<"1">>}),
    Statuses = [control({127, 0, 0, 2}, Port, Wrong, Body) || _ <- lists:seq(1, 20)],
    ct:pal("statuses from 127.0.0.2: ~w", [[S || {S, _} <- Statuses]]),
    ?assertEqual(lists:duplicate(10, 401) ++ lists:duplicate(10, 429), [S || {S, _} <- Statuses]),
    {429, Head} = lists:last(Statuses),
    {match, _} = re:run(Head, "Retry-After: (60|59)\r\n"),
    %% the right token from the limited address: refused all the same
    {429, _} = control({127, 0, 0, 2}, Port, binary_to_list(Token), Body),
    %% another address is served
    {200, _} = control({127, 0, 0, 3}, Port, binary_to_list(Token), Body),
    {401, _} = control({127, 0, 0, 3}, Port, Wrong, Body),
    Stale = [control({127, 0, 0, 4}, Port, {"Cookie", "toroco_session=stale" ++ integer_to_list(I)}, Body)
             || I <- lists:seq(1, 15)],
    ?assertEqual(lists:duplicate(15, 401), [S || {S, _} <- Stale]),
    {200, _, Metrics} = toroco_live_test_client:get(Port, "/metrics"),
    Lines = string:split(binary_to_list(Metrics), "\n", all),
    ?assert(lists:member("toroco_live_auth_failures_total 11", Lines)),
    ?assert(lists:member("toroco_live_auth_limited_total 11", Lines)),
    ?assert(lists:member("toroco_live_auth_limited_addresses 1", Lines)),
    ok.

token_nowhere_after_a_session() ->
    [{doc, "After a session (first visit, cookie, controls, a wrong token, rosbridge with the "
      "token on its URL and the auth op, a client dialling with the token, a listener killed "
      "and restarted, a recording), the token is in no log line or crash report, not in "
      "/metrics, /api/state nor the recording"}].
token_nowhere_after_a_session(Config) ->
    Priv = ?config(priv_dir, Config),
    Log = capture_log(Priv, "session.log"),
    Recording = filename:join(Priv, "session.mcap"),
    #{rosbridge := Ros, token := Token} =
        start_tls(Config, #{http => 0, foxglove => 0, rosbridge => 0}),
    T = binary_to_list(Token),
    ok = toroco_live:record(Recording, #{}),
    Ssl = [{ssl, [{verify, verify_peer}, {cacertfile, maps:get(ca, ?config(tls, Config))},
                  {server_name_indication, "localhost"}]}],
    Url = fun(P) -> "https://localhost:" ++ integer_to_list(toroco_live_http:port()) ++ P end,
    {ok, {{_, 303, _}, H, _}} = httpc:request(get, {Url("/?token=" ++ T), []},
                                              [{autoredirect, false} | Ssl], []),
    [Cookie | _] = string:split(proplists:get_value("set-cookie", H), ";"),
    {ok, {{_, 200, _}, _, _}} =
        httpc:request(post, {Url("/api/control"), [{"cookie", Cookie}], "application/json",
                             jiffy:encode(#{action => inject, source => [s, dist], term => <<"5">>})},
                      Ssl, []),
    {ok, {{_, 401, _}, _, _}} =
        httpc:request(post, {Url("/api/control"), [{"authorization", "Bearer " ++ T ++ "x"}],
                             "application/json", <<"{}">>}, Ssl, []),
    C = node_client("ros_driver.js", Config),
    toroco_live_js:send(C, #{cmd => connect, url => url("wss", Ros, "/?token=" ++ T)}),
    {ok, _, _} = toroco_live_js:await(C, ev(<<"open">>), 15000),
    toroco_live_js:send(C, #{cmd => auth, token => Token}),
    toroco_live_js:send(C, #{cmd => publish, topic => <<"/cmd_vel">>, type => ?TWIST,
                             msg => #{linear => #{x => 0.1, y => 0, z => 0},
                                      angular => #{x => 0, y => 0, z => 0}}}),
    toroco_test_lib:wait_until(fun() -> toroco_fake_actuator:history(cmd) =/= [] end, 10000),
    %% the robot dialling this server, the token on the URL
    {ok, Client} = toroco_live:rosbridge_connect(url("wss", Ros, "/?token=" ++ T),
                                                 #{cacertfile => maps:get(ca, ?config(tls, Config))}),
    toroco_test_lib:wait_until(
      fun() -> [connected] =:= [S || #{state := S} <- toroco_live:rosbridge_clients()] end, 10000),
    %% a crash: the dashboard's listener killed, its supervisor reports and restarts it
    Listener = whereis(toroco_live_http),
    exit(Listener, kill),
    toroco_test_lib:wait_until(fun() -> is_pid(whereis(toroco_live_http))
                                            andalso whereis(toroco_live_http) =/= Listener end, 5000),
    {ok, {{_, 200, _}, _, Metrics}} = httpc:request(get, {Url("/metrics"), []}, Ssl,
                                                    [{body_format, binary}]),
    {ok, {{_, 200, _}, _, State}} = httpc:request(get, {Url("/api/state"), []}, Ssl,
                                                  [{body_format, binary}]),
    Info = iolist_to_binary(io_lib:format("~p", [toroco_live:rosbridge_clients()])),
    ok = toroco_live:rosbridge_disconnect(Client),
    toroco_live_js:stop(C),
    {ok, _} = toroco_live:stop_recording(),
    {ok, Mcap} = file:read_file(Recording),
    toroco_live:stop(),
    Lines = stop_capture(Log),
    ct:pal("~b log lines captured, e.g.~n~ts", [length(Lines), lists:join("\n", lists:sublist(Lines, 12))]),
    %% the capture saw the session: the supervisor's report of the killed
    %% listener with its start arguments, and the client's line
    ?assert(lists:any(fun(L) -> string:find(L, "child_terminated") =/= nomatch end, Lines)),
    ?assert(lists:any(fun(L) -> string:find(L, "{toroco_live_http,start_link,") =/= nomatch end, Lines)),
    ?assert(lists:any(fun(L) -> string:find(L, "rosbridge client: connected to") =/= nomatch end, Lines)),
    [?assertEqual({Where, nomatch}, {Where, binary:match(Bin, Token)})
     || {Where, Bin} <- [{log, unicode:characters_to_binary(Lines)}, {metrics, Metrics},
                         {api_state, State}, {rosbridge_clients, Info}, {recording, Mcap}]],
    ?assert(byte_size(Mcap) > 0),
    ok.

certificate_renewed_in_place() ->
    [{doc, "A certificate and key replaced in place (a renewal) are served from the next "
      "start, not the first ones from ssl's cache"}].
certificate_renewed_in_place(Config) ->
    Dir = filename:join(?config(priv_dir, Config), "renewed"),
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    Tls = #{certfile => filename:join(Dir, "cert.pem"), keyfile => filename:join(Dir, "key.pem")},
    Served = fun(#{cert := C, key := K}) ->
                     {ok, _} = file:copy(C, maps:get(certfile, Tls)),
                     {ok, _} = file:copy(K, maps:get(keyfile, Tls)),
                     {ok, #{http := Port}} = toroco_live:start(#{http => 0, foxglove => off, tls => Tls}),
                     {ok, S} = ssl:connect("localhost", Port, [{verify, verify_none}], 5000),
                     {ok, Der} = ssl:peercert(S),
                     ssl:close(S),
                     ok = toroco_live:stop(),
                     Der
             end,
    First = ?config(tls, Config),
    Second = tl_tls:make(?config(priv_dir, Config)),
    Pem = fun(#{cert := C}) -> {ok, B} = file:read_file(C),
                               [{'Certificate', Der, _} | _] = public_key:pem_decode(B),
                               Der end,
    ?assertEqual(Pem(First), Served(First)),
    ?assertEqual(Pem(Second), Served(Second)).

%%====================================================================
%% Helpers
%%====================================================================

%% A Node client of test/js trusting the test CA.
node_client(Script, Config) ->
    toroco_live_js:start(Script, [{"NODE_EXTRA_CA_CERTS", maps:get(ca, ?config(tls, Config))}]).

url(Scheme, Port, Path) ->
    iolist_to_binary(io_lib:format("~s://localhost:~b~s", [Scheme, Port, Path])).

ev(Name) -> fun(#{<<"ev">> := E}) -> E =:= Name; (_) -> false end.

%% One control from the address `From', `Connection: close': the status
%% and the response's head.
control(From, Port, Token, Body) when is_list(Token) ->
    control(From, Port, {"Authorization", "Bearer " ++ Token}, Body);
control(From, Port, {Name, Value}, Body) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}, {ip, From}], 5000),
    ok = gen_tcp:send(S, ["POST /api/control HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n",
                          Name, ": ", Value, "\r\nContent-Type: application/json\r\n"
                          "Content-Length: ", integer_to_list(byte_size(Body)), "\r\n\r\n", Body]),
    {closed, Resp} = recv_all(S, 5000),
    gen_tcp:close(S),
    <<"HTTP/1.1 ", Status:3/binary, _/binary>> = Resp,
    [Head | _] = binary:split(Resp, <<"\r\n\r\n">>),
    {binary_to_integer(Status), Head}.

recv_all(S, Timeout) ->
    recv_all(S, Timeout, <<>>).

recv_all(S, Timeout, Acc) ->
    case gen_tcp:recv(S, 0, Timeout) of
        {ok, B} -> recv_all(S, Timeout, <<Acc/binary, B/binary>>);
        {error, closed} -> {closed, Acc};
        {error, Why} -> {Why, Acc}
    end.

%% Every log event of the node, at every level, to a file (a handler of
%% its own, the primary level lowered for the case).
capture_log(Dir, Name) ->
    File = filename:join(Dir, Name),
    #{level := Primary} = logger:get_primary_config(),
    ok = logger:set_primary_config(level, all),
    Id = list_to_atom("capture_" ++ filename:rootname(Name)),
    ok = logger:add_handler(Id, logger_std_h,
                            #{level => all, config => #{file => File},
                              %% reports in full: a supervisor's with its
                              %% children's start arguments
                              formatter => {logger_formatter, #{single_line => false,
                                                                template => [time, " ", level, "\n",
                                                                             msg, "\n"]}}}),
    {Id, File, Primary}.

stop_capture({Id, File, Primary}) ->
    ok = logger:set_primary_config(level, Primary),
    ok = logger_std_h:filesync(Id),
    ok = logger:remove_handler(Id),
    {ok, Bin} = file:read_file(File),
    [L || L <- string:split(unicode:characters_to_list(Bin), "\n", all), L =/= ""].
