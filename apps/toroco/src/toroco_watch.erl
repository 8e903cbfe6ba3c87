%% @doc `toroco:watch/2': a bounded live trace of deliveries, safe on a running
%% robot (recon_trace's limits are the model).
%%
%% One watcher process at a time (registered as `toroco_watch') subscribes
%% to the observer tap (`toroco:subscribe_events/1', deliveries and
%% lifecycle of the watched name) and prints each input delivered to it,
%% `{Receiver, Input}' or every input of a `Receiver', to the group leader
%% of the caller (in a remote shell, that shell):
%% ```
%% 1.204 s  motors.setvel <- {80,80}
%% '''
%% It stops by itself, and says why, at the first of these limits:
%% <ul>
%% <li>`max' deliveries printed (default 100);</li>
%% <li>`seconds' since the start (default 60);</li>
%% <li>more than `rate' deliveries within one second (default 50): a flood is
%%     not printed, the watch stops instead;</li>
%% <li>the shell it prints to going away.</li>
%% </ul>
%% `toroco:unwatch()' stops it earlier; a new watch replaces the running one.
%% The tap follows names, so a receiver that restarts is watched on, and its
%% going down and coming back are printed. Other options: `io' (an io device
%% to print to instead of the group leader) and `notify' (a pid that gets
%% `{toroco_watch, stopped, {Why, Printed}}' with `Why' one of `max',
%% `seconds', `rate', `io_gone', `unwatch'). The watch touches nothing of the
%% receiver (no tracing), and its subscription is bounded like any other.
-module(toroco_watch).

-export([start/2, stop/0]).
-export_type([opts/0, why/0]).

-type opts() :: #{max => pos_integer(), seconds => number(), rate => pos_integer(),
                  io => io:device(), notify => pid()}.
-type why() :: max | seconds | rate | io_gone | unwatch.

