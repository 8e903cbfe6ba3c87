%% Benchmark source: a behavior that emits timestamped events on `out' when
%% told to by the benchmark controller: closed loop (the next event when the
%% sink reports the previous one arrived), paced every N ms (absolute
%% deadlines, no drift), or open loop with a bounded window of events in flight.
%% `{sent, From}' asks how many events it has emitted since the last run began.
-module(toroco_bench_source).
-behaviour(toroco_behavior).
-export([interface/0, init/1, handle_input/4, handle_event/4]).

interface() -> #{inputs => [], outputs => [out]}.

init(P) -> {ok, idle, P}.

handle_input(_, _, _, _) -> keep_state_and_data.

now_ns() -> erlang:monotonic_time(nanosecond).

emit(Seq) -> {send, #{out => {now_ns(), Seq}}}.

handle_event(info, {run, closed, N}, S, D) ->
    handle_event(info, {run, {closed, 1}, N}, S, D);
handle_event(info, {run, {closed, F}, N}, _S, D) ->
    {next_state, {closed, N, F, 0}, D#{sent => 1}, [emit(1)]};
%% The next event goes when every one of the F receivers has the last one.
handle_event(info, {arrived, Seq}, {closed, N, F, Got}, D) when Got + 1 < F ->
    {next_state, {closed, N, F, Got + 1}, D#{last => Seq}};
handle_event(info, {arrived, Seq}, {closed, N, F, _}, D) when Seq < N ->
    {next_state, {closed, N, F, 0}, D#{sent => Seq + 1}, [emit(Seq + 1)]};
handle_event(info, {arrived, _}, {closed, _, _, _}, D) ->
    {next_state, idle, D};
handle_event(info, {run, {paced, Ms}, N}, _S, D) ->
    T0 = erlang:monotonic_time(millisecond),
    {next_state, {paced, Ms, N, T0}, D#{sent => 1},
     [emit(1), {{timeout, pace}, T0 + Ms, next, [{abs, true}]}]};
handle_event({timeout, pace}, next, {paced, Ms, N, T0}, D = #{sent := Sent}) when Sent < N ->
    Seq = Sent + 1,
    {keep_state, D#{sent := Seq},
     [emit(Seq) | case Seq < N of
                      true -> [{{timeout, pace}, T0 + Seq * Ms, next, [{abs, true}]}];
                      false -> []
                  end]};
handle_event(info, {run, {window, W}, N}, _S, D) ->
    window(0, W, N, D#{sent => 0});
handle_event(info, {acked, Acked}, {window, W, N, _}, D) ->
    window(Acked, W, N, D);
handle_event(info, {sent, From}, _S, D) ->
    From ! {sent, self(), maps:get(sent, D, 0)},
    keep_state_and_data;
handle_event(_Type, _Msg, _S, _D) ->
    keep_state_and_data.

%% Emits until `W' events are in flight (or all `N' are sent).
window(Acked, W, N, D = #{sent := Sent}) ->
    Upto = min(N, Acked + W),
    case Upto > Sent of
        true ->
            {next_state, {window, W, N, Acked}, D#{sent := Upto},
             [{send, #{out => {0, Seq}}} || Seq <- lists:seq(Sent + 1, Upto)]};
        false ->
            {next_state, {window, W, N, Acked}, D}
    end.
