%% The dashboard over HTTP and WebSocket: every route, every refused input
%% (with its status and reason, and nothing changed), the token, many
%% clients coming and going, and a client that never reads.
-module(toroco_live_http_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

-import(toroco_live_test_client, [get/2, get/3, post/3, post/4]).

all() -> [{group, routes}, {group, refusals}, {group, clients}].

groups() ->
    [{routes, [], [page_and_assets, api_state, metrics, api_world, control_suspend_resume,
                   control_inject, control_reset_restart, control_load_wiring,
                   first_visit_trades_the_token_for_a_cookie, token_on_a_control_url_is_not_a_credential,
                   ws_pushes_state, ws_state_from_events, ws_device_counters_as_text,
                   ws_control_with_token, ws_control_with_the_cookie,
                   start_options]},
     {refusals, [], [unknown_route, wrong_method, no_token, wrong_token, bad_json,
                     not_an_object, unknown_action, unknown_behavior, not_a_literal,
                     oversized_body, runtime_refusal, missing_fields, not_a_websocket,
                     ws_refusals, too_many_clients, cross_origin_control, cross_origin_websocket]},
     {clients, [], [fifty_clients, client_that_never_reads]}].

%%====================================================================
%% Setup
%%====================================================================

init_per_suite(Config) ->
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_hw),
    {ok, _} = application:ensure_all_started(toroco_live),
    {ok, _} = application:ensure_all_started(inets),
    {ok, #{http := Port, token := Token, foxglove := off}} =
        %% many clients from one address (loopback): a share per address
        %% above the clients the cases open
        toroco_live:start(#{http => 0, foxglove => off, max_clients => 60, max_body => 4096,
                            max_per_peer => 128}),
    [{port, Port}, {token, Token} | Config].

end_per_suite(_Config) ->
    ok = toroco_live:stop(),
    ok.

