%% The structural reference for the benchmark: as many processes as the
%% internal test's path has (source → router → relay → router → sink:
%% five), each a plain gen_statem (no runtime: no routers' cores, no tap,
%% no wiring), driven exactly as toroco_bench_raw's plain processes and
%% toroco_bench drive theirs. Beside the raw chain it splits the runtime's
%% ratio into what the structure costs (five gen_statems instead of five
%% receive loops) and what the runtime adds on top.
-module(toroco_bench_statem).
-behaviour(gen_statem).

-export([chain/3, stop/1]).
-export([callback_mode/0, init/1, handle_event/4]).

%% Starts the chain; returns the source, which takes {run, Mode, N}.
chain(Mode, N, Controller) ->
    {ok, Sink} = gen_statem:start(?MODULE, {sink, Mode, N, Controller}, []),
    Fwds = lists:foldl(fun(_, [Next | _] = Acc) ->
                               {ok, F} = gen_statem:start(?MODULE, {forward, Next}, []),
                               [F | Acc]
                       end, [Sink], [1, 2, 3]),
    {ok, Src} = gen_statem:start(?MODULE, {source, hd(Fwds)}, []),
    Sink ! {source, Src},
    {Src, [Src | Fwds]}.

stop({_Src, Pids}) ->
    _ = [exit(P, kill) || P <- Pids],
    ok.

callback_mode() -> handle_event_function.

init({sink, Mode, N, Controller}) -> {ok, sinking, {sink, Mode, N, Controller, none, 0, []}};
init({forward, Next}) -> {ok, forwarding, {forward, Next}};
init({source, First}) -> {ok, idle, {source, First}}.

now_ns() -> erlang:monotonic_time(nanosecond).

handle_event(info, {ev, _} = Ev, _, {forward, Next}) ->
    Next ! Ev,
    keep_state_and_data;
handle_event(info, {ev, Ev}, _, {sink, Mode, Expect, Ctl, Src, N, Lat}) ->
    case toroco_bench_sink:arrived(Ev, Mode, Expect, Src, Ctl, N, Lat) of
        done -> {keep_state, {sink, Mode, Expect, Ctl, Src, 0, []}};
        {N1, Lat1} -> {keep_state, {sink, Mode, Expect, Ctl, Src, N1, Lat1}}
    end;
handle_event(info, {source, Src}, _, {sink, Mode, Expect, Ctl, _, N, Lat}) ->
    {keep_state, {sink, Mode, Expect, Ctl, Src, N, Lat}};
handle_event(info, {run, Mode, N}, idle, {source, First}) ->
    source(Mode, N, First);
handle_event(info, {arrived, Seq}, closed, {N, First}) when Seq < N ->
    First ! {ev, {now_ns(), Seq + 1}},
    keep_state_and_data;
handle_event({timeout, next}, Sent, paced, {Ms, N, T0, First}) ->
    First ! {ev, {now_ns(), Sent + 1}},
    paced(Ms, N, T0, Sent + 1, First);
handle_event(info, {acked, A}, window, {W, N, Sent, First}) ->
    Upto = min(N, A + W),
    _ = [First ! {ev, {0, Seq}} || Seq <- lists:seq(Sent + 1, Upto)],
    {keep_state, {W, N, max(Sent, Upto), First}};
handle_event(_Type, _Content, _State, _Data) ->
    keep_state_and_data.

source(closed, N, First) ->
    First ! {ev, {now_ns(), 1}},
    {next_state, closed, {N, First}};
source({paced, Ms}, N, First) ->
    T0 = erlang:monotonic_time(millisecond),
    First ! {ev, {now_ns(), 1}},
    paced(Ms, N, T0, 1, First);
source({window, W}, N, First) ->
    Upto = min(N, W),
    _ = [First ! {ev, {0, Seq}} || Seq <- lists:seq(1, Upto)],
    {next_state, window, {W, N, Upto, First}}.

paced(_Ms, N, _T0, N, _First) ->
    {next_state, done, none};
paced(Ms, N, T0, Sent, First) ->
    {next_state, paced, {Ms, N, T0, First}, [{{timeout, next}, T0 + Sent * Ms, Sent, [{abs, true}]}]}.
