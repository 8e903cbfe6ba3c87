%% Benchmark, section "Lua behaviors" (`make bench', TOROCO_BENCH_ONLY=lua):
%% the internal test's chain source -> relay -> relay -> sink with both relays
%% in Lua (bench/lua/relay.lua), closed loop (one event in flight: latency)
%% and open loop (a window of events in flight: throughput), the same chain
%% with the Erlang relay beside it, and the memory of an idle Lua behavior.
%% Beside them, a reference with no Lua and no VM (bench/pipe_pingpong.c): a
%% one-byte round trip between two C processes over pipes, the least one
%% activation of a Lua behavior costs, since the runtime and lua_port
%% exchange each event and its reply that way. With both relays in Lua the
%% closed loop makes two such round trips in series on top of the event
%% path the Erlang row measures: the table says what floor that gives.
-module(toroco_bench_lua).
-behaviour(toroco_device).

-export([main/1]).
-export([interface/1, init/2, handle_input/4]).

-define(N, 10000).
-define(WINDOW, 64).
-define(IDLE, 100).

main([Dir | _]) ->
    N = case os:getenv("TOROCO_BENCH_QUICK") of "1" -> 2000; _ -> ?N end,
    {ok, _} = application:ensure_all_started(toroco_hw),
    {ok, _} = application:ensure_all_started(toroco_lua),
    Relay = filename:absname("bench/lua/relay.lua"),
    Rows = [chain(lua, Relay, N), chain(erlang, Relay, N)],
    Pipe = pipe(filename:join(filename:dirname(Dir), "pipe_pingpong"), N),
    Idle = idle(Relay),
    Out = io_lib:format(
            "~n### Lua behaviors~n~n"
            "Internal test, source -> relay -> relay -> sink, ~b events, the relays in Lua "
            "(one lua_port program) and in Erlang:~n~n"
            "| relays | closed loop p50 | p99 | open loop (window ~b) |~n|---|---|---|---|~n"
            "~ts~ts~n"
            "Idle Lua behavior (one trigger, ~b of them): ~.1f KiB of Lua state + ~.1f KiB "
            "for its gen_statem, ~.1f KiB in all.~n",
            [N, ?WINDOW,
             [io_lib:format("| ~p | ~.1f \x{b5}s | ~.1f \x{b5}s | ~b events/s |~n", [K, P50, P99, Rate])
              || #{kind := K, p50 := P50, p99 := P99, rate := Rate} <- Rows],
             floor(Pipe, Rows),
             ?IDLE, maps:get(lua_kib, Idle), maps:get(process_kib, Idle),
             maps:get(lua_kib, Idle) + maps:get(process_kib, Idle)]),
    ok = io:setopts([{encoding, unicode}]),
    io:put_chars(Out),
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    ok = file:write_file(filename:join(Dir, "lua.md"), unicode:characters_to_binary(Out)),
    halt(0).

chain(Kind, Relay, N) ->
    ok = toroco:add_device(src, toroco_fake_sensor, #{outputs => [out]}),
    ok = toroco:add_device(sink, ?MODULE, #{controller => self()}),
    [ok = add_relay(Kind, R, Relay) || R <- [r1, r2]],
    ok = toroco:set_inputs(r1, #{in => [{src, out}]}),
    ok = toroco:set_inputs(r2, #{in => [{r1, out}]}),
    ok = toroco:set_inputs(sink, #{in => [{r2, out}]}),
    _ = closed(1000),                                  % warm up
    Lat = lists:sort(closed(N)),
    Rate = open(N),
    [ok = toroco:remove_behavior(R) || R <- [r1, r2]],
    [ok = toroco:remove_device(D) || D <- [src, sink]],
    #{kind => Kind, p50 => pct(Lat, 0.50), p99 => pct(Lat, 0.99), rate => Rate}.

add_relay(lua, Name, File) -> toroco_lua:add_behavior(Name, #{file => File});
add_relay(erlang, Name, _) -> toroco:add_behavior(Name, toroco_bench_relay, #{}).

%% One event in flight: µs from inject to the sink.
closed(N) ->
    [begin
         T0 = erlang:monotonic_time(nanosecond),
         ok = toroco:inject({src, out}, Seq),
         receive {got, Seq} -> (erlang:monotonic_time(nanosecond) - T0) / 1000 end
     end || Seq <- lists:seq(1, N)].

%% At most ?WINDOW events in flight; events per second.
open(N) ->
    T0 = erlang:monotonic_time(microsecond),
    open(1, 0, N),
    round(N * 1.0e6 / (erlang:monotonic_time(microsecond) - T0)).

open(_Next, Got, N) when Got >= N -> ok;
open(Next, Got, N) when Next =< N, Next - Got =< ?WINDOW ->
    ok = toroco:inject({src, out}, Next),
    open(Next + 1, Got, N);
open(Next, Got, N) ->
    receive {got, _} -> open(Next, Got + 1, N) end.

%% ?IDLE idle Lua behaviors: the mean of their Lua heaps and processes.
idle(Relay) ->
    Names = [list_to_atom("idle" ++ integer_to_list(K)) || K <- lists:seq(1, ?IDLE)],
    [ok = toroco_lua:add_behavior(B, #{file => Relay}) || B <- Names],
    Lua = lists:sum([element(2, toroco_lua:memory(B)) || B <- Names]),
    Proc = lists:sum([element(2, erlang:process_info(whereis(toroco_names:process(B)), memory))
                      || B <- Names]),
    [ok = toroco:remove_behavior(B) || B <- Names],
    #{lua_kib => Lua / ?IDLE / 1024, process_kib => Proc / ?IDLE / 1024}.

%% The reference: Count pipe round trips between two C processes, or none
%% if the program is not built.
pipe(Prog, Count) ->
    case filelib:is_regular(Prog) of
        false -> none;
        true ->
            Rtts = lists:sort([list_to_integer(Ns) / 1000
                               || "rtt " ++ Ns <- string:lexemes(os:cmd(Prog ++ " " ++ integer_to_list(Count)),
                                                                 "\n")]),
            #{p50 => pct(Rtts, 0.50), p99 => pct(Rtts, 0.99)}
    end.

floor(none, _Rows) ->
    "";
floor(#{p50 := P50, p99 := P99}, Rows) ->
    [Erlang] = [E || #{kind := erlang, p50 := E} <- Rows],
    io_lib:format("| a pipe round trip between two C processes (no Lua, no VM) | ~.1f \x{b5}s | "
                  "~.1f \x{b5}s | \x{2013} |~n~n"
                  "The floor of the closed loop with both relays in Lua, each activation a round "
                  "trip to lua_port: 2 \x{d7} ~.1f + ~.1f (the Erlang relays' p50) = ~.1f \x{b5}s.~n",
                  [P50, P99, P50, Erlang, 2 * P50 + Erlang]).

pct(Sorted, P) ->
    lists:nth(max(1, round(P * length(Sorted))), Sorted).

%% The sink: each delivery to the controller.
interface(_) -> #{inputs => [in], outputs => []}.
init(_Name, #{controller := C}) -> {ok, sinking, C}.
handle_input(in, V, _S, C) -> C ! {got, V}, keep_state_and_data.
