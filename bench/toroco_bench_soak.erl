%% The benchmark's soak section (run only when named:
%% TOROCO_BENCH_ONLY=soak make bench): the robot at 1 kHz for a long time
%% with every observer on at once, and whether the node's memory stays flat
%% and the robot loses nothing meanwhile. The chain of toroco_bench (source
%% → relay → sink, a router at each input) is paced at 1 ms (the source's
%% gen_statem timeouts on absolute deadlines, no busy loop) while
%%   - the dashboard (toroco_live:start/1) has one connected page (the
%%     suites' WebSocket client, which decodes every frame as a page does),
%%     its flight recorder on;
%%   - a Foxglove client (the suites' Node driver, test/js/fox_driver.js,
%%     on a raw WebSocket) is subscribed to every channel and reads every
%%     message;
%%   - every topic is recorded to MCAP.
%% Once a second it samples erlang:memory/0 and the process count. The
%% table gives each minute's medians, the first minute against the last,
%% what the source injected and the sink got, what each observer dropped or
%% received, the recording's size, and two verdicts: memory flat (first and
%% last minute's medians within 10 %) and nothing lost on the robot's side
%% (delivered = injected). Then where memory went: the node's live memory
%% (every process garbage-collected, which tells data kept from garbage
%% waiting in old heaps for a full sweep) at the end of the first minute
%% and at the end, and the processes that grew most in between.
%% TOROCO_SOAK_S sets the length in seconds (default 600, quick run or not).
-module(toroco_bench_soak).
-export([main/1]).

-define(PACE_MS, 1).
%% First and last minute's medians within this fraction: memory is flat.
-define(FLAT, 0.10).
%% How long the robot may take, after the last second, to emit and deliver
%% what it still owes.
-define(GRACE_MS, 10000).

main([Dir]) ->
    _ = toroco_bench:setup(Dir),
    Secs = list_to_integer(os:getenv("TOROCO_SOAK_S", "600")),
    Total = Secs * 1000 div ?PACE_MS,
    File = filename:join(Dir, "soak.mcap"),
    %% The sink tells this process of every arrival (a batch of one), so
    %% what it got is counted exactly.
    toroco_bench:chain(none, 1),
    Src = whereis(toroco_names:process(src)),
    ok = toroco_live_js:ensure_installed(),
    _ = application:load(toroco_live),
    ok = application:set_env(toroco_live, enabled, false),
    {ok, _} = application:ensure_all_started(toroco_live),
    {ok, #{http := Http, foxglove := Fox}} = toroco_live:start(#{http => 0, foxglove => 0}),
    ok = toroco_live:record(File, #{}),
    Page = reader(soak_page, fun() -> page(Http) end),
    Foxglove = reader(soak_foxglove, fun() -> foxglove(Fox) end),
    T0 = erlang:monotonic_time(millisecond),
    Src ! {run, {paced, ?PACE_MS}, Total},
    {Samples, {Then, LiveThen}, Got} = sample(T0, Secs, min(60, Secs), [], none, 0),
    {Injected, Delivered} = settle(Src, Total, Got, erlang:monotonic_time(millisecond) + ?GRACE_MS),
    Grown = grown(Then, proc_mems()),
    Live = {LiveThen, live_memory()},
    Frames = stop_reader(Page),
    Fx = stop_reader(Foxglove),
    #{tap_dropped := HubDropped} = toroco_live_hub:stats(),
    #{dropped := FlightDropped} = toroco_rec:window(),
    {ok, #{messages := Recorded, dropped := RecDropped}} = toroco_live:stop_recording(),
    ok = toroco_live:stop(),
    table(#{secs => Secs, samples => lists:reverse(Samples), injected => Injected,
            delivered => Delivered, hub_dropped => HubDropped, flight_dropped => FlightDropped,
            recorded => Recorded, rec_dropped => RecDropped, bytes => filelib:file_size(File),
            frames => maps:get(frames, Frames), fox => Fx, grown => Grown, live => Live}, Dir),
    halt(0).

%%====================================================================
%% Sampling
%%====================================================================

%% One sample a second, on absolute deadlines, counting the sink's
%% arrivals in between; at second `Snap' (the end of the first minute),
%% after its sample, each process's memory and then the live memory.
%% Returns the samples (newest first), that snapshot and the arrivals.
sample(T0, Secs, Snap, Acc, Then, Got) when length(Acc) < Secs ->
    K = length(Acc) + 1,
    Arrived = arrivals(T0 + K * 1000, 0),
    Mem = maps:from_list(erlang:memory()),
    S = #{mem => Mem, own => own_memory(), procs => erlang:system_info(process_count),
          arrived => Arrived},
    Then1 = case K of
                Snap -> Procs = proc_mems(), {Procs, live_memory()};
                _ -> Then
            end,
    sample(T0, Secs, Snap, [S | Acc], Then1, Got + Arrived);
sample(_T0, _Secs, _Snap, Acc, Then, Got) ->
    {Acc, Then, Got}.

arrivals(Until, N) ->
    receive {sink_done, _, _, _} -> arrivals(Until, N + 1)
    after max(0, Until - erlang:monotonic_time(millisecond)) -> N
    end.

%% Until the source has emitted all `Total' and the sink has them all, or
%% `Deadline': {emitted, delivered}.
settle(Src, Total, Got, Deadline) ->
    Src ! {sent, self()},
    Sent = receive {sent, Src, S} -> S end,
    Left = Deadline - erlang:monotonic_time(millisecond),
    case Sent =:= Total andalso Got =:= Sent orelse Left =< 0 of
        true -> {Sent, Got};
        false -> settle(Src, Total, Got + arrivals(erlang:monotonic_time(millisecond) + min(100, Left), 0),
                        Deadline)
    end.

%% What the benchmark's own processes hold: this one (its samples), the
%% clients' readers and the page's socket. The page and the Foxglove client
%% are a browser and Foxglove on another machine in real use, not part of
%% the robot's node.
own_memory() ->
    lists:sum([M || P <- [self() | [whereis(N) || N <- [soak_page, soak_page_socket, soak_foxglove]]],
                    is_pid(P), {memory, M} <- [erlang:process_info(P, memory)]]).

%% The node's memory once every process has been garbage-collected.
live_memory() ->
    _ = [erlang:garbage_collect(P) || P <- processes()],
    erlang:memory(total).

proc_mems() ->
    maps:from_list([{P, M} || P <- processes(), {memory, M} <- [erlang:process_info(P, memory)]]).

%% The five processes alive at both times that grew most (with their
%% message queues at the end), and what processes started since `Then'
%% hold at the end.
grown(Then, Now) ->
    Both = [{M - maps:get(P, Then), P, maps:get(P, Then), M}
            || {P, M} <- maps:to_list(Now), is_map_key(P, Then)],
    Top = lists:sublist(lists:reverse(lists:sort(Both)), 5),
    New = maps:without(maps:keys(Then), Now),
    Queue = fun(P) -> case erlang:process_info(P, message_queue_len) of
                          {message_queue_len, Q} -> Q;
                          undefined -> 0
                      end
            end,
    #{top => [{who(P), Was, Is, Queue(P)} || {_, P, Was, Is} <- Top],
      new => {map_size(New), lists:sum(maps:values(New))}}.

%% A process's registered name, else its pid, what it was started with
%% and where it is now.
who(P) when P =:= self() ->
    "this benchmark (its samples)";
who(P) ->
    case erlang:process_info(P, [registered_name, dictionary, initial_call, current_function]) of
        [{registered_name, Name} | _] when is_atom(Name) -> atom_to_list(Name);
        [_, {dictionary, D}, {initial_call, Call}, {current_function, {M1, F1, A1}}] ->
            {M, F, A} = proplists:get_value('$initial_call', D, Call),
            lists:flatten(io_lib:format("~w (~w:~w/~w, in ~w:~w/~w)", [P, M, F, A, M1, F1, A1]));
        undefined -> pid_to_list(P)
    end.

%%====================================================================
%% The observers' clients
%%====================================================================

%% A process holding one client, registered as `Name': Start() connects
%% it and returns the function that takes its counts to the counts after
%% its next message (or a short wait), how to close it, and the counts to
%% start from. {stop, From} closes it and answers the counts.
reader(Name, Start) ->
    Parent = self(),
    Pid = spawn_link(fun() ->
                             true = register(Name, self()),
                             {Next, Close, Counts} = Start(),
                             Parent ! {self(), ready},
                             read(Next, Close, Counts)
                     end),
    receive {Pid, ready} -> Pid after 30000 -> error(observer_client_not_ready) end.

read(Next, Close, Counts) ->
    receive
        {stop, From} -> Close(), From ! {self(), Counts}
    after 0 -> read(Next, Close, Next(Counts))
    end.

stop_reader(Pid) ->
    Pid ! {stop, self()},
    receive {Pid, Counts} -> Counts end.

bump(K, N, Counts) -> maps:update_with(K, fun(X) -> X + N end, N, Counts).

%% A page: every frame the dashboard pushes, read and decoded.
page(Port) ->
    C = toroco_live_test_client:ws(Port, ""),
    true = register(soak_page_socket, C),
    {fun(Counts) -> receive {wsc, C, _} -> bump(frames, 1, Counts) after 200 -> Counts end end,
     fun() -> toroco_live_test_client:ws_close(C) end, #{frames => 0}}.

%% A Foxglove client subscribed to every channel the bridge advertises,
%% counting the messages it gets and the drops the bridge tells it of.
foxglove(Port) ->
    C = toroco_live_js:start("fox_driver.js"),
    Url = iolist_to_binary(io_lib:format("ws://127.0.0.1:~b/", [Port])),
    toroco_live_js:send(C, #{cmd => raw_connect, url => Url}),
    {ok, _, _} = toroco_live_js:await(C, fun(#{<<"ev">> := <<"raw_text">>, <<"msg">> := #{<<"op">> := Op}}) ->
                                                 Op =:= <<"advertise">>;
                                            (_) -> false
                                         end, 10000),
    toroco_live_js:send(C, #{cmd => raw_subscribe_all}),
    {ok, #{<<"count">> := Channels}, _} =
        toroco_live_js:await(C, fun(#{<<"ev">> := E}) -> E =:= <<"raw_subscribed">> end, 10000),
    Next = fun(Counts) ->
                   case toroco_live_js:await(C, fun(_) -> true end, 200) of
                       {ok, #{<<"ev">> := <<"raw_binary">>}, _} -> bump(messages, 1, Counts);
                       {ok, #{<<"ev">> := <<"raw_text">>,
                              <<"msg">> := #{<<"op">> := <<"status">>, <<"message">> := M}}, _} ->
                           %% "N messages were dropped: ..."
                           case string:to_integer(M) of
                               {N, <<" messages were dropped", _/binary>>} -> bump(dropped, N, Counts);
                               _ -> Counts
                           end;
                       {ok, _, _} -> Counts;
                       {error, {timeout, _}} -> Counts;
                       {error, Reason} -> error({foxglove_client, Reason})
                   end
           end,
    {Next, fun() -> toroco_live_js:stop(C) end, #{channels => Channels}}.

%%====================================================================
%% The table
%%====================================================================

table(#{secs := Secs, samples := Samples, injected := Injected, delivered := Delivered,
        fox := Fx, grown := #{top := Top, new := {NewN, NewBytes}}, live := {LiveThen, LiveEnd}} = R,
      Dir) ->
    Minutes = minutes(Samples),
    MiB = fun(B) -> B / 1048576 end,
    Med = fun(F, Ss) -> median([F(S) || S <- Ss]) end,
    Mem = fun(K) -> fun(#{mem := M}) -> maps:get(K, M) end end,
    Robot = fun(#{mem := #{total := T}, own := Own}) -> T - Own end,
    Row = fun({I, Ss}) ->
                  io_lib:format("| ~b | ~.1f | ~.1f | ~.1f | ~.1f | ~.1f | ~b | ~b |~n",
                                [I, MiB(Med(Mem(total), Ss)), MiB(Med(Robot, Ss)),
                                 MiB(Med(Mem(processes), Ss)), MiB(Med(Mem(binary), Ss)),
                                 MiB(Med(Mem(ets), Ss)), Med(fun(#{procs := P}) -> P end, Ss),
                                 lists:sum([A || #{arrived := A} <- Ss])])
          end,
    %% First and last minute's medians of F, and the change in %.
    Change = fun(F) ->
                     First = Med(F, element(2, hd(Minutes))),
                     Last = Med(F, element(2, lists:last(Minutes))),
                     {MiB(First), MiB(Last), 100 * (Last - First) / First}
             end,
    {First, Last, Whole} = Change(Mem(total)),
    {RFirst, RLast, Less} = Change(Robot),
    LiveChange = 100 * (LiveEnd - LiveThen) / LiveThen,
    Flat = fun(C) -> io_lib:format("~s (~ts~.1f %)", [yes(abs(C) =< 100 * ?FLAT), sign(C), C]) end,
    Lost = Injected - Delivered,
    Text = [io_lib:format("~n## Soak: ~b s at 1 kHz with the dashboard, a Foxglove client and a "
                          "recording~n~nThe chain source → relay → sink paced at ~b ms; one page "
                          "connected to the dashboard (flight recorder on), one Foxglove client "
                          "subscribed to all ~b channels, every topic recorded to MCAP. Node "
                          "memory sampled once a second; medians per minute. \"Less the "
                          "benchmark's own\" leaves out this benchmark's process (its samples), "
                          "the clients' readers and the page's socket. Live memory: with every "
                          "process garbage-collected, at the end of the first minute (after its "
                          "sample) and at the end.~n~n",
                          [Secs, ?PACE_MS, maps:get(channels, Fx)]),
            "| minute | memory MiB | less the benchmark's own MiB | processes MiB | binary MiB "
            "| ETS MiB | processes | events delivered |\n",
            "|---:|---:|---:|---:|---:|---:|---:|---:|\n",
            [Row(M) || M <- Minutes],
            io_lib:format("~n| | |~n|---|---:|~n"
                          "| memory, first minute → last minute | ~.1f → ~.1f MiB |~n"
                          "| less the benchmark's own, first minute → last minute | ~.1f → ~.1f MiB |~n"
                          "| live (every process garbage-collected), end of the first minute → end "
                          "| ~.1f → ~.1f MiB |~n"
                          "| events injected (source) | ~b |~n"
                          "| events delivered (sink) | ~b |~n"
                          "| tap events dropped: dashboard | ~b |~n"
                          "| tap events dropped: flight recorder (the recording's too) | ~b |~n"
                          "| recording: messages, dropped | ~b, ~b |~n"
                          "| recording size | ~.1f MiB |~n"
                          "| Foxglove client: messages received, drops it was told of | ~b, ~b |~n"
                          "| page: frames received | ~b |~n",
                          [First, Last, RFirst, RLast, MiB(LiveThen), MiB(LiveEnd), Injected, Delivered,
                           maps:get(hub_dropped, R), maps:get(flight_dropped, R),
                           maps:get(recorded, R), maps:get(rec_dropped, R), MiB(maps:get(bytes, R)),
                           maps:get(messages, Fx, 0), maps:get(dropped, Fx, 0), maps:get(frames, R)]),
            io_lib:format("~nMemory flat (first and last minute within ~b %): ~ts; less the "
                          "benchmark's own: ~ts; live: ~ts~n"
                          "Lost on the robot's side = 0: ~s (~b lost)~n",
                          [round(100 * ?FLAT), Flat(Whole), Flat(Less), Flat(LiveChange),
                           yes(Lost =:= 0), Lost]),
            io_lib:format("~nProcesses that grew most from the end of the first minute to the end "
                          "(~b processes started meanwhile hold ~.1f KiB):~n~n"
                          "| process | KiB then | KiB at the end | messages queued at the end |~n"
                          "|---|---:|---:|---:|~n",
                          [NewN, NewBytes / 1024]),
            [io_lib:format("| ~ts | ~.1f | ~.1f | ~b |~n", [W, Was / 1024, Is / 1024, Q])
             || {W, Was, Is, Q} <- Top]],
    io:format("~ts", [Text]),
    ok = file:write_file(filename:join(Dir, "soak.md"), unicode:characters_to_binary(Text)).

%% The samples in minutes: [{1, Samples} ...], the last one possibly short.
minutes(Samples) -> minutes(Samples, 1).

minutes([], _) -> [];
minutes(Ss, I) when length(Ss) =< 60 -> [{I, Ss}];
minutes(Ss, I) ->
    {M, Rest} = lists:split(60, Ss),
    [{I, M} | minutes(Rest, I + 1)].

median(Xs) -> lists:nth((length(Xs) + 1) div 2, lists:sort(Xs)).

sign(X) when X >= 0 -> "+";
sign(_) -> "".

yes(true) -> "yes";
yes(false) -> "no".