init_per_testcase(_Case, Config) ->
    ok = toroco:add_device(s, toroco_fake_sensor, #{outputs => [v]}),
    ok = toroco:add_device(a, toroco_fake_actuator, #{inputs => [x]}),
    ok = toroco:add_behavior(relay, toroco_live_relay, #{layer => 0}),
    ok = toroco:add_behavior(relay2, toroco_live_relay, #{layer => 1}),
    ok = toroco:set_inputs(relay, #{in => [{s, v}]}),
    ok = toroco:set_inputs(a, #{x => [{relay2, out}, {relay, out}]}),
    Config.

end_per_testcase(_Case, _Config) ->
    _ = [toroco:remove_behavior(B) || B <- [relay, relay2, relay3]],
    _ = [toroco:remove_device(D) || D <- [s, a, motors]],
    ok.

auth(Config) -> [{"authorization", "Bearer " ++ binary_to_list(?config(token, Config))}].

control(Config, Req) ->
    post(?config(port, Config), "/api/control", jiffy:encode(Req), auth(Config)).

%% What a refusal must leave alone: the network's whole inspection.
snapshot() ->
    #{behaviors := Bs, devices := Ds} = toroco:inspect(),
    Strip = fun(M) -> maps:without([device], M) end,
    {[Strip(toroco:inspect(N)) || N <- Bs ++ Ds], toroco_fake_actuator:history(a)}.

refused(Config, Req, Status, Reason) ->
    Before = snapshot(),
    {Got, _, Body} = control(Config, Req),
    ?assertEqual({Status, Reason}, {Got, maps:get(<<"error">>, Body)}),
    ?assert(byte_size(maps:get(<<"message">>, Body)) > 10),
    ?assertEqual(Before, snapshot()),
    Body.

wait(Fun, Timeout) -> toroco_test_lib:wait_until(Fun, Timeout).

%%====================================================================
%% Routes
%%====================================================================

page_and_assets() -> [{doc, "GET / is the page, its scripts come from the node itself"}].
page_and_assets(Config) ->
    P = ?config(port, Config),
    {200, _, Html} = get(P, "/"),
    ?assertMatch({_, _}, binary:match(Html, <<"Torocó live"/utf8>>)),
    %% Everything the page loads is on the node: no http(s):// sources.
    nomatch = re:run(Html, "(src|href)=\"https?:"),
    {200, _, Js} = get(P, "/assets/app.js"),
    ?assertMatch({_, _}, binary:match(Js, <<"WebSocket">>)),
    {200, _, Elk} = get(P, "/assets/elk.bundled.js"),
    ?assert(byte_size(Elk) > 100000),
    {404, _, #{<<"error">> := <<"unknown_route">>}} = get(P, "/assets/nothing.js"),
    {404, _, #{<<"error">> := <<"unknown_route">>}} = get(P, "/assets/../../ebin/toroco_live.app").

api_state() -> [{doc, "GET /api/state is inspect() and inspect(Name) of every name"}].
api_state(Config) ->
    ok = toroco:inject({s, v}, 5),
    ok = toroco_fake_actuator:await(a, fun(H) -> H =/= [] end, 2000),
    {200, _, #{<<"inspect">> := Overview, <<"nodes">> := Nodes}} = get(?config(port, Config), "/api/state"),
    #{<<"behaviors">> := Bs, <<"devices">> := Ds} = Overview,
    ?assert(lists:member(<<"relay">>, Bs) andalso lists:member(<<"a">>, Ds)),
    ?assertEqual(lists:sort(Bs ++ Ds), lists:sort(maps:keys(Nodes))),
    #{<<"a">> := #{<<"inputs">> := #{<<"x">> := X}}} = Nodes,
    ?assertMatch(#{<<"winner">> := [<<"relay">>, <<"out">>], <<"last">> := [<<"value">>, 5],
                   <<"sources">> := [[<<"relay2">>, <<"out">>], [<<"relay">>, <<"out">>]]}, X).

metrics() -> [{doc, "GET /metrics is Prometheus text, every name toroco_, events per output and input"}].
metrics(Config) ->
    ok = toroco:inject({s, v}, 6),
    ok = toroco_fake_actuator:await(a, fun(H) -> H =/= [] end, 2000),
    Text = fun() -> {200, Hs, T} = get(?config(port, Config), "/metrics"),
                    "text/plain" ++ _ = proplists:get_value("content-type", Hs),
                    T
           end,
    wait(fun() -> binary:match(Text(), <<"toroco_deliveries_total{receiver=\"a\",input=\"x\"}">>) =/= nomatch end, 3000),
    Lines = [L || L <- binary:split(Text(), <<"\n">>, [global]), L =/= <<>>],
    [] = [L || L <- Lines, not (binary:first(L) =:= $# orelse binary:part(L, 0, 7) =:= <<"toroco_">>)],
    Has = fun(Prefix) -> lists:any(fun(L) -> binary:match(L, Prefix) =:= {0, byte_size(Prefix)} end, Lines) end,
    true = Has(<<"toroco_emits_total{emitter=\"s\",output=\"v\"}">>),
    true = Has(<<"toroco_emits_total{emitter=\"relay\",output=\"out\"}">>),
    true = Has(<<"toroco_restarts_total{name=\"relay\"} 0">>),
    true = Has(<<"toroco_mailbox_length{name=\"relay\"}">>),
    true = Has(<<"toroco_device_counter{device=\"a\",counter=\"deliveries\"}">>),
    true = Has(<<"toroco_vm_memory_bytes{kind=\"total\"}">>),
    true = Has(<<"toroco_up{name=\"relay\",kind=\"behavior\",status=\"running\"} 1">>).

api_world() -> [{doc, "GET /api/world is the last snapshot a world published, with the trajectory"}].
api_world(Config) ->
    P = ?config(port, Config),
    Snap = fun(T, X) -> #{run => make_ref_run, t_ms => T, arena => {2.0, 1.0},
                           walls => [{{1.0, 0.0}, {1.0, 0.5}}], objects => [{red, {1.5, 0.5}, 0.1}],
                           robots => [#{name => bot, pose => {X, 0.5, 90.0}, radius => 0.1,
                                        winner => relay, ir => [], camera => #{fov_deg => 60, range => 1.0}}]}
           end,
    ok = toroco:publish_world(Snap(50, 0.2)),
    ok = toroco:publish_world(Snap(100, 0.3)),
    wait(fun() -> case get(P, "/api/world") of
                      {200, _, #{<<"t_ms">> := 100}} -> true;
                      _ -> false
                  end end, 2000),
    {200, _, W} = get(P, "/api/world"),
    #{<<"arena">> := [2.0, 1.0], <<"robots">> := [R], <<"objects">> := [#{<<"color">> := <<"red">>}]} = W,
    #{<<"pose">> := [0.3, 0.5, 90.0], <<"winner">> := <<"relay">>,
      <<"trajectory">> := Tr} = R,
    ?assertMatch([[0.2, 0.5, <<"relay">>] | _], Tr),
    ?assertEqual([0.3, 0.5, <<"relay">>], lists:last(Tr)).

control_suspend_resume() -> [{doc, "With the token, suspend and resume change what inspect/1 says"}].
control_suspend_resume(Config) ->
    {200, _, #{<<"ok">> := true}} = control(Config, #{action => suspend, name => relay}),
    #{status := suspended} = toroco:inspect(relay),
    {200, _, #{<<"ok">> := true}} = control(Config, #{action => resume, name => relay}),
    #{status := running} = toroco:inspect(relay).

control_inject() -> [{doc, "Inject reads the term as a literal and delivers it; latch latches it"}].
control_inject(Config) ->
    {200, _, _} = control(Config, #{action => inject, source => [s, v], term => <<"{1.5, \"x\", [a]}">>}),
    ok = toroco_fake_actuator:await(a, fun(H) -> lists:keymember({1.5, "x", [a]}, 2, H) end, 2000),
    {200, _, _} = control(Config, #{action => inject, source => [relay2, out], term => <<"top">>,
                                    latch => true}),
    #{inputs := #{x := #{winner := {relay2, out}, latches := [{{relay2, out}, top} | _]}}} =
        toroco:inspect(a).

control_reset_restart() -> [{doc, "Reset starts a behavior again from init/1; restart is counted"}].
control_reset_restart(Config) ->
    ok = toroco:inject({s, v}, 1),
    wait(fun() -> state(relay) =:= relaying end, 2000),
    {200, _, _} = control(Config, #{action => reset, name => relay}),
    wait(fun() -> state(relay) =:= waiting end, 2000),
    Pid = toroco:whereis(relay),
    Before = maps:get(restarts, toroco:inspect(relay)),
    {200, _, _} = control(Config, #{action => restart, name => relay}),
    wait(fun() -> New = toroco:whereis(relay),
                  is_pid(New) andalso New =/= Pid end, 3000),
    wait(fun() -> maps:get(restarts, toroco:inspect(relay)) =:= Before + 1 end, 3000).

state(B) ->
    {S, _} = sys:get_state(toroco:whereis(B)),
    S.

control_load_wiring() -> [{doc, "load_wiring loads a wiring file that is on the node"}].
control_load_wiring(Config) ->
    File = filename:join(?config(priv_dir, Config), "more.wiring"),
    ok = file:write_file(File, "{behavior, relay3, toroco_live_relay, #{layer => 2}}.\n"
                               "{inputs, relay3, #{in => [{s, v}]}}.\n"),
    {200, _, _} = control(Config, #{action => load_wiring, file => list_to_binary(File)}),
    #{inputs := #{in := #{sources := [{s, v}]}}} = toroco:inspect(relay3),
    {409, _, #{<<"error">> := <<"refused">>}} =
        control(Config, #{action => load_wiring, file => <<"/nonexistent/x.wiring">>}).

first_visit_trades_the_token_for_a_cookie() ->
    [{doc, "GET /?token=T answers 303 to the address without the token and an HttpOnly, "
      "SameSite=Strict session cookie (not Secure over plain HTTP, not the token); the "
      "cookie then drives the robot"}].
first_visit_trades_the_token_for_a_cookie(Config) ->
    Port = ?config(port, Config),
    Token = binary_to_list(?config(token, Config)),
    Url = "http://127.0.0.1:" ++ integer_to_list(Port) ++ "/?token=" ++ Token ++ "&view=wiring",
    {ok, {{_, 303, _}, Headers, _}} = httpc:request(get, {Url, []}, [{autoredirect, false}], []),
    "/?view=wiring" = proplists:get_value("location", Headers),
    SetCookie = proplists:get_value("set-cookie", Headers),
    ct:pal("Set-Cookie: ~s", [SetCookie]),
    [Pair | Attrs] = [string:trim(A) || A <- string:split(SetCookie, ";", all)],
    ?assertEqual(lists:sort(["Path=/", "HttpOnly", "SameSite=Strict"]), lists:sort(Attrs)),
    "toroco_session=" ++ Session = Pair,
    ?assertEqual(nomatch, string:find(SetCookie, Token)),
    {200, _, _} = post(Port, "/api/control", jiffy:encode(#{action => suspend, name => relay2}),
                       [{"cookie", Pair}]),
    #{status := suspended} = toroco:inspect(relay2),
    %% a session that is not this token's is no session
    Forged = "toroco_session=" ++ lists:reverse(Session),
    {401, _, _} = post(Port, "/api/control", jiffy:encode(#{action => resume, name => relay2}),
                       [{"cookie", Forged}]),
    %% a wrong token on the first visit: the page, read-only, and no cookie
    {ok, {{_, 303, _}, Wrong, _}} =
        httpc:request(get, {"http://127.0.0.1:" ++ integer_to_list(Port) ++ "/?token=nottheone",
                            []}, [{autoredirect, false}], []),
    "/" = proplists:get_value("location", Wrong),
    undefined = proplists:get_value("set-cookie", Wrong).

token_on_a_control_url_is_not_a_credential() ->
    [{doc, "?token=T on /api/control is not read: the token belongs in a header or a cookie"}].
token_on_a_control_url_is_not_a_credential(Config) ->
    Path = "/api/control?token=" ++ binary_to_list(?config(token, Config)),
    {401, _, _} = post(?config(port, Config), Path, jiffy:encode(#{action => suspend, name => relay2})),
    #{status := running} = toroco:inspect(relay2).

ws_pushes_state() -> [{doc, "A WebSocket client gets hello, then the state, then each change"}].
ws_pushes_state(Config) ->
    C = toroco_live_test_client:ws(?config(port, Config), ""),
    {ok, _} = toroco_live_test_client:ws_next(C, fun(#{<<"type">> := T}) -> T =:= <<"hello">> end, 3000),
    ok = toroco:inject({s, v}, 77),
    {ok, _} = toroco_live_test_client:ws_next(C, fun(J) -> last(J, <<"a">>, <<"x">>) =:= <<"77">> end, 3000),
    ok = toroco:inject({s, v}, 78),
    %% What the tap carries comes at once; a behavior's state with the
    %% runtime's reading, at most a second later.
    {ok, J} = toroco_live_test_client:ws_next(C, fun(J) -> last(J, <<"a">>, <<"x">>) =:= <<"78">>
                                                          andalso state(J, <<"relay">>) =:= <<"relaying">>
                                              end, 3000),
    [Relay] = [N || N = #{<<"name">> := <<"relay">>} <- maps:get(<<"nodes">>, J)],
    #{<<"status">> := <<"running">>, <<"restarts">> := Restarts, <<"mailbox">> := 0, <<"layer">> := 0,
      <<"state">> := #{<<"term">> := <<"relaying">>},
      <<"outputs">> := [#{<<"output">> := <<"out">>, <<"latch">> := #{<<"value">> := 78}}]} = Relay,
    %% Counted since the node started: a relay of an earlier case was restarted.
    true = is_integer(Restarts),
    toroco_live_test_client:ws_close(C).

ws_state_from_events() ->
    [{doc, "With a page open and 100 values a second, the page shows each value the tap carries while "
      "the runtime is read at most about once a second"}].
ws_state_from_events(Config) ->
    C = toroco_live_test_client:ws(?config(port, Config), ""),
    {ok, _} = toroco_live_test_client:ws_next(C, fun(#{<<"type">> := T}) -> T =:= <<"hello">> end, 3000),
    {ok, _} = toroco_live_test_client:ws_next(C, fun(#{<<"type">> := T}) -> T =:= <<"state">> end, 3000),
    erlang:trace_pattern({toroco_live_state, readings, 0}, true, [call_count]),
    T0 = erlang:monotonic_time(millisecond),
    %% 2 s of values, 100 a second at most, each one on the page before the next.
    _ = toroco_test_lib:pace(fun(I) ->
                                     ok = toroco:inject({s, v}, I),
                                     Want = integer_to_binary(I),
                                     {ok, _} = toroco_live_test_client:ws_next(
                                                 C, fun(J) -> last(J, <<"a">>, <<"x">>) =:= Want end,
                                                 3000)
                             end, 200, 10),
    Ms = erlang:monotonic_time(millisecond) - T0,
    {call_count, Reads} = erlang:trace_info({toroco_live_state, readings, 0}, call_count),
    _ = erlang:trace_pattern({toroco_live_state, readings, 0}, false, [call_count]),
    ct:pal("~b values in ~b ms, ~b readings of the runtime", [200, Ms, Reads]),
    true = Reads =< Ms div 1000 + 2,
    toroco_live_test_client:ws_close(C).

ws_device_counters_as_text() ->
    [{doc, "A device's counters that are text (the servos' sysfs_root) reach the page as "
      "strings, not as lists of character codes"}].
ws_device_counters_as_text(Config) ->
    ok = toroco:add_device(motors, toroco_servo_motors, #{backend => sim}),
    #{device := #{sysfs_root := Root}} = toroco:inspect(motors),
    true = io_lib:printable_unicode_list(Root),
    C = toroco_live_test_client:ws(?config(port, Config), ""),
    Want = unicode:characters_to_binary(Root),
    {ok, _} = toroco_live_test_client:ws_next(
                C, fun(#{<<"type">> := <<"state">>, <<"nodes">> := Nodes}) ->
                           [Want] =:= [R || #{<<"name">> := <<"motors">>,
                                              <<"device">> := #{<<"sysfs_root">> := R}} <- Nodes];
                      (_) -> false
                   end, 3000),
    toroco_live_test_client:ws_close(C).

%% The term of node N's state in a state frame.
state(#{<<"type">> := <<"state">>, <<"nodes">> := Nodes}, N) ->
    case [S || #{<<"name">> := Name, <<"state">> := #{<<"term">> := S}} <- Nodes, Name =:= N] of
        [S] -> S;
        _ -> none
    end;
state(_, _) -> none.

%% The term of the last value delivered to input I of node N in a state frame.
last(#{<<"type">> := <<"state">>, <<"nodes">> := Nodes}, N, I) ->
    case [In || #{<<"name">> := Name, <<"inputs">> := Ins} <- Nodes, Name =:= N,
                In = #{<<"input">> := Input} <- Ins, Input =:= I] of
        [#{<<"last">> := #{<<"term">> := T}}] -> T;
        _ -> none
    end;
last(_, _, _) -> none.

ws_control_with_token() -> [{doc, "Over the WebSocket opened with the bearer token, a control is done and answered"}].
ws_control_with_token(Config) ->
    C = toroco_live_test_client:ws(?config(port, Config), "", auth(Config)),
    {ok, #{<<"controls">> := true}} = toroco_live_test_client:ws_next(
                                         C, fun(J) -> maps:get(<<"type">>, J) =:= <<"session">> end, 3000),
    ok = toroco_live_test_client:ws_send(C, #{action => suspend, name => relay, id => 7}),
    {ok, #{<<"ok">> := true}} = toroco_live_test_client:ws_next(
                                   C, fun(J) -> maps:get(<<"id">>, J, null) =:= 7 end, 3000),
    #{status := suspended} = toroco:inspect(relay),
    toroco_live_test_client:ws_close(C).

ws_control_with_the_cookie() ->
    [{doc, "The page's WebSocket carries the session cookie and the page's own Origin: controls are on"}].
ws_control_with_the_cookie(Config) ->
    Port = ?config(port, Config),
    Cookie = "toroco_session=" ++ binary_to_list(toroco_live_auth:session(?config(token, Config))),
    C = toroco_live_test_client:ws(Port, "", [{"Cookie", Cookie},
                                              {"Origin", "http://127.0.0.1:" ++ integer_to_list(Port)}]),
    {ok, #{<<"controls">> := true}} = toroco_live_test_client:ws_next(
                                         C, fun(J) -> maps:get(<<"type">>, J) =:= <<"session">> end, 3000),
    ok = toroco_live_test_client:ws_send(C, #{action => suspend, name => relay, id => 8}),
    {ok, #{<<"ok">> := true}} = toroco_live_test_client:ws_next(
                                   C, fun(J) -> maps:get(<<"id">>, J, null) =:= 8 end, 3000),
    #{status := suspended} = toroco:inspect(relay),
    toroco_live_test_client:ws_close(C).

start_options() -> [{doc, "start/1 refuses bad options and a second start, naming them"}].
start_options(_Config) ->
    {error, {bad_option, {http, -1}}} = toroco_live:start(#{http => -1}),
    {error, {bad_option, {token, <<"a b">>}}} = toroco_live:start(#{token => <<"a b">>}),
    {error, {bad_option, {colour, red}}} = toroco_live:start(#{colour => red}),
    {error, already_started} = toroco_live:start(#{http => 0}).

%%====================================================================
%% Refusals
%%====================================================================

unknown_route() -> [{doc, "An unknown route is a 404 that lists the routes"}].
unknown_route(Config) ->
    {404, _, #{<<"error">> := <<"unknown_route">>, <<"message">> := M}} = get(?config(port, Config), "/nope"),
    {_, _} = binary:match(M, <<"/api/state">>).

wrong_method() -> [{doc, "A known route with the wrong method is a 405"}].
wrong_method(Config) ->
    {405, _, #{<<"error">> := <<"method_not_allowed">>}} = get(?config(port, Config), "/api/control"),
    {405, _, #{<<"error">> := <<"method_not_allowed">>}} = post(?config(port, Config), "/api/state", <<"{}">>).

no_token() -> [{doc, "A control without the token is refused with 401 and why; nothing changes"}].
no_token(Config) ->
    Before = snapshot(),
    {401, _, #{<<"error">> := <<"unauthorized">>, <<"message">> := M}} =
        post(?config(port, Config), "/api/control", jiffy:encode(#{action => suspend, name => relay})),
    {_, _} = binary:match(M, <<"token">>),
    ?assertEqual(Before, snapshot()).

wrong_token() -> [{doc, "A wrong token is no token"}].
wrong_token(Config) ->
    Before = snapshot(),
    Bad = "Bearer " ++ lists:duplicate(byte_size(?config(token, Config)), $x),
    {401, _, _} = post(?config(port, Config), "/api/control",
                       jiffy:encode(#{action => suspend, name => relay}), [{"authorization", Bad}]),
    {401, _, _} = post(?config(port, Config), "/api/control?token=short",
                       jiffy:encode(#{action => suspend, name => relay})),
    ?assertEqual(Before, snapshot()).

bad_json() -> [{doc, "A body that is not JSON is a 400 bad_json"}].
bad_json(Config) ->
    Before = snapshot(),
    {400, _, #{<<"error">> := <<"bad_json">>}} =
        post(?config(port, Config), "/api/control", <<"{\"action\": ">>, auth(Config)),
    ?assertEqual(Before, snapshot()).

not_an_object() -> [{doc, "JSON that is not an object is refused"}].
not_an_object(Config) ->
    {400, _, #{<<"error">> := <<"bad_json">>}} =
        post(?config(port, Config), "/api/control", <<"[1,2]">>, auth(Config)).

unknown_action() -> [{doc, "An unknown action is refused and the actions listed"}].
unknown_action(Config) ->
    #{<<"message">> := M} = refused(Config, #{action => explode, name => relay}, 400, <<"unknown_action">>),
    {_, _} = binary:match(M, <<"suspend">>).

unknown_behavior() -> [{doc, "A name that is no behavior (no atom, or a device) is a 404"}].
unknown_behavior(Config) ->
    refused(Config, #{action => suspend, name => <<"no_such_behavior_zz9">>}, 404, <<"unknown_behavior">>),
    refused(Config, #{action => restart, name => a}, 404, <<"unknown_behavior">>),
    refused(Config, #{action => inject, source => [<<"no_such_emitter_zz9">>, v], term => <<"1">>},
            404, <<"unknown_emitter">>).

not_a_literal() -> [{doc, "A term that is not a literal is refused, never evaluated"}].
not_a_literal(Config) ->
    [refused(Config, #{action => inject, source => [s, v], term => T}, 400, <<"bad_term">>)
     || T <- [<<"os:cmd(\"touch /tmp/toroco_live_pwned\")">>, <<"fun() -> ok end">>, <<"X">>,
              <<"1 + 1">>, <<"{unclosed">>, <<"">>]],
    false = filelib:is_file("/tmp/toroco_live_pwned").

oversized_body() -> [{doc, "A body over max_body is a 413, not read"}].
oversized_body(Config) ->
    Big = jiffy:encode(#{action => inject, source => [s, v], term => binary:copy(<<"1">>, 5000)}),
    Before = snapshot(),
    {413, _, #{<<"error">> := <<"too_large">>}} = post(?config(port, Config), "/api/control", Big, auth(Config)),
    ?assertEqual(Before, snapshot()).

runtime_refusal() -> [{doc, "What the runtime refuses comes back as 409 with its reason"}].
runtime_refusal(Config) ->
    #{<<"message">> := M} = refused(Config, #{action => inject, source => [s, x], term => <<"1">>},
                                    409, <<"refused">>),
    {_, _} = binary:match(M, <<"x">>).

missing_fields() -> [{doc, "A control missing its fields says which"}].
missing_fields(Config) ->
    refused(Config, #{action => suspend}, 400, <<"bad_request">>),
    refused(Config, #{action => inject, source => [s, v]}, 400, <<"bad_request">>),
    refused(Config, #{name => relay}, 400, <<"bad_request">>),
    refused(Config, #{action => inject, source => [s, v], term => <<"1">>, hold => <<"long">>},
            400, <<"bad_request">>).

not_a_websocket() -> [{doc, "GET /ws without an upgrade is a 400"}].
not_a_websocket(Config) ->
    {400, _, #{<<"error">> := <<"not_websocket">>}} = get(?config(port, Config), "/ws").

ws_refusals() -> [{doc, "Over the WebSocket: no token, bad JSON, an oversized frame are answered and the client stays"}].
ws_refusals(Config) ->
    Before = snapshot(),
    C = toroco_live_test_client:ws(?config(port, Config), ""),
    Err = fun(Reason) -> toroco_live_test_client:ws_next(
                           C, fun(J) -> maps:get(<<"error">>, J, none) =:= Reason end, 3000) end,
    ok = toroco_live_test_client:ws_send(C, #{action => suspend, name => relay, id => 1}),
    {ok, #{<<"id">> := 1}} = Err(<<"unauthorized">>),
    ok = toroco_live_test_client:ws_send_raw(C, <<"{not json">>),
    {ok, _} = Err(<<"bad_json">>),
    ok = toroco_live_test_client:ws_send_raw(C, jiffy:encode(#{action => inject, source => [s, v],
                                                               term => binary:copy(<<"7">>, 6000)})),
    {ok, _} = Err(<<"too_large">>),
    %% Still connected and still refusing politely.
    ok = toroco_live_test_client:ws_send(C, #{action => resume, name => relay, id => 2}),
    {ok, #{<<"id">> := 2}} = Err(<<"unauthorized">>),
    ?assertEqual(Before, snapshot()),
    toroco_live_test_client:ws_close(C).

cross_origin_control() ->
    [{doc, "A control whose Origin is another page is refused (403 cross_origin) even with the "
      "session or the token; nothing changes; the page's own Origin is served"}].
cross_origin_control(Config) ->
    Port = ?config(port, Config),
    Before = snapshot(),
    Cookie = {"cookie", "toroco_session=" ++ binary_to_list(toroco_live_auth:session(?config(token, Config)))},
    Body = jiffy:encode(#{action => suspend, name => relay}),
    [{403, _, #{<<"error">> := <<"cross_origin">>}} =
         post(Port, "/api/control", Body, [{"origin", Origin}, Cred])
     || Origin <- ["http://evil.example", "http://127.0.0.1:" ++ integer_to_list(Port + 1),
                   "https://127.0.0.1:" ++ integer_to_list(Port), "null"],
        Cred <- [Cookie | auth(Config)]],
    ?assertEqual(Before, snapshot()),
    {200, _, _} = post(Port, "/api/control", Body,
                       [{"origin", "http://127.0.0.1:" ++ integer_to_list(Port)}, Cookie]),
    #{status := suspended} = toroco:inspect(relay).

cross_origin_websocket() ->
    [{doc, "A WebSocket opened from another page (its Origin not the server's) is refused with 403"}].
cross_origin_websocket(Config) ->
    P = ?config(port, Config),
    {ok, Sock} = gen_tcp:connect({127, 0, 0, 1}, P, [binary, {active, false}]),
    {403, Rest} = toroco_live_test_client:handshake(Sock, P, "", [{"Origin", "http://evil.example"}]),
    {_, _} = binary:match(Rest, <<"cross_origin">>),
    gen_tcp:close(Sock).

too_many_clients() -> [{doc, "Past max_clients a new WebSocket is refused with 503 too_many_clients"}].
too_many_clients(Config) ->
    P = ?config(port, Config),
    Cs = [toroco_live_test_client:ws(P, "") || _ <- lists:seq(1, 60)],
    wait(fun() -> maps:get(clients, toroco_live_hub:stats()) =:= 60 end, 5000),
    {ok, Sock} = gen_tcp:connect({127, 0, 0, 1}, P, [binary, {active, false}]),
    {503, Rest} = toroco_live_test_client:handshake(Sock, P, ""),
    {_, _} = binary:match(Rest, <<"too_many_clients">>),
    gen_tcp:close(Sock),
    [toroco_live_test_client:ws_close(C) || C <- Cs],
    wait(fun() -> maps:get(clients, toroco_live_hub:stats()) =:= 0 end, 5000).

%%====================================================================
%% Clients
%%====================================================================

fifty_clients() -> [{doc, "50 clients connect, all get the state, leave, and the hub forgets them"}].
fifty_clients(Config) ->
    P = ?config(port, Config),
    Procs0 = length(processes()),
    Cs = [toroco_live_test_client:ws(P, "") || _ <- lists:seq(1, 50)],
    ok = toroco:inject({s, v}, 50),
    [{ok, _} = toroco_live_test_client:ws_next(C, fun(J) -> last(J, <<"a">>, <<"x">>) =:= <<"50">> end, 5000)
     || C <- Cs],
    50 = maps:get(clients, toroco_live_hub:stats()),
    [toroco_live_test_client:ws_close(C) || C <- Cs],
    wait(fun() -> maps:get(clients, toroco_live_hub:stats()) =:= 0 end, 5000),
    %% Their connection and sender processes are gone too.
    wait(fun() -> length(processes()) =< Procs0 + 5 end, 5000).

client_that_never_reads() ->
    [{doc, "A client that never reads holds no more than one frame, others keep updating, memory stays bounded"}].
client_that_never_reads(Config) ->
    P = ?config(port, Config),
    %% A large latched value makes every state frame some 60 KB.
    ok = toroco:add_behavior(relay3, toroco_live_relay, #{layer => 2}),
    ok = toroco:inject({relay3, out}, binary:copy(<<"z">>, 60000), #{latch => true}),
    {ok, Stuck, _} = toroco_live_test_client:raw_ws(P, ""),
    Reader = toroco_live_test_client:ws(P, ""),
    wait(fun() -> maps:get(clients, toroco_live_hub:stats()) =:= 2 end, 3000),
    Mem0 = erlang:memory(total),
    Feeder = toroco_test_lib:paced(fun(N) -> ok = toroco:inject({s, v}, N) end, infinity, 2),
    %% For 3 s the reader keeps seeing new values while the stuck one reads nothing.
    Seen = count_updates(Reader, erlang:monotonic_time(millisecond) + 3000, none, 0),
    ok = toroco_test_lib:stop_paced(Feeder),
    ct:pal("the reader saw ~b new values in 3 s; memory grew by ~b KB; ~p",
           [Seen, (erlang:memory(total) - Mem0) div 1024, toroco_live_hub:stats()]),
    ?assert(Seen >= 10),
    ?assert(erlang:memory(total) - Mem0 < 64 * 1024 * 1024),
    %% Every dashboard process holds at most one pending push.
    Queues = [Q || Pid <- processes(), {message_queue_len, Q} <- [process_info(Pid, message_queue_len)]],
    ?assert(lists:max(Queues) < 1000),
    ?assert(maps:get(skipped, toroco_live_hub:stats()) > 0),
    %% The stuck client is dropped once its writes time out; the reader stays.
    wait(fun() -> maps:get(clients, toroco_live_hub:stats()) =:= 1 end, 15000),
    gen_tcp:close(Stuck),
    toroco_live_test_client:ws_close(Reader).

count_updates(C, Deadline, Last, N) ->
    case erlang:monotonic_time(millisecond) >= Deadline of
        true -> N;
        false ->
            case toroco_live_test_client:ws_next(C, fun(J) -> last(J, <<"a">>, <<"x">>) =/= none end, 1000) of
                {ok, J} ->
                    V = last(J, <<"a">>, <<"x">>),
                    count_updates(C, Deadline, V, case V of Last -> N; _ -> N + 1 end);
                {error, timeout} ->
                    count_updates(C, Deadline, Last, N)
            end
    end.
