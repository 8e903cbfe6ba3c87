%% Benchmark sink: a device that takes each delivery's latency from the
%% timestamp the source put in it, tells the source (closed loop: every event;
%% windowed: every `ack_every' events), and reports to the controller when
%% `expect' events have arrived.
-module(toroco_bench_sink).
-behaviour(toroco_device).
-export([interface/1, init/2, handle_input/4, handle_event/4]).
-export([arrived/7]).

interface(_) -> #{inputs => [in], outputs => []}.

init(_Name, Opts) ->
    {ok, sinking, Opts#{n => 0, lat => []}}.

handle_input(in, {_, _} = Ev, _S, D = #{n := N, expect := Expect, mode := Mode,
                                         source := Src, controller := Ctl, lat := Lat}) ->
    case arrived(Ev, Mode, Expect, Src, Ctl, N, Lat) of
        done -> {keep_state, D#{n := 0, lat := []}};
        {N1, Lat1} -> {keep_state, D#{n := N1, lat := Lat1}}
    end;
handle_input(in, _Other, _S, _D) ->
    keep_state_and_data.

handle_event(info, {configure, Opts}, _S, D) ->
    {keep_state, maps:merge(D, Opts#{n => 0, lat => []})};
handle_event(_, _, _, _) -> keep_state_and_data.

%% One arrival at a sink, this device's or the raw reference's
%% (`toroco_bench_raw'), so both do the same work per event: its latency
%% kept (a zero timestamp is a warm-up event), the source told as the mode
%% says, the controller told once `Expect' have arrived. Returns `done' then,
%% else the new count and latencies.
-spec arrived({integer(), term()}, closed | {window, pos_integer()} | term(), pos_integer(),
              pid(), pid(), non_neg_integer(), [integer()]) ->
          done | {pos_integer(), [integer()]}.
arrived({T0, Seq}, Mode, Expect, Src, Ctl, N, Lat) ->
    Now = erlang:monotonic_time(nanosecond),
    N1 = N + 1,
    Lat1 = case T0 of 0 -> Lat; _ -> [Now - T0 | Lat] end,
    case Mode of
        closed -> Src ! {arrived, Seq};
        {window, Every} when N1 rem Every =:= 0 -> Src ! {acked, N1};
        _ -> ok
    end,
    case N1 >= Expect of
        true -> Ctl ! {sink_done, self(), Now, lists:reverse(Lat1)}, done;
        false -> {N1, Lat1}
    end.
