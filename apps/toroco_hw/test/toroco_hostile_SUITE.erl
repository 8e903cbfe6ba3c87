%% Hostile input at the UDP devices: 100,000 datagrams each, random and
%% malformed ones with valid ones interleaved. Nothing may crash, every
%% datagram must be counted once (accepted + rejected = sent) and every
%% valid one delivered, in order.
%%
%% The sender waits for the device to catch up every few hundred datagrams
%% (or 96 KiB): what is measured is the device, not the kernel's receive
%% buffer, which drops datagrams silently when it overflows.
-module(toroco_hostile_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-export([all/0, suite/0, init_per_testcase/2, end_per_testcase/2]).
-export([camera_hostile/1, udp_link_hostile/1]).
-export([log/2]).


-define(N, 100000).
-define(WINDOW, 256).
-define(WINDOW_BYTES, 98304).
-define(SEED, {17, 42, 2015}).

suite() ->
    [{timetrap, {minutes, 5}}].

all() ->
    [camera_hostile, udp_link_hostile].

init_per_testcase(_Case, Config) ->
    ok = toroco_test_lib:start(),
    Config.

end_per_testcase(_Case, _Config) ->
    toroco_test_lib:stop().

%%% ---------------------------------------------------------------------
%%% Cases
%%% ---------------------------------------------------------------------

camera_hostile(doc) ->
    ["100,000 hostile datagrams at udp_camera: no crash, every one counted, the valid ones delivered"];
camera_hostile(_Config) ->
    ok = toroco:add_device(cam, toroco_udp_camera, #{}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [red, trq]}),
    ok = toroco:set_inputs(rec, #{red => [{cam, update_red}], trq => [{cam, update_trq}]}),
    run(cam, fun camera_datagram/1,
        fun(Valid) ->
                Red = [V || {update_red, V} <- Valid],
                Trq = [V || {update_trq, V} <- Valid],
                await_values(rec, red, Red),
                await_values(rec, trq, Trq),
                {length(Red), length(Trq)}
        end).

udp_link_hostile(doc) ->
    ["100,000 hostile datagrams at udp_link: no crash, every one counted, the valid ones delivered"];
udp_link_hostile(_Config) ->
    ok = toroco:add_device(link, toroco_udp_link, #{outputs => [cmd, mode]}),
    ok = toroco:add_device(rec, toroco_fake_actuator, #{inputs => [cmd]}),
    ok = toroco:set_inputs(rec, #{cmd => [{link, cmd}]}),
    run(link, fun link_datagram/1,
        fun(Valid) ->
                Cmd = [V || {cmd, V} <- Valid],
                await_values(rec, cmd, Cmd),
                length(Cmd)
        end).

%% Sends ?N datagrams made by Gen(I) -> {valid, Datagram, Expected} |
%% {Kind, Datagram}, then checks the counts and lets Check look at the
%% deliveries.
run(Dev, Gen, Check) ->
    _ = rand:seed(exsss, ?SEED),
    #{port := Port} = dev(Dev),
    ok = logger:add_handler(hostile_errors, ?MODULE, #{level => error, config => #{pid => self()}}),
    DevPid = toroco:whereis(Dev),
    {ok, S} = gen_udp:open(0, [binary, {ip, {127, 0, 0, 1}}, {sndbuf, 1048576}]),
    T0 = erlang:monotonic_time(millisecond),
    {Kinds, RevValid, Bytes} = send_all(S, Port, Dev, Gen, 1, 0, 0, #{}, [], 0),
    ok = await_counted(Dev, ?N),
    Ms = max(1, erlang:monotonic_time(millisecond) - T0),
    gen_udp:close(S),
    ok = logger:remove_handler(hostile_errors),
    Errors = logged_errors(),
    Valid = lists:reverse(RevValid),
    Delivered = Check(Valid),
    #{accepted := Accepted, rejected := Rejected, rejected_by := By} = dev(Dev),
    ct:pal("~p: sent ~b datagrams (~b bytes) in ~b ms (~b/s)~n"
           "  by kind ~p~n"
           "  accepted ~b, rejected ~b, accepted + rejected = ~b~n"
           "  rejected by reason ~p~n"
           "  valid delivered ~p; device pid unchanged: ~p; logged errors: ~b",
           [Dev, ?N, Bytes, Ms, ?N * 1000 div Ms, Kinds, Accepted, Rejected,
            Accepted + Rejected, By, Delivered, toroco:whereis(Dev) =:= DevPid,
            length(Errors)]),
    ?assertEqual(DevPid, toroco:whereis(Dev)),
    ?assertEqual(?N, Accepted + Rejected),
    ?assertEqual(length(Valid), Accepted),
    ?assertEqual([], Errors),
    {message_queue_len, 0} = process_info(DevPid, message_queue_len),
    ok.

send_all(_S, _Port, _Dev, _Gen, I, _Win, _WinBytes, Kinds, Valid, Bytes) when I > ?N ->
    {Kinds, Valid, Bytes};
send_all(S, Port, Dev, Gen, I, Win, WinBytes, Kinds, Valid, Bytes) ->
    {Kind, D, Valid1} = case Gen(I) of
                            {valid, Dg, Expected} -> {valid, Dg, [Expected | Valid]};
                            {K, Dg} -> {K, Dg, Valid}
                        end,
    ok = gen_udp:send(S, {127, 0, 0, 1}, Port, D),
    Size = byte_size(D),
    Kinds1 = maps:update_with(Kind, fun(N) -> N + 1 end, 1, Kinds),
    case Win + 1 >= ?WINDOW orelse WinBytes + Size >= ?WINDOW_BYTES of
        true ->
            ok = await_counted(Dev, I),
            send_all(S, Port, Dev, Gen, I + 1, 0, 0, Kinds1, Valid1, Bytes + Size);
        false ->
            send_all(S, Port, Dev, Gen, I + 1, Win + 1, WinBytes + Size, Kinds1, Valid1,
                     Bytes + Size)
    end.

%% A logger handler for the run: every error (a crash report included)
%% reaches the test process. The devices log bad input as warnings.
log(Event, #{config := #{pid := Pid}}) ->
    Pid ! {logged_error, maps:get(msg, Event)},
    ok.

logged_errors() ->
    receive {logged_error, Msg} -> [Msg | logged_errors()]
    after 0 -> []
    end.

%%% ---------------------------------------------------------------------
%%% Generators
%%% ---------------------------------------------------------------------

camera_datagram(_I) ->
    case rand:uniform(100) of
        R when R =< 10 -> valid_sighting();
        R when R =< 30 -> {random_bytes, random_bytes(rand:uniform(301) - 1)};
        R when R =< 45 -> {truncated_json, truncate(element(2, valid_sighting()))};
        R when R =< 60 -> {wrong_types, pick(wrong_type_sightings())};
        R when R =< 70 -> {huge_numbers, pick(huge_sightings())};
        R when R =< 80 -> {unknown_colour, unknown_colour()};
        R when R =< 82 -> {payload_64k, big_payload(element(2, valid_sighting()))};
        R when R =< 90 -> {not_object, pick(non_objects())};
        _ -> {bad_object, pick(bad_sightings())}
    end.

valid_sighting() ->
    {Colour, Out} = pick([{<<"red">>, update_red}, {<<"blue">>, update_trq}]),
    case rand:uniform(5) of
        1 ->
            {valid, jiffy:encode(#{<<"color">> => Colour, <<"none">> => true}), {Out, none}};
        _ ->
            X = rand:uniform(641) - 321,
            Y = rand:uniform(481) - 241,
            {valid, jiffy:encode(#{<<"color">> => Colour, <<"x">> => X, <<"y">> => Y,
                                   <<"area">> => rand:uniform(10000),
                                   <<"t">> => erlang:unique_integer([positive])}),
             {Out, {X, Y}}}
    end.

wrong_type_sightings() ->
    [<<"{\"color\":\"red\",\"x\":\"10\",\"y\":5}">>,
     <<"{\"color\":\"red\",\"x\":10,\"y\":5.5}">>,
     <<"{\"color\":7,\"x\":10,\"y\":5}">>,
     <<"{\"color\":[\"red\"],\"x\":10,\"y\":5}">>,
     <<"{\"color\":\"blue\",\"x\":{\"v\":1},\"y\":5}">>,
     <<"{\"color\":\"blue\",\"x\":null,\"y\":null}">>,
     <<"{\"color\":\"blue\",\"x\":true,\"y\":false}">>,
     <<"{\"color\":\"red\",\"none\":\"yes\"}">>,
     <<"{\"color\":\"red\",\"x\":1,\"y\":2,\"area\":\"big\"}">>,
     <<"{\"color\":\"red\",\"x\":1,\"y\":2,\"t\":1.5}">>].

huge_sightings() ->
    [<<"{\"color\":\"red\",\"x\":1e400,\"y\":5}">>,
     <<"{\"color\":\"red\",\"x\":123456789012345678901234567890,\"y\":5}">>,
     <<"{\"color\":\"blue\",\"x\":5,\"y\":-99999999999}">>,
     <<"{\"color\":\"blue\",\"x\":5,\"y\":6,\"t\":", (binary:copy(<<"9">>, 400))/binary, "}">>,
     <<"{\"color\":\"red\",\"x\":2000000,\"y\":0}">>].

unknown_colour() ->
    C = pick([<<"green">>, <<"RED">>, <<"">>, <<"redd">>, <<"bleu">>, <<"turquoise">>]),
    jiffy:encode(#{<<"color">> => C, <<"x">> => 1, <<"y">> => 2}).

non_objects() ->
    [<<"[]">>, <<"[1,2,3]">>, <<"\"red\"">>, <<"42">>, <<"null">>, <<"true">>,
     <<"[{\"color\":\"red\",\"x\":1,\"y\":2}]">>].

bad_sightings() ->
    [<<"{}">>, <<"{\"colour\":\"red\",\"x\":1,\"y\":2}">>, <<"{\"color\":\"red\",\"x\":1}">>,
     <<"{\"color\":\"blue\",\"none\":false}">>, <<"{\"x\":1,\"y\":2}">>,
     <<"{\"color\":\"red\",\"y\":1}">>].

link_datagram(I) ->
    case rand:uniform(100) of
        R when R =< 10 -> valid_event(I);
        R when R =< 30 -> {random_bytes, random_bytes(rand:uniform(301) - 1)};
        R when R =< 45 -> {truncated_json, truncate(element(2, valid_event(I)))};
        R when R =< 60 -> {wrong_types, pick(wrong_type_events())};
        R when R =< 70 -> {huge_numbers, pick(huge_events())};
        R when R =< 80 -> {unknown_output, unknown_output()};
        R when R =< 82 -> {payload_64k, big_payload(element(2, valid_event(I)))};
        R when R =< 90 -> {not_object, pick(non_objects())};
        _ -> {bad_object, pick(bad_events())}
    end.

valid_event(I) ->
    case rand:uniform(3) of
        1 -> {valid, jiffy:encode(#{<<"output">> => <<"cmd">>, <<"value">> => [I, -I],
                                    <<"as">> => <<"tuple">>}), {cmd, {I, -I}}};
        2 -> {valid, jiffy:encode(#{<<"output">> => <<"cmd">>, <<"value">> => I}), {cmd, I}};
        3 -> {valid, jiffy:encode(#{<<"input">> => <<"cmd">>, <<"value">> => <<"stop">>,
                                    <<"as">> => <<"atom">>}), {cmd, stop}}
    end.

wrong_type_events() ->
    [<<"{\"output\":7,\"value\":1}">>,
     <<"{\"output\":[\"cmd\"],\"value\":1}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"as\":\"tuple\"}">>,
     <<"{\"output\":\"cmd\",\"value\":\"nowhere_near_an_atom\",\"as\":\"atom\"}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"latch\":\"yes\"}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"hold\":-5}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"hold\":2.5}">>,
     <<"{\"output\":\"cmd\",\"unset\":\"no\"}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"as\":42}">>].

huge_events() ->
    [<<"{\"output\":\"cmd\",\"value\":1e400}">>,
     <<"{\"output\":\"cmd\",\"value\":1,\"hold\":123456789012345678901234567890}">>,
     <<"{\"output\":\"cmd\",\"value\":-1e999}">>].

unknown_output() ->
    O = pick([<<"launch">>, <<"CMD">>, <<"">>, <<"cmd ">>, <<"modes">>, <<"toroco:cmd">>]),
    jiffy:encode(#{<<"output">> => O, <<"value">> => 1}).

bad_events() ->
    [<<"{}">>, <<"{\"value\":1}">>, <<"{\"output\":\"cmd\"}">>,
     <<"{\"outputs\":\"cmd\",\"value\":1}">>, <<"{\"input\":5,\"value\":1}">>].

random_bytes(N) ->
    rand:bytes(N).

%% A valid object cut short: never valid JSON.
truncate(Bin) ->
    binary:part(Bin, 0, rand:uniform(byte_size(Bin) - 1) - 1).

%% 60-64 KiB: random bytes, or a valid object padded with spaces (valid
%% JSON, but longer than the device takes).
big_payload(Valid) ->
    Size = 61440 + rand:uniform(4000),
    case rand:uniform(2) of
        1 -> rand:bytes(Size);
        2 -> <<Valid/binary, (binary:copy(<<" ">>, Size - byte_size(Valid)))/binary>>
    end.

pick(L) ->
    lists:nth(rand:uniform(length(L)), L).

%%% ---------------------------------------------------------------------
%%% Helpers
%%% ---------------------------------------------------------------------

dev(Name) ->
    maps:get(device, toroco:inspect(Name)).

%% Waits until the device has counted `N' datagrams; fails with the counts
%% if it does not within 10 s (the kernel dropped some, or the device is
%% stuck).
await_counted(Dev, N) ->
    Counted = fun() -> #{accepted := A, rejected := R} = dev(Dev), A + R >= N end,
    case toroco_test_lib:poll(Counted, 10000) of
        ok -> ok;
        timeout -> ct:fail({not_counted, N, dev(Dev)})
    end.

%% As toroco_test_lib:await_input/4, failing with the counts only (the
%% lists are long).
await_values(A, Input, Expected) ->
    Pred = fun(H) -> [V || {I, V, _} <- H, I =:= Input] =:= Expected end,
    case toroco_fake_actuator:await(A, Pred, 30000) of
        ok -> ok;
        {error, timeout} ->
            ct:fail({expected, Input, length(Expected), got,
                     length(toroco_test_lib:values(A, Input))})
    end.
