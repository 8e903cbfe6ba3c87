%% The UDP and TCP links over loopback: events out and in as JSON, the
%% allow-lists, and what clients that misbehave can and cannot do.
-module(toroco_links_SUITE).
-import(toroco_test_lib, [wait_until/2]).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, groups/0, suite/0, init_per_testcase/2, end_per_testcase/2]).
-export([event_codec/1,
         udp_round_trip/1, udp_latch_hold_unset/1, udp_allow_list/1, udp_bad_datagrams/1,
         tcp_round_trip/1, tcp_allow_list_and_max_clients/1, tcp_garbage_and_partial_lines/1,
         tcp_connect_cycles/1, tcp_silent_clients_shed/1, tcp_line_and_idle_timeouts/1,
         tcp_per_peer_limit/1]).

-define(WAIT, 5000).

suite() ->
    [{timetrap, {seconds, 60}}].

all() ->
    [event_codec, {group, udp}, {group, tcp}].

groups() ->
    [{udp, [], [udp_round_trip, udp_latch_hold_unset, udp_allow_list, udp_bad_datagrams]},
     {tcp, [], [tcp_round_trip, tcp_allow_list_and_max_clients, tcp_garbage_and_partial_lines,
                tcp_connect_cycles, tcp_silent_clients_shed, tcp_line_and_idle_timeouts,
                tcp_per_peer_limit]}].

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    Config.

end_per_testcase(_Case, _Config) ->
    toroco_test_lib:stop().

%%% ---------------------------------------------------------------------
%%% Codec
%%% ---------------------------------------------------------------------

event_codec(doc) ->
    ["Values survive encode/decode as documented; atoms are never made from the network"];
