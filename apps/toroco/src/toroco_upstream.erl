%% @doc How routers and gates (the consumers) attach to the processes their
%% sources come from (the upstreams: an emitter, or the gate of an inhibited
%% output), and the one send primitive of the event path.
%%
%% Subscribing is a handshake: the consumer sends `{'$toroco_sub', Src, Reg}';
%% the upstream adds `Reg' to the source's subscribers and answers, in the same
%% step, `{'$toroco_state', Tag, Src, Pid, Latch}' with the source's current
%% latch. Every event it sends afterwards follows that answer, so the latch
%% handed over is never older than what the consumer sees next, and nothing
%% is lost or repeated across the hand-over.
-module(toroco_upstream).

-export([subscribe/3, unsubscribe/3, send/2, sync_timeout/0, start_opts/0]).
-export([new_links/0, rewire/4, detach_all/2, hello/4, late_state/5, down/2, upstream_pids/1,
         carries/3, hold_timer/2]).
-export_type([entry/0, synced/0, links/0]).

-type source() :: {atom(), atom()}.
-type entry() :: {source(), {emitter | gate, atom()}}.
-type synced() :: {source(), pid() | undefined, toroco_router_core:latch() | inhibited}.
-type upstream() :: {emitter | gate, atom()}.
%% What a consumer knows of its upstreams: where each source comes from, the
%% pid of the incarnation it currently listens to, and one monitor per pid.
-type links() :: #{ups := #{source() => upstream()},
                   pids := #{source() => pid()},
                   mons := #{pid() => reference()}}.

%%====================================================================
%% Links: a consumer's view of its upstreams
%%====================================================================

-spec new_links() -> links().
new_links() -> #{ups => #{}, pids => #{}, mons => #{}}.

%% @doc Moves the links to a new set of upstreams: unsubscribes from the
%% sources that left (or whose upstream changed), subscribes to the new ones
%% and waits for their latches. Returns the synced latches and the sources
%% whose state starts afresh: the new ones, and those that now come through a
%% gate that inhibits them. A source that only moved between its emitter and
%% a gate that lets it through keeps its hold (a gate that inhibits nothing
%% changes nothing).
%% `Caller' (the process whose wiring call this is, or `none') is not
%% waited for: it is busy in that call; its answer comes as a late state.
-spec rewire(#{source() => upstream()}, links(), atom(), pid() | none) ->
          {links(), [{source(), toroco_router_core:latch()}], [source()]}.
rewire(NewUps, Links = #{ups := OldUps}, MyReg, Caller) ->
    Gone = [S || {S, Up} <- maps:to_list(OldUps), maps:get(S, NewUps, none) =/= Up],
    [unsubscribe(S, maps:get(S, OldUps), MyReg) || S <- Gone],
    Fresh = [{S, Up} || {S, Up} <- maps:to_list(NewUps), maps:get(S, OldUps, none) =/= Up],
    {Busy, Waited} = lists:partition(fun({_, {_, Up}}) -> whereis(Up) =:= Caller end, Fresh),
    _ = [send(Up, {'$toroco_sub', S, MyReg}) || {S, {_, Up}} <- Busy],
    Synced = subscribe(Waited, MyReg, sync_timeout()) ++ [{S, undefined, none} || {S, _} <- Busy],
    L1 = lists:foldl(fun(S, Acc) -> forget(S, Acc) end, Links#{ups := NewUps}, Gone),
    L2 = lists:foldl(fun({S, Pid, _}, Acc) when is_pid(Pid) -> listen(S, Pid, Acc);
                        (_, Acc) -> Acc
                     end, L1, Synced),
    Reset = [S || {S, _, Latch} <- Synced, Latch =:= inhibited orelse not maps:is_key(S, OldUps)],
    {L2, [{S, latch(Latch)} || {S, _, Latch} <- Synced], Reset}.

%% A gate answers `inhibited' for a member it holds back: no latch gets through.
latch(inhibited) -> none;
latch(Latch) -> Latch.

%% @doc Unsubscribes from every upstream (the consumer is going away).
-spec detach_all(links(), atom()) -> ok.
detach_all(#{ups := Ups}, MyReg) ->
    maps:foreach(fun(S, Up) -> unsubscribe(S, Up, MyReg) end, Ups).

%% @doc A new incarnation of an upstream announced itself: listen to it. Its
%% source starts with no latch and no hold (the caller applies an `unset').
-spec hello(emitter | gate, source(), pid(), links()) -> {ok, links()} | ignore.
hello(Tag, Src, Pid, Links = #{ups := Ups}) ->
    case Ups of
        #{Src := {Tag, _}} -> {ok, listen(Src, Pid, Links)};
        #{} -> ignore
    end.

%% @doc An answer to a subscription that came after the wait gave up on it.
-spec late_state(emitter | gate, source(), pid(), toroco_router_core:latch() | inhibited, links()) ->
          {ok, links()} | ignore.
late_state(Tag, Src, Pid, _State, Links = #{ups := Ups, pids := Pids}) ->
    case {Ups, Pids} of
        {#{Src := {Tag, _}}, #{Src := _}} -> ignore;
        {#{Src := {Tag, _}}, #{}} -> {ok, listen(Src, Pid, Links)};
        _ -> ignore
    end.

%% @doc An upstream process died: the sources it carried, and the links
%% without it.
-spec down(pid(), links()) -> {[source()], links()}.
down(Pid, Links = #{pids := Pids, mons := Mons}) ->
    Srcs = [S || {S, P} <- maps:to_list(Pids), P =:= Pid],
    {Srcs, Links#{pids := maps:without(Srcs, Pids), mons := maps:remove(Pid, Mons)}}.

%% @doc Whether an event tagged `Tag' (`emitter' for `{'$toroco', ..}',
%% `gate' for `{'$toroco_gate', ..}') for `Src' is one this consumer listens
%% to; while a source moves between its emitter and a gate, events from the
%% side it left are ignored.
-spec carries(emitter | gate, source(), links()) -> boolean().
carries(Tag, Src, #{ups := Ups}) ->
    case Ups of
        #{Src := {Tag, _}} -> true;
        #{} -> false
    end.

%% @doc The consumer's one hold timer (the gen_statem timeout `{timeout,
%% hold}'), moved only when the earliest deadline changed.
-spec hold_timer(infinity | integer(), infinity | integer()) ->
          {infinity | integer(), [gen_statem:action()]}.
hold_timer(Same, Same) -> {Same, []};
hold_timer(infinity, _) -> {infinity, [{{timeout, hold}, cancel}]};
hold_timer(Next, _) ->
    {Next, [{{timeout, hold}, toroco_clock:real_deadline(Next), expire, [{abs, true}]}]}.

%% @doc The pids currently listened to, by source.
-spec upstream_pids(links()) -> #{source() => pid()}.
upstream_pids(#{pids := Pids}) -> Pids.

listen(Src, Pid, Links) ->
    L1 = #{pids := Pids, mons := Mons} = forget(Src, Links),
    Mons1 = case Mons of
                #{Pid := _} -> Mons;
                #{} -> Mons#{Pid => erlang:monitor(process, Pid)}
            end,
    L1#{pids := Pids#{Src => Pid}, mons := Mons1}.

%% Drops a source's pid, and the monitor of that pid if no other source uses it.
forget(Src, Links = #{pids := Pids, mons := Mons}) ->
    case Pids of
        #{Src := Pid} ->
            Pids1 = maps:remove(Src, Pids),
            case lists:member(Pid, maps:values(Pids1)) of
                true -> Links#{pids := Pids1};
                false ->
                    case Mons of
                        #{Pid := Ref} -> erlang:demonitor(Ref, [flush]);
                        #{} -> ok
                    end,
                    Links#{pids := Pids1, mons := maps:remove(Pid, Mons)}
            end;
        #{} -> Links
    end.

%% @doc Subscribes `MyReg' to each entry's upstream and waits (at most
%% `Timeout' ms in all) for their answers. A source whose upstream is not
%% running, or does not answer in time, comes back with no pid and no latch;
%% if its answer comes later the consumer takes it as a late sync.
-spec subscribe([entry()], atom(), timeout()) -> [synced()].
subscribe([], _MyReg, _Timeout) ->
    [];
subscribe(Entries, MyReg, Timeout) ->
    Pending = maps:from_list(
                [begin
                     Mref = erlang:monitor(process, Up),
                     send(Up, {'$toroco_sub', Src, MyReg}),
                     {Src, {Tag, Mref}}
                 end || {Src, {Tag, Up}} <- Entries]),
    Deadline = erlang:monotonic_time(millisecond) + Timeout,
    collect(Pending, Deadline, []).

collect(Pending, _Deadline, Acc) when map_size(Pending) =:= 0 ->
    Acc;
collect(Pending, Deadline, Acc) ->
    Left = max(0, Deadline - erlang:monotonic_time(millisecond)),
    receive
        {'$toroco_state', Tag, Src, Pid, Latch} when is_map_key(Src, Pending) ->
            case maps:get(Src, Pending) of
                {Tag, Mref} ->
                    erlang:demonitor(Mref, [flush]),
                    collect(maps:remove(Src, Pending), Deadline, [{Src, Pid, Latch} | Acc]);
                _OtherTag ->
                    collect(Pending, Deadline, Acc)
            end;
        {'DOWN', Mref, process, _, _} ->
            case [S || {S, {_, M}} <- maps:to_list(Pending), M =:= Mref] of
                [Src] -> collect(maps:remove(Src, Pending), Deadline,
                                 [{Src, undefined, none} | Acc]);
                [] -> collect(Pending, Deadline, Acc)
            end
    after Left ->
            [erlang:demonitor(M, [flush]) || {_, M} <- maps:values(Pending)],
            Acc ++ [{Src, undefined, none} || Src <- maps:keys(Pending)]
    end.

%% @doc Tells an upstream to stop sending `Src' to `MyReg'.
-spec unsubscribe(source(), {emitter | gate, atom()}, atom()) -> ok.
unsubscribe(Src, {_Tag, Up}, MyReg) ->
    send(Up, {'$toroco_unsub', Src, MyReg}).

%% @doc Sends to a registered name; a name that is not registered (its process
%% is restarting or gone) swallows the message, as a cut wire would.
-spec send(atom() | pid(), term()) -> ok.
send(To, Msg) ->
    try To ! Msg of
        _ -> ok
    catch
        error:badarg -> ok
    end.

%% @doc Start options of the network's processes (behaviors, devices,
%% routers, gates): a process idle for `hibernate_after_ms' (app env, default
%% 5000) hibernates, which shrinks an idle behavior with its router to a few
%% kilobytes; a busy one never does.
-spec start_opts() -> [gen_statem:start_opt()].
start_opts() ->
    [{hibernate_after, application:get_env(toroco, hibernate_after_ms, 5000)}].

%% @doc How long wiring waits for an upstream's answer (app env `sync_timeout_ms').
-spec sync_timeout() -> timeout().
sync_timeout() ->
    application:get_env(toroco, sync_timeout_ms, 5000).