-define(NAME, toroco_watch).
-define(DEFAULTS, #{max => 100, seconds => 60, rate => 50}).
-define(DEPTH, 12).

-record(w, {name :: atom(),
            input :: atom() | all,
            ref :: reference(),
            io :: io:device(),
            notify :: pid() | undefined,
            max :: pos_integer(),
            rate :: pos_integer(),
            start :: integer(),
            count = 0 :: non_neg_integer(),
            window = 0 :: integer(),
            in_window = 0 :: non_neg_integer()}).

%%====================================================================
%% API
%%====================================================================

-spec start(atom() | {atom(), atom()}, opts()) -> ok | {error, term()}.
start(What, Opts) when is_map(Opts) ->
    case {target(What), options(Opts)} of
        {{ok, Name, Input}, {ok, O}} ->
            launch(Name, Input, O);
        {{error, _} = Err, _} -> Err;
        {_, {error, _} = Err} -> Err
    end;
start(What, Opts) ->
    {error, {bad_option, {What, Opts}}}.

%% @doc Stops the running watch, if any; returns once it is unsubscribed.
-spec stop() -> ok.
stop() ->
    case whereis(?NAME) of
        undefined -> ok;
        Pid ->
            Ref = erlang:monitor(process, Pid),
            Pid ! {?NAME, stop},
            receive {'DOWN', Ref, process, Pid, _} -> ok end
    end.

%%====================================================================
%% Checking the request
%%====================================================================

target({Name, Input}) when is_atom(Name), is_atom(Input) ->
    case toroco_wiring:call({node, Name}) of
        {ok, #{inputs := Ins}} ->
            case lists:member(Input, Ins) of
                true -> {ok, Name, Input};
                false -> {error, {unknown_input, {Name, Input}}}
            end;
        {error, _} = Err -> Err
    end;
target(Name) when is_atom(Name) ->
    case toroco_wiring:call({node, Name}) of
        {ok, _} -> {ok, Name, all};
        {error, _} = Err -> Err
    end;
target(Other) ->
    {error, {bad_watch, Other}}.

options(Opts) ->
    O = maps:merge(?DEFAULTS, Opts),
    case [{K, V} || {K, V} <- lists:sort(maps:to_list(O)), not option(K, V)] of
        [] -> {ok, O};
        [Bad | _] -> {error, {bad_option, Bad}}
    end.

option(max, V) -> is_integer(V) andalso V > 0;
option(rate, V) -> is_integer(V) andalso V > 0;
option(seconds, V) -> is_number(V) andalso V > 0;
option(io, V) -> is_pid(V) orelse is_atom(V);
option(notify, V) -> is_pid(V);
option(_, _) -> false.

%%====================================================================
%% The watcher
%%====================================================================

launch(Name, Input, O) ->
    stop(),
    Io = maps:get(io, O, group_leader()),
    Caller = self(),
    {W, Ref} = spawn_monitor(fun() -> init(Caller, Name, Input, Io, O) end),
    receive
        {W, watching} -> erlang:demonitor(Ref, [flush]), ok;
        {W, {error, _} = Err} -> erlang:demonitor(Ref, [flush]), Err;
        {'DOWN', Ref, process, W, Reason} -> {error, {watch_failed, Reason}}
    end.

init(Caller, Name, Input, Io, O = #{seconds := Secs, rate := Rate}) ->
    true = register(?NAME, self()),
    _ = is_pid(Io) andalso erlang:monitor(process, Io),
    %% A flood is stopped at `rate' a second: more than that never waits.
    case toroco:subscribe_events(#{kinds => [deliver, lifecycle], names => [Name],
                                   buffer => 2 * Rate + 10}) of
        {ok, Ref} ->
            Now = erlang:system_time(millisecond),
            S = #w{name = Name, input = Input, ref = Ref, io = Io,
                   notify = maps:get(notify, O, undefined), max = maps:get(max, O),
                   rate = Rate, start = Now, window = Now},
            Caller ! {self(), watching},
            erlang:send_after(round(Secs * 1000), self(), {?NAME, seconds}),
            loop(S);
        {error, _} = Err ->
            Caller ! {self(), Err}
    end.

loop(S = #w{ref = Ref, io = Io, name = Name}) ->
    receive
        {toroco_event, Ref, {deliver, T, {_, I}, V}} ->
            delivered(I, V, erlang:convert_time_unit(T, nanosecond, millisecond), S);
        {toroco_event, Ref, {lifecycle, _, Name, stopped}} ->
            say(S, "watch: ~w went down~n", [Name]),
            loop(S);
        {toroco_event, Ref, {lifecycle, _, Name, What}} when What =:= restarted; What =:= started ->
            say(S, "watch: ~w is back~n", [Name]),
            loop(S);
        {toroco_event, Ref, {dropped, N}} ->
            say(S, "watch: ~b deliveries not shown (too many at once)~n", [N]),
            loop(S);
        {toroco_event, Ref, _} ->
            loop(S);
        {'DOWN', _, process, Io, _} ->
            done(S, io_gone);
        {?NAME, seconds} ->
            done(S, seconds);
        {?NAME, stop} ->
            done(S, unwatch);
        _ ->
            loop(S)
    end.

delivered(I, V, Ms, S = #w{input = Input}) when Input =:= all; I =:= Input ->
    S1 = #w{count = C, in_window = InW, rate = Rate, max = Max} = tick(Ms, S),
    if InW > Rate ->
           done(S1, rate);
       true ->
           say(S1, "~.3f s  ~w.~w <- ~9999tP~n", [(Ms - S1#w.start) / 1000, S1#w.name, I, V, ?DEPTH]),
           case C + 1 of
               Max -> done(S1#w{count = Max}, max);
               C1 -> loop(S1#w{count = C1})
           end
    end;
delivered(_I, _V, _Ms, S) ->
    loop(S).

%% Deliveries are counted in one-second windows from the start.
tick(Ms, S = #w{window = W, in_window = N}) when Ms - W < 1000 ->
    S#w{in_window = N + 1};
tick(Ms, S = #w{start = Start}) ->
    S#w{window = Ms - (Ms - Start) rem 1000, in_window = 1}.

done(S = #w{ref = Ref, count = C, notify = Notify}, Why) ->
    ok = toroco:unsubscribe_events(Ref),
    Why =/= io_gone andalso say(S, "watch stopped: ~w after ~w deliveries~n", [Why, C]),
    _ = is_pid(Notify) andalso (Notify ! {?NAME, stopped, {Why, C}}),
    ok.

say(#w{io = Io}, Fmt, Args) ->
    try io:format(Io, Fmt, Args) of
        ok -> true
    catch _:_ -> false
    end.