event_codec(_Config) ->
    RoundTrip = [{{10, -10}, {10, -10}}, {forward, forward}, {3.5, 3.5}, {true, true},
                 {null, null}, {<<"text">>, <<"text">>}, {[1, [2, a]], [1, [2, <<"a">>]]},
                 {#{a => 1, <<"b">> => {x, 2}, 3 => c}, #{<<"a">> => 1, <<"b">> => [<<"x">>, 2],
                                                          <<"3">> => <<"c">>}},
                 {123456789012345678901234567890, 123456789012345678901234567890}],
    [begin
         {ok, Json} = toroco_net:encode_event(cmd, V),
         In = jiffy:decode(Json, [return_maps]),
         Back = maps:remove(<<"input">>, In#{<<"output">> => <<"cmd">>}),
         ?assertEqual({V, {ok, {send, #{cmd => Expected}}}},
                      {V, toroco_net:decode_event(jiffy:encode(Back), [cmd])})
     end || {V, Expected} <- RoundTrip],
    [?assertEqual({V, {error, unencodable}}, {V, toroco_net:encode_event(cmd, V)})
     || V <- [self(), fun() -> ok end, <<255>>, make_ref(), [1 | 2], #{{a} => 1}]],
    Refused = [{<<"{\"output\":\"cmd\",\"value\":\"no_such_atom_here_at_all\",\"as\":\"atom\"}">>,
                bad_value},
               {<<"{\"output\":\"cmd\",\"value\":1,\"as\":\"tuple\"}">>, bad_value},
               {<<"{\"output\":\"cmd\",\"value\":1,\"as\":\"pid\"}">>, bad_value},
               {<<"{\"output\":\"cmd\",\"value\":1,\"hold\":-1}">>, bad_field},
               {<<"{\"output\":\"cmd\",\"value\":1,\"latch\":\"yes\"}">>, bad_field},
               {<<"{\"output\":\"cmd\",\"value\":1,\"latch\":true,\"hold\":5}">>, bad_field},
               {<<"{\"output\":\"cmd\",\"unset\":1}">>, bad_field},
               {<<"{\"output\":\"cmd\"}">>, no_value},
               {<<"{\"output\":\"other\",\"value\":1}">>, unknown_output},
               {<<"{\"output\":7,\"value\":1}">>, bad_field},
               {<<"{\"value\":1}">>, no_output},
               {<<"{\"input\":\"other\",\"value\":1}">>, unknown_output},
               {<<"[]">>, not_object},
               {<<"{\"output\":">>, not_json}],
    [?assertEqual({B, {error, R}}, {B, toroco_net:decode_event(B, [cmd])}) || {B, R} <- Refused].

%%% ---------------------------------------------------------------------
%%% UDP
%%% ---------------------------------------------------------------------

udp_round_trip(doc) ->
    ["Two UDP links carry events both ways over loopback, tuples and atoms intact"];
udp_round_trip(_Config) ->
    [PA, PB] = free_udp_ports(2),
    ok = toroco:add_device(a, toroco_udp_link, #{port => PA, inputs => [cmd], outputs => [reply],
                                                 peers => [{"127.0.0.1", PB}]}),
    ok = toroco:add_device(b, toroco_udp_link, #{port => PB, inputs => [reply], outputs => [cmd],
                                                 peers => [{{127, 0, 0, 1}, PA}]}),
    ok = toroco:add_device(src, toroco_fake_sensor, #{outputs => [cmd, reply]}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [cmd, reply]}),
    ok = toroco:set_inputs(a, #{cmd => [{src, cmd}]}),
    ok = toroco:set_inputs(b, #{reply => [{src, reply}]}),
    ok = toroco:set_inputs(rec, #{cmd => [{b, cmd}], reply => [{a, reply}]}),
    Values = [{10, -10}, forward, 3.5, <<"text">>, [1, 2, 3], true, null, -7],
    %% one at a time: datagrams may be reordered in principle, not here
    [begin
         ok = toroco:inject({src, cmd}, V),
         await_input(rec, cmd, lists:sublist(Values, I))
     end || {I, V} <- lists:zip(lists:seq(1, length(Values)), Values)],
    ok = toroco:inject({src, reply}, #{status => ok}),
    await_input(rec, reply, [#{<<"status">> => <<"ok">>}]),
    ok = toroco:inject({src, cmd}, self()),
    ok = wait_until(fun() -> maps:get(unencodable, dev(a)) =:= 1 end),
    N = length(Values),
    #{sent := N, accepted := 1, rejected := 0, send_errors := 0} = dev(a),
    #{sent := 1, accepted := N, rejected := 0} = dev(b).

udp_latch_hold_unset(doc) ->
    ["A remote event can latch, hold and unset an output of the link"];
udp_latch_hold_unset(_Config) ->
    ok = toroco:add_device(l, toroco_udp_link, #{outputs => [mode]}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [mode]}),
    ok = toroco:set_inputs(rec, #{mode => [{l, mode}]}),
    #{port := Port} = dev(l),
    send_udp(Port, [<<"{\"output\":\"mode\",\"value\":\"auto\",\"latch\":true}">>]),
    await_input(rec, mode, [<<"auto">>]),
    #{outputs := #{mode := #{latch := {value, <<"auto">>}}}} = toroco:inspect(l),
    send_udp(Port, [<<"{\"output\":\"mode\",\"unset\":true}">>]),
    ok = wait_until(fun() ->
                            #{outputs := #{mode := #{latch := L}}} = toroco:inspect(l),
                            L =:= none
                    end),
    send_udp(Port, [<<"{\"output\":\"mode\",\"value\":\"manual\",\"hold\":\"infinity\"}">>]),
    await_input(rec, mode, [<<"auto">>, <<"manual">>]),
    #{inputs := #{mode := #{holds := [{{l, mode}, infinity}]}}} = toroco:inspect(rec).

udp_allow_list(doc) ->
    ["A UDP link with an allow-list drops datagrams from other addresses, counted"];
udp_allow_list(_Config) ->
    ok = toroco:add_device(l, toroco_udp_link, #{outputs => [cmd], allow => ["127.0.0.2"]}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [cmd]}),
    ok = toroco:set_inputs(rec, #{cmd => [{l, cmd}]}),
    #{port := Port} = dev(l),
    Event = <<"{\"output\":\"cmd\",\"value\":1}">>,
    send_udp(Port, [Event, Event]),
    ok = wait_until(fun() -> maps:get(rejected_by, dev(l)) =:= #{not_allowed => 2} end),
    {ok, S} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 2}}]),
    ok = gen_udp:send(S, {127, 0, 0, 1}, Port, <<"{\"output\":\"cmd\",\"value\":2}">>),
    gen_udp:close(S),
    await_input(rec, cmd, [2]),
    #{accepted := 1, rejected := 2} = dev(l).

udp_bad_datagrams(doc) ->
    ["Malformed datagrams at a UDP link are dropped and counted by reason"];
udp_bad_datagrams(_Config) ->
    ok = toroco:add_device(l, toroco_udp_link, #{outputs => [cmd], max_datagram => 100}),
    #{port := Port} = dev(l),
    Bad = [{<<"not json">>, not_json},
           {<<"{\"output\":\"cmd\",\"value\":1">>, not_json},
           {<<"42">>, not_object},
           {<<"{\"value\":1}">>, no_output},
           {<<"{\"output\":\"launch\",\"value\":1}">>, unknown_output},
           {<<"{\"output\":[\"cmd\"],\"value\":1}">>, bad_field},
           {<<"{\"output\":\"cmd\"}">>, no_value},
           {<<"{\"output\":\"cmd\",\"value\":\"zzz_not_an_atom_yet\",\"as\":\"atom\"}">>, bad_value},
           {binary:copy(<<"{}">>, 100), oversized}],
    send_udp(Port, [B || {B, _} <- Bad]),
    ok = wait_until(fun() -> maps:get(rejected, dev(l)) =:= length(Bad) end),
    Expected = lists:foldl(fun({_, R}, Acc) -> maps:update_with(R, fun(N) -> N + 1 end, 1, Acc) end,
                           #{}, Bad),
    ?assertEqual(Expected, maps:get(rejected_by, dev(l))),
    #{accepted := 0} = dev(l).

%%% ---------------------------------------------------------------------
%%% TCP
%%% ---------------------------------------------------------------------

tcp_round_trip(doc) ->
    ["TCP clients send events as lines (split, CRLF) and every client gets each input"];
tcp_round_trip(_Config) ->
    {Port, _} = tcp_rig(#{}),
    C1 = connect(Port),
    C2 = connect(Port),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 2 end),
    ok = gen_tcp:send(C1, <<"{\"output\":\"cmd\",\"value\":[1,2],\"as\":\"tuple\"}\n">>),
    %% one line in three pieces, with a CRLF ending
    [ok = gen_tcp:send(C2, Piece) || Piece <- [<<"{\"outp">>, <<"ut\":\"cmd\",\"va">>,
                                               <<"lue\":\"stop\",\"as\":\"atom\"}\r\n">>]],
    %% two connections: each line arrives, in no promised order between them
    await_connections(rec, cmd, [[{1, 2}], [stop]]),
    ok = toroco:inject({src, status}, {battery, 87}),
    Event = #{<<"input">> => <<"status">>, <<"value">> => [<<"battery">>, 87],
              <<"as">> => <<"tuple">>},
    ?assertEqual(Event, recv_event(C1)),
    ?assertEqual(Event, recv_event(C2)),
    #{accepted := 2, rejected := 0, sent := 2, clients := 2, connections := 2} = dev(t),
    gen_tcp:close(C1),
    gen_tcp:close(C2),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 0 end).

tcp_allow_list_and_max_clients(doc) ->
    ["Connections from outside the allow-list, or beyond max_clients, are closed and counted"];
tcp_allow_list_and_max_clients(_Config) ->
    %% min_age: the third is refused, not admitted in place of an older one
    {Port, _} = tcp_rig(#{allow => [{127, 0, 0, 2}], max_clients => 2, min_age => 60000}),
    Refused = connect(Port),
    ?assertEqual({error, closed}, gen_tcp:recv(Refused, 0, ?WAIT)),
    C1 = connect(Port, {127, 0, 0, 2}),
    C2 = connect(Port, {127, 0, 0, 2}),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 2 end),
    Third = connect(Port, {127, 0, 0, 2}),
    ?assertEqual({error, closed}, gen_tcp:recv(Third, 0, ?WAIT)),
    #{refused_by := #{not_allowed := 1, too_many_clients := 1}, clients := 2} = dev(t),
    ok = gen_tcp:send(C2, <<"{\"output\":\"cmd\",\"value\":7}\n">>),
    await_input(rec, cmd, [7]),
    [gen_tcp:close(S) || S <- [Refused, C1, C2, Third]],
    ok.

tcp_garbage_and_partial_lines(doc) ->
    ["Garbage, an oversized line and a disconnect mid-line are counted; "
     "the other client is unaffected"];
tcp_garbage_and_partial_lines(_Config) ->
    {Port, _} = tcp_rig(#{max_line => 4096}),
    Good = connect(Port),
    Bad = connect(Port),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 2 end),
    rand:seed(exsss, {1, 2, 3}),
    Garbage = [garbage_line() || _ <- lists:seq(1, 200)],
    ok = gen_tcp:send(Bad, [[G, $\n] || G <- Garbage]),
    %% 200 KB without a newline, in 4 KB pieces; the good client talks meanwhile
    [begin
         ok = gen_tcp:send(Bad, binary:copy(<<"x">>, 4096)),
         case I rem 10 of
             0 -> ok = gen_tcp:send(Good, <<"{\"output\":\"cmd\",\"value\":",
                                            (integer_to_binary(I))/binary, "}\n">>);
             _ -> ok
         end
     end || I <- lists:seq(1, 50)],
    %% the end of the oversized line, then a good line on the bad connection
    ok = gen_tcp:send(Bad, <<"tail of it\n{\"output\":\"cmd\",\"value\":\"after\"}\n">>),
    await_connections(rec, cmd, [[10, 20, 30, 40, 50], [<<"after">>]]),
    ok = gen_tcp:send(Bad, <<"{\"output\":\"cmd\",\"val">>),
    ok = gen_tcp:close(Bad),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 1 end),
    #{rejected_by := By, rejected := Rejected, accepted := 6} = dev(t),
    ct:pal("garbage lines: 200, rejected ~b by reason ~p", [Rejected, By]),
    ?assertMatch(#{oversized := 1, partial_line := 1}, By),
    ?assertEqual(200 + 2, Rejected),
    ok = toroco:inject({src, status}, ok),
    ?assertMatch({ok, <<"{", _/binary>>}, gen_tcp:recv(Good, 0, ?WAIT)),
    gen_tcp:close(Good).

tcp_connect_cycles(doc) ->
    ["100 connect/disconnect cycles (half mid-line) leave no client, port or memory behind"];
tcp_connect_cycles(_Config) ->
    %% This case is about leftovers: the bounds on strangers (line timeout,
    %% shedding of the longest idle, per-address share) are kept out of it.
    {Port, Pid} = tcp_rig(#{line_timeout => 60000, min_age => 60000, max_per_peer => 8}),
    Good = connect(Port),
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 1 end),
    Ports0 = length(erlang:ports()),
    _ = erlang:garbage_collect(Pid),
    {memory, Mem0} = process_info(Pid, memory),
    [begin
         S = connect(Port),
         case I rem 2 of
             0 -> ok = gen_tcp:send(S, <<"{\"output\":\"cmd\",\"value\":", (binary:copy(<<"1">>, 3000))/binary>>);
             1 -> ok
         end,
         gen_tcp:close(S)
     end || I <- lists:seq(1, 100)],
    %% Every connection is counted: served, or refused while eight were
    %% still open (a busy machine closes them later than they come).
    ok = wait_until(fun() -> #{clients := C, connections := N, refused := R} = dev(t),
                             {C, N + R} =:= {1, 101} end),
    _ = erlang:garbage_collect(Pid),
    {memory, Mem1} = process_info(Pid, memory),
    {message_queue_len, 0} = process_info(Pid, message_queue_len),
    Ports1 = length(erlang:ports()),
    #{rejected_by := By} = dev(t),
    ct:pal("ports ~b -> ~b, link memory ~b -> ~b bytes, rejected ~p", [Ports0, Ports1, Mem0, Mem1, By]),
    ?assert(Ports1 =< Ports0 + 2),
    ?assert(Mem1 < Mem0 + 200000),
    %% The 50 half lines are counted as such, but for those of connections
    %% refused or gone before the device served them.
    [partial_line] = maps:keys(By),
    ?assert(maps:get(partial_line, By) =< 50 andalso maps:get(partial_line, By) >= 25),
    ok = gen_tcp:send(Good, <<"{\"output\":\"cmd\",\"value\":\"still here\"}\n">>),
    await_input(rec, cmd, [<<"still here">>]),
    ok = toroco:inject({src, status}, 1),
    ?assertEqual(#{<<"input">> => <<"status">>, <<"value">> => 1}, recv_event(Good)),
    gen_tcp:close(Good).

tcp_silent_clients_shed(doc) ->
    ["8 silent clients hold every slot: a 9th client's line is delivered within 2 s of "
     "its connect, the longest-idle silent one closed for it and counted"];
tcp_silent_clients_shed(_Config) ->
    MinAge = 200,
    {Port, _} = tcp_rig(#{max_clients => 8, max_per_peer => 8, min_age => MinAge,
                          line_timeout => 60000}),
    Silent = [connect(Port) || _ <- lists:seq(1, 8)],
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 8 end),
    %% the silent ones must be min_age old to be shed: a known wait
    toroco_test_lib:quiet(MinAge),
    T0 = erlang:monotonic_time(millisecond),
    Ninth = connect(Port, {127, 0, 0, 2}),
    ok = gen_tcp:send(Ninth, <<"{\"output\":\"cmd\",\"value\":9}\n">>),
    ok = toroco_fake_actuator:await(rec, fun(H) -> [V || {cmd, V, _} <- H] =:= [9] end, 2000),
    Took = erlang:monotonic_time(millisecond) - T0,
    ct:pal("the 9th client's line delivered ~b ms after its connect", [Took]),
    ?assert(Took < 2000),
    %% the first silent client was the longest idle: it is the one closed
    [First | Others] = Silent,
    ?assertEqual({error, closed}, gen_tcp:recv(First, 0, ?WAIT)),
    #{clients := 8, closed_by := #{shed := 1}, refused := 0} = dev(t),
    [?assertEqual({error, timeout}, gen_tcp:recv(S, 0, 0)) || S <- Others],
    [gen_tcp:close(S) || S <- [Ninth | Silent]],
    ok.

tcp_line_and_idle_timeouts(doc) ->
    ["A client silent since its connect, or with a line begun and not ended, is closed "
     "after line_timeout; one quiet since its last line after idle_timeout; each counted"];
tcp_line_and_idle_timeouts(_Config) ->
    {LineT, IdleT} = {300, 900},
    {Port, _} = tcp_rig(#{line_timeout => LineT, idle_timeout => IdleT}),
    T0 = erlang:monotonic_time(millisecond),
    Silent = connect(Port),
    Half = connect(Port),
    Quiet = connect(Port),
    ok = gen_tcp:send(Half, <<"{\"output\":\"cmd\",\"value\":1}\n{\"output\":">>),
    ok = gen_tcp:send(Quiet, <<"{\"output\":\"cmd\",\"value\":2}\n">>),
    await_connections(rec, cmd, [[1], [2]]),
    Closed = fun(S) -> {gen_tcp:recv(S, 0, ?WAIT), erlang:monotonic_time(millisecond) - T0} end,
    {{error, closed}, TSilent} = Closed(Silent),
    {{error, closed}, THalf} = Closed(Half),
    {{error, closed}, TQuiet} = Closed(Quiet),
    ct:pal("closed after ~b ms (silent), ~b ms (half a line), ~b ms (quiet); "
           "line_timeout ~b, idle_timeout ~b", [TSilent, THalf, TQuiet, LineT, IdleT]),
    ?assert(TSilent >= LineT andalso THalf >= LineT andalso TQuiet >= IdleT),
    ?assert(TQuiet > THalf),
    ?assertMatch(#{clients := 0, closed_by := #{line_timeout := 2, idle_timeout := 1},
                   rejected_by := #{partial_line := 1}}, dev(t)),
    [gen_tcp:close(S) || S <- [Silent, Half, Quiet]],
    ok.

tcp_per_peer_limit(doc) ->
    ["One address holds at most max_per_peer connections; another address still gets in"];
tcp_per_peer_limit(_Config) ->
    {Port, _} = tcp_rig(#{max_per_peer => 2, min_age => 60000}),
    [A1, A2] = [connect(Port) || _ <- [1, 2]],
    ok = wait_until(fun() -> maps:get(clients, dev(t)) =:= 2 end),
    A3 = connect(Port),
    ?assertEqual({error, closed}, gen_tcp:recv(A3, 0, ?WAIT)),
    B = connect(Port, {127, 0, 0, 2}),
    ok = gen_tcp:send(B, <<"{\"output\":\"cmd\",\"value\":\"b\"}\n">>),
    await_input(rec, cmd, [<<"b">>]),
    #{clients := 3, refused_by := #{too_many_from_peer := 1}} = dev(t),
    [gen_tcp:close(S) || S <- [A1, A2, A3, B]],
    ok.

%%% ---------------------------------------------------------------------
%%% Helpers
%%% ---------------------------------------------------------------------

%% A TCP link `t' (input status from fake sensor `src', output cmd to
%% recorder `rec'); its port and pid.
tcp_rig(Opts) ->
    ok = toroco:add_device(t, toroco_tcp_link, Opts#{inputs => [status], outputs => [cmd]}),
    ok = toroco:add_device(src, toroco_fake_sensor, #{outputs => [status]}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [cmd]}),
    ok = toroco:set_inputs(t, #{status => [{src, status}]}),
    ok = toroco:set_inputs(rec, #{cmd => [{t, cmd}]}),
    #{port := Port} = dev(t),
    {Port, toroco:whereis(t)}.

%% One line from a client socket, decoded.
recv_event(S) ->
    {ok, Line} = gen_tcp:recv(S, 0, ?WAIT),
    <<Json:(byte_size(Line) - 1)/binary, $\n>> = Line,
    jiffy:decode(Json, [return_maps]).

connect(Port) ->
    connect(Port, {127, 0, 0, 1}).

connect(Port, From) ->
    {ok, S} = gen_tcp:connect({127, 0, 0, 1}, Port, [binary, {active, false}, {packet, line},
                                                     {ip, From}], ?WAIT),
    S.

garbage_line() ->
    Len = rand:uniform(300),
    Bytes = << <<(case rand:uniform(256) - 1 of $\n -> $x; B -> B end)>> || _ <- lists:seq(1, Len) >>,
    case Bytes of
        <<"\r">> -> <<"y">>;
        _ -> Bytes
    end.

free_udp_ports(N) ->
    Socks = [begin {ok, S} = gen_udp:open(0, [{ip, {127, 0, 0, 1}}]), S end
             || _ <- lists:seq(1, N)],
    Ports = [begin {ok, P} = inet:port(S), P end || S <- Socks],
    [gen_udp:close(S) || S <- Socks],
    Ports.

send_udp(Port, Datagrams) ->
    {ok, S} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}]),
    [ok = gen_udp:send(S, {127, 0, 0, 1}, Port, D) || D <- Datagrams],
    gen_udp:close(S).

dev(Name) ->
    maps:get(device, toroco:inspect(Name)).

%% Waits until `Input' of `A' got the lines of each connection, each
%% connection's in order, interleaved in any way (the device reads several
%% sockets; SPEC §4 promises order per source, and a source here is the
%% link's output, fed by whichever socket the VM hands over first).
await_connections(A, Input, PerConnection) ->
    All = lists:append(PerConnection),
    Pred = fun(H) ->
                   Got = [V || {I, V, _} <- H, I =:= Input],
                   lists:sort(Got) =:= lists:sort(All) andalso
                       lists:all(fun(Conn) -> [V || V <- Got, lists:member(V, Conn)] =:= Conn end,
                                 PerConnection)
           end,
    case toroco_fake_actuator:await(A, Pred, ?WAIT) of
        ok -> ok;
        {error, timeout} ->
            ct:fail({expected, Input, PerConnection, got, toroco_test_lib:values(A, Input)})
    end.

await_input(A, Input, Expected) ->
    toroco_test_lib:await_input(A, Input, Expected, ?WAIT).

wait_until(Fun) ->
    wait_until(Fun, ?WAIT).

