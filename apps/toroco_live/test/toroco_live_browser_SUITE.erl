%% The dashboard in a real browser (the system's chromium, headless, driven
%% by puppeteer-core): the page shows every behavior, follows a fake
%% sensor's events, trades the token of its first address for a session
%% cookie and suspends a behavior with it, is read-only in a profile
%% without the cookie, cannot be driven from another page, works the
%% same over TLS (chromium trusting a test CA made at suite start), and
%% follows a simulated run's robot. Screenshots go to
%% _build/toroco_live_*.png.
-module(toroco_live_browser_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").
-compile([export_all, nowarn_export_all]).

all() -> [page_follows_the_robot_and_suspends_with_the_token, controls_without_the_token_are_refused,
          another_page_cannot_drive_the_robot, page_follows_a_simulated_run, page_over_tls].

init_per_suite(Config) ->
    case toroco_live_browser:available() of
        ok ->
            _ = application:load(toroco_live),
            ok = application:set_env(toroco_live, enabled, false),
            {ok, _} = application:ensure_all_started(toroco_hw),
            {ok, _} = application:ensure_all_started(toroco_live),
            {ok, #{http := Port, token := Token}} = toroco_live:start(#{http => 0, foxglove => off}),
            Tls = tl_tls:make(?config(priv_dir, Config)),
            Browser = toroco_live_browser:start(tl_tls:chromium_args(Tls)),
            [{port, Port}, {token, Token}, {browser, Browser}, {tls, Tls} | Config];
        {no, Why} ->
            {skip, Why}
    end.

end_per_suite(Config) ->
    toroco_live_browser:stop(?config(browser, Config)),
    toroco_live:stop().

init_per_testcase(page_over_tls, Config) ->
    ok = toroco_live:stop(),
    {ok, #{http := Port, token := Token}} =
        toroco_live:start(#{http => 0, foxglove => off, tls => tl_tls:tls(?config(tls, Config))}),
    init_per_testcase(robot, [{port, Port}, {token, Token}, {scheme, "https"}
                              | [C || C = {K, _} <- Config, K =/= port, K =/= token]]);
init_per_testcase(Case, Config) when Case =/= page_follows_a_simulated_run ->
    ok = toroco:add_device(eye, toroco_fake_sensor, #{outputs => [seen]}),
    ok = toroco:add_device(wheels, toroco_fake_actuator, #{inputs => [cmd]}),
    ok = toroco:add_behavior(wander, toroco_live_relay, #{layer => 0}),
    ok = toroco:add_behavior(chase, toroco_live_relay, #{layer => 1}),
    ok = toroco:set_inputs(chase, #{in => [{eye, seen}]}),
    ok = toroco:set_inputs(wheels, #{cmd => [{chase, out}, {wander, out}]}),
    ok = toroco:inject({wander, out}, cruise, #{latch => true}),
    Config;
init_per_testcase(_Case, Config) ->
    Config.

end_per_testcase(_Case, _Config) ->
    _ = [toroco:remove_behavior(B) || B <- [wander, chase]],
    _ = [toroco:remove_device(D) || D <- [eye, wheels]],
    ok.

url(Config, WithToken) ->
    Scheme = proplists:get_value(scheme, Config, "http"),
    Base = Scheme ++ "://127.0.0.1:" ++ integer_to_list(?config(port, Config)) ++ "/",
    case WithToken of
        true -> list_to_binary(Base ++ "?token=" ++ binary_to_list(?config(token, Config)));
        false -> list_to_binary(Base)
    end.

do(Config, Cmd0) ->
    %% Scripts are written as strings and iolists here; JSON wants text.
    Cmd = maps:map(fun(_, V) when is_list(V) -> unicode:characters_to_binary(V);
                      (_, V) -> V
                   end, Cmd0),
    case toroco_live_browser:cmd(?config(browser, Config), Cmd) of
        {ok, V} -> V;
        {error, Why} ->
            {ok, Console} = toroco_live_browser:cmd(?config(browser, Config), #{console => true}),
            ct:fail({browser, Cmd, Why, Console})
    end.

wait_for(Config, Js) -> do(Config, #{waitFor => Js, timeout => 10000}).

input_cell(Input, Cell) ->
    io_lib:format("(document.querySelector('#inputs tr[data-input=\"~s\"] td.~s') || {}).textContent", [Input, Cell]).

screenshot(Config, Name) ->
    Path = filename:join([toroco_live_browser:root(), "_build", Name]),
    ok = filelib:ensure_dir(Path),
    do(Config, #{screenshot => list_to_binary(Path)}),
    ct:pal("screenshot: ~ts", [Path]).


%%====================================================================

page_follows_the_robot_and_suspends_with_the_token() ->
    [{doc, "The page draws every behavior, shows a sensor's event win, and suspends a behavior with the token"}].
page_follows_the_robot_and_suspends_with_the_token(Config) ->
    do(Config, #{open => url(Config, true)}),
    %% The first visit traded the token for the session cookie: the
    %% address bar (and the history) no longer has it.
    ?assertEqual(url(Config, false), do(Config, #{url => true})),
    wait_for(Config, "document.querySelector('#mode').textContent.startsWith('controls on')"),
    %% 1. Every behavior and device is a box of the wiring.
    wait_for(Config, "['wander','chase','eye','wheels'].every(n => "
                     "document.querySelector('#wiring [data-node=\"' + n + '\"]'))"),
    %% 2. The latched lower layer wins the wheels at first.
    wait_for(Config, [input_cell("wheels/cmd", "winner"), " === 'wander.out'"]),
    %% 3. The fake sensor emits: the higher layer takes the wheels, and the
    %%    page shows the new winner, the last value and the winning wire.
    ok = toroco:inject({eye, seen}, 42),
    wait_for(Config, [input_cell("wheels/cmd", "winner"), " === 'chase.out' && ",
                      input_cell("wheels/cmd", "last"), " === '42'"]),
    wait_for(Config, "document.querySelector('#wiring [data-wire=\"w:wheels/cmd:1\"]').classList.contains('win')"),
    %% 4. Suspend chase through the page's control, with the token.
    do(Config, #{select => <<"#control-name">>, value => <<"chase">>}),
    do(Config, #{click => <<"button[data-action=suspend]">>}),
    wait_for(Config, "(document.querySelector('#control-log div') || {}).textContent === 'suspend chase: done'"),
    #{status := suspended} = toroco:inspect(chase),
    wait_for(Config, "document.querySelector('#nodes tr[data-name=\"chase\"] td.status').textContent === 'suspended'"),
    %% 5. Clicking a behavior shows its inspect/1.
    do(Config, #{click => <<"#wiring [data-node=\"chase\"]">>}),
    wait_for(Config, "document.querySelector('#details').textContent.includes('\"status\": \"suspended\"')"),
    screenshot(Config, "toroco_live_browser.png").

controls_without_the_token_are_refused() ->
    [{doc, "In a second profile, without the cookie, the page is read-only: the node refuses "
      "its control and says why"}].
controls_without_the_token_are_refused(Config) ->
    do(Config, #{open => url(Config, false), fresh => true}),
    wait_for(Config, "document.querySelector('#mode').textContent.startsWith('read-only')"),
    wait_for(Config, "document.querySelectorAll('#control-name option').length === 2"),
    do(Config, #{select => <<"#control-name">>, value => <<"chase">>}),
    do(Config, #{click => <<"button[data-action=suspend]">>}),
    Line = wait_for(Config, "(() => { const d = document.querySelector('#control-log div');"
                            " return d && d.textContent; })()"),
    ct:pal("the page says: ~ts", [Line]),
    {match, _} = re:run(Line, "^suspend chase: refused \\(401 unauthorized\\): .*token"),
    #{status := running} = toroco:inspect(chase).

another_page_cannot_drive_the_robot() ->
    [{doc, "A page of another origin, in the browser that holds the session cookie, cannot "
      "suspend a behavior: not with a fetch, a form, nor the WebSocket"}].
another_page_cannot_drive_the_robot(Config) ->
    Port = integer_to_list(?config(port, Config)),
    %% the cookie, in this profile
    do(Config, #{open => url(Config, true)}),
    wait_for(Config, "document.querySelector('#mode').textContent.startsWith('controls on')"),
    %% another origin (localhost is not 127.0.0.1 to the browser): a page
    %% there tries every way a page has to reach the robot's port
    do(Config, #{open => list_to_binary("http://localhost:" ++ Port ++ "/")}),
    Target = "http://127.0.0.1:" ++ Port,
    Tries = do(Config, #{eval => list_to_binary(
        ["(async () => { const body = JSON.stringify({action: 'suspend', name: 'chase'});"
         " const out = {};"
         " try { const r = await fetch('", Target, "/api/control', {method: 'POST', credentials: 'include',"
         "  headers: {'Content-Type': 'application/json'}, body}); out.fetch = r.status; }"
         " catch (e) { out.fetch = 'blocked: ' + e.message; }"
         " try { await fetch('", Target, "/api/control', {method: 'POST', mode: 'no-cors',"
         "  credentials: 'include', headers: {'Content-Type': 'text/plain'}, body}); out.no_cors = 'sent'; }"
         " catch (e) { out.no_cors = 'blocked: ' + e.message; }"
         " out.ws = await new Promise((res) => { const w = new WebSocket('ws://127.0.0.1:", Port, "/ws');"
         "  w.onopen = () => { w.send(JSON.stringify({action: 'suspend', name: 'chase', id: 1}));"
         "   w.onmessage = (m) => { const f = JSON.parse(m.data); if (f.id === 1) res('answered: ' + m.data); }; };"
         "  w.onerror = () => res('refused'); setTimeout(() => res('no answer'), 5000); });"
         " const f = document.createElement('form'); f.method = 'POST'; f.action = '", Target, "/api/control';"
         " f.enctype = 'text/plain'; const i = document.createElement('input'); i.name = body; i.value = '';"
         " f.appendChild(i); document.body.appendChild(f);"
         " const frame = document.createElement('iframe'); frame.name = 'sink'; document.body.appendChild(frame);"
         " f.target = 'sink'; f.submit(); await new Promise((res) => frame.onload = res);"
         " out.form = 'submitted'; return out; })()"])}),
    ct:pal("another page's tries: ~p", [Tries]),
    ?assertEqual(<<"refused">>, maps:get(<<"ws">>, Tries)),
    ?assertNotEqual(200, maps:get(<<"fetch">>, Tries)),
    #{status := running} = toroco:inspect(chase),
    %% the page itself, at its own address, still drives it
    do(Config, #{open => url(Config, false)}),
    wait_for(Config, "document.querySelector('#mode').textContent.startsWith('controls on')"),
    wait_for(Config, "document.querySelectorAll('#control-name option').length === 2"),
    do(Config, #{select => <<"#control-name">>, value => <<"chase">>}),
    do(Config, #{click => <<"button[data-action=suspend]">>}),
    wait_for(Config, "(document.querySelector('#control-log div') || {}).textContent === 'suspend chase: done'"),
    #{status := suspended} = toroco:inspect(chase).

page_over_tls() ->
    [{doc, "Over TLS (a certificate of a test CA the browser trusts) the first visit's cookie "
      "is Secure, the token leaves the address, the page lives on wss:// and its controls work"}].
page_over_tls(Config) ->
    do(Config, #{open => url(Config, true), fresh => true}),
    ?assertEqual(url(Config, false), do(Config, #{url => true})),
    wait_for(Config, "document.querySelector('#conn').textContent === 'live'"),
    wait_for(Config, "document.querySelector('#mode').textContent.startsWith('controls on')"),
    wait_for(Config, "['wander','chase','eye','wheels'].every(n => "
                     "document.querySelector('#wiring [data-node=\"' + n + '\"]'))"),
    do(Config, #{select => <<"#control-name">>, value => <<"chase">>}),
    do(Config, #{click => <<"button[data-action=suspend]">>}),
    wait_for(Config, "(document.querySelector('#control-log div') || {}).textContent === 'suspend chase: done'"),
    #{status := suspended} = toroco:inspect(chase),
    %% the cookie over TLS is Secure (read from the wire: the page cannot see an HttpOnly cookie)
    {ok, _} = application:ensure_all_started(ssl),
    {ok, S} = ssl:connect({127, 0, 0, 1}, ?config(port, Config),
                          [binary, {active, false}, {verify, verify_peer},
                           {cacertfile, maps:get(ca, ?config(tls, Config))},
                           {server_name_indication, disable}], 5000),
    ok = ssl:send(S, ["GET /?token=", ?config(token, Config), " HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                      "Connection: close\r\n\r\n"]),
    Head = recv_head(S, <<>>),
    ct:pal("~s", [Head]),
    {match, _} = re:run(Head, "Set-Cookie: toroco_session=[^;]+; Path=/; HttpOnly; SameSite=Strict; Secure"),
    ssl:close(S).

recv_head(S, Acc) ->
    case binary:match(Acc, <<"\r\n\r\n">>) of
        nomatch ->
            {ok, B} = ssl:recv(S, 0, 5000),
            recv_head(S, <<Acc/binary, B/binary>>);
        _ -> Acc
    end.

page_follows_a_simulated_run() ->
    [{doc, "While a simulated world runs, the page draws the arena and the robot moving in it"}].
page_follows_a_simulated_run(Config) ->
    Root = toroco_live_browser:root(),
    World = filename:join(?config(priv_dir, Config), "short.world"),
    {ok, Default} = file:read_file(filename:join(Root, "config/worlds/default.world")),
    ok = file:write_file(World, re:replace(Default, "\\{duration_s, *[0-9]+\\}", "{duration_s, 8}")),
    Self = self(),
    Sim = spawn_link(fun() ->
                             R = torobot_sim:run(World, #{wiring => filename:join(Root, "config/torobot.wiring")}),
                             Self ! {sim_done, R}
                     end),
    do(Config, #{open => url(Config, false)}),
    Pose = "(() => { const r = document.querySelector('#arena [data-robot=\"torobot\"]');"
           " return r && [r.dataset.x, r.dataset.y, r.dataset.heading].join(' '); })()",
    First = wait_for(Config, Pose),
    wait_for(Config, ["document.querySelectorAll('#wiring [data-node]').length >= 12 && ",
                      Pose, " !== '", First, "'"]),
    Later = do(Config, #{eval => list_to_binary(Pose)}),
    ct:pal("pose went from ~s to ~s", [First, Later]),
    screenshot(Config, "toroco_live_arena.png"),
    receive {sim_done, {ok, _}} -> ok
    after 30000 -> unlink(Sim), exit(Sim, kill), ct:fail(sim_did_not_end)
    end.
