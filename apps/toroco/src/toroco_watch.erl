%% @doc `toroco:watch/2': a bounded live trace of deliveries, safe on a running
%% robot (the limits of recon_trace are the model).
%%
%% One watcher process at a time traces the `receive' events of the watched
%% behavior or device and prints each input delivery to the group leader of the
%% caller. It stops by itself after `max' deliveries (default 100), after
%% `seconds' (default 60), or as soon as deliveries come faster than `rate' per
%% second (default 50), and says why it stopped.
-module(toroco_watch).

-export([start/2, stop/0]).

-define(NAME, toroco_watch).

-spec start(atom() | {atom(), atom()}, map()) -> ok | {error, term()}.
start(What, Opts) when is_map(Opts) ->
    {Name, Input} = case What of
                        {N, I} -> {N, I};
                        N -> {N, all}
                    end,
    case whereis(toroco_names:node(Name)) of
        undefined when is_atom(Name) -> {error, {not_running, Name}};
        undefined -> {error, {bad_watch, What}};
        Pid ->
            stop(),
            Limits = #{max => maps:get(max, Opts, 100), seconds => maps:get(seconds, Opts, 60),
                       rate => maps:get(rate, Opts, 50), out => group_leader(),
                       notify => maps:get(notify, Opts, undefined)},
            Caller = self(),
            {W, Ref} = spawn_monitor(fun() -> watcher(Caller, Pid, Name, Input, Limits) end),
            receive
                {W, tracing} -> erlang:demonitor(Ref, [flush]), ok;
                {'DOWN', Ref, process, W, Reason} -> {error, {watch_failed, Reason}}
            end
    end;
start(What, Opts) ->
    {error, {bad_option, {What, Opts}}}.

-spec stop() -> ok.
stop() ->
    case whereis(?NAME) of
        undefined -> ok;
        Pid ->
            Ref = erlang:monitor(process, Pid),
            Pid ! stop,
            receive {'DOWN', Ref, process, Pid, _} -> ok end
    end.

watcher(Caller, Pid, Name, Input, Limits = #{seconds := Secs}) ->
    register(?NAME, self()),
    erlang:trace(Pid, true, ['receive', {tracer, self()}]),
    Caller ! {self(), tracing},
    erlang:send_after(Secs * 1000, self(), timeout),
    Start = erlang:monotonic_time(millisecond),
    loop(Pid, Name, Input, Limits, 0, Start).

loop(Pid, Name, Input, Limits = #{max := Max, rate := Rate, out := Out}, Count, Start) ->
    receive
        {trace, Pid, 'receive', Msg} ->
            case delivery(Msg) of
                {I, V} when Input =:= all; I =:= Input ->
                    Now = erlang:monotonic_time(millisecond),
                    io:format(Out, "~w ms  ~w.~w <- ~tp~n", [Now - Start, Name, I, V]),
                    C = Count + 1,
                    Elapsed = max(1, Now - Start),
                    if C >= Max -> done(Pid, Limits, {max, C});
                       C > 10, C * 1000 / Elapsed > Rate -> done(Pid, Limits, {rate, C});
                       true -> loop(Pid, Name, Input, Limits, C, Start)
                    end;
                _ -> loop(Pid, Name, Input, Limits, Count, Start)
            end;
        {trace, _, _, _} -> loop(Pid, Name, Input, Limits, Count, Start);
        timeout -> done(Pid, Limits, {seconds, Count});
        stop -> done(Pid, Limits, {stopped, Count})
    end.

delivery({'$toroco_in', I, V}) -> {I, V};
delivery({'$toroco_in', I, V, _}) -> {I, V};
delivery(_) -> other.

done(Pid, #{out := Out, notify := Notify}, Why) ->
    catch erlang:trace(Pid, false, ['receive']),
    io:format(Out, "watch stopped: ~w~n", [Why]),
    _ = is_pid(Notify) andalso (Notify ! {toroco_watch, stopped, Why}),
    ok.
