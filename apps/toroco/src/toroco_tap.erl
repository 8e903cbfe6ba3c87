%% @doc The observer tap of the event path (SPEC §10): whoever watches the
%% robot (watch, top's restart counts, the dashboard, the Foxglove bridge,
%% recording, a user's own process) subscribes here.
%%
%% It sits in `toroco_sup' before the wiring and the network. Three parts:
%% <ul>
%% <li>the tap server (this module, registered `toroco_tap') keeps the
%%     subscriptions in a table and, when they change, tells every process of
%%     the network (`{'$toroco_tap', Subs}'), which find each other in the
%%     `pg' scope `toroco_tap_pg' (they join it when they start, {@link join/0}).
%%     Each process keeps, in its own state, only the sinks that concern it
%%     ({@link select/3}): with no subscriber an emission does no send and no
%%     lookup;</li>
%% <li>the producers' side: {@link tap/3} takes room for an event and keeps
%%     it in the producer's own batch, sealed and sent as one message at
%%     `?BATCH_MAX' events; {@link after_event/3} says when the rest goes:
%%     the first event of a batch arms the producer's named gen_statem
%%     timeout `'$toroco_tap'' (`?FLUSH_MS'), whose event comes after what
%%     was already waiting, so the batch goes once the producer has handled
%%     it. A busy period costs the subscriber one message per batch, not one
%%     per event, and the scheduler that runs the subscriber is not woken at
%%     each event. A behavior whose callback just set an event timeout
%%     (which any event would cancel) sends its batch at once instead; in
%%     lockstep a batch goes at the end of the event that made it (no real
%%     timer: SPEC §14);</li>
%% <li>one feeder process per subscription, beside the subscriber: it holds
%%     the batches that come within `?MERGE_MS' of each other, merges them by
%%     time stamp (each producer's own order kept), unpacks them into
%%     `{toroco_event, Ref, Event}' messages (or, for a subscriber that
%%     asked for `delivery => batch', sends the merged events as one
%%     `{toroco_events, Ref, Events}', whose events the credit counts) and
%%     reports what the producers dropped.</li>
%% </ul>
%%
%% Credit. A sink carries an `atomics' array: (1) room the producers took
%% and the feeder has not passed on yet (a producer takes it 16 events at a
%% time and gives back what its batch did not use), (2) events dropped, (3)
%% how many of the subscriber's messages the feeder counts as pending. A
%% producer takes room only while taken + pending &lt;= buffer, else counts
%% a drop; having found the sink full, it counts the rest of that batch's
%% events as dropped without looking again (at most `?FLUSH_MS'). The
%% feeder adds what it passes on to the pending count and gives the room
%% back by looking at the subscriber's queue: when a batch leaves
%% the subscriber half full or more, and then every 5 ms only while it
%% stays so or drops wait to be reported (a subscriber that keeps up costs
%% no timer and no polling). As soon as the subscriber has room the
%% feeder sends `{dropped, N}', even if no later event comes. Every event
%% is either received or counted; the count errs on the side of dropping
%% early, never of growing the queue.
%%
%% A subscriber on another node's events is fed the same way: the relay
%% there (`toroco_tap_relay') hands its batches to this node's feeder
%% ({@link relayed/4}), which takes room for them as a producer would and
%% counts what does not fit into the same `{dropped, N}'.
%%
%% Order: each producer's batches go to one feeder, which alone sends to
%% the subscriber, so the events of one source arrive in emission order.
-module(toroco_tap).
-behaviour(gen_server).

-include("toroco_wire.hrl").

-export([start_link/0, subscribe/1, unsubscribe/1, feeder/1]).
-export([current/0, join/0, select/3, tap/3, after_event/3, flush/1, notify/2, timestamp/0]).
-export([lifecycle/2, lifecycle/3, lifecycle/4, relayed/4]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).
-export_type([sinks/0, batch/0, kind/0, event/0, opts/0, sub/0, delivery/0]).

-type kind() :: emit | deliver | router | lifecycle.
-type lifecycle() :: started | restarted | stopped | suspended | resumed | reset
                   | {layer_removed, non_neg_integer()}.
-type event() :: {emit, integer(), {atom(), atom()}, send | set | unset, term()}
               | {deliver, integer(), {atom(), atom()}, term()}
               | {router, integer(), {atom(), atom()}, map()}
               | {lifecycle, integer(), atom(), lifecycle()}
               | {dropped, pos_integer()}.
-type opts() :: #{kinds => [kind()], names => all | [atom()], buffer => pos_integer(),
                  delivery => delivery()}.
%% How the events reach the subscriber: `{toroco_event, Ref, Event}' each
%% (`event', the default), or `{toroco_events, Ref, [Event]}', several in
%% order to a message (`batch').
-type delivery() :: event | batch.
%% One subscription as the producers see it: its feeder, credit and bound.
-opaque sub() :: {reference(), pid(), atomics:atomics_ref(), pos_integer(),
                  [kind()], all | [atom()]}.
-type sink() :: {reference(), pid(), atomics:atomics_ref(), pos_integer()}.  % feeder
%% What a producer keeps: the sinks of each kind that concern it.
-type sinks() :: #{kind() => [sink()]}.
%% The events a producer tapped and has not sent yet, per subscription
%% (newest first); `[]' when there are none.
%% With each, the room taken for it and not used yet (`full': none is left,
%% see {@link tap/3}), and the events dropped.
-type batch() :: [{reference(), pid(), atomics:atomics_ref(), non_neg_integer(),
                   non_neg_integer() | full, non_neg_integer(), [event()]}].

-define(TABLE, toroco_tap).
-define(SCOPE, toroco_tap_pg).
-define(GROUP, network).
-define(KINDS, [emit, deliver, router, lifecycle]).
-define(DEFAULT_BUFFER, 10000).
-define(BATCH_MAX, 128).
-define(FLUSH_MS, 2).
-define(CREDIT, 16).
%% How long a feeder holds the batches that came, to merge them.
-define(MERGE_MS, 3).
-define(FLUSH_TIMER, {timeout, '$toroco_tap'}).
-define(LOOK_MS, 5).
%% Cells of a sink's atomics array.
-define(HELD, 1).
-define(DROPPED, 2).
-define(SEEN, 3).
%% producer -> feeder: events in emission order, N of them.
-define(BATCH(Ref, Producer, Events, N), {'$toroco_tap_batch', Ref, Producer, Events, N}).
%% producer -> feeder: drops wait to be reported.
-define(NUDGE, '$toroco_tap_nudge').
%% relay -> feeder: events of another node, and what was dropped there.
-define(RELAYED(Ref, Events, N, Dropped), {'$toroco_tap_relayed', Ref, Events, N, Dropped}).

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Subscribes the calling process to the events of `kinds' (default
%% all) about `names' (default all), at most `buffer' events pending
%% (default 10000). Events come as `{toroco_event, Ref, Event}', or with
%% `delivery => batch' as `{toroco_events, Ref, Events}', the same events
%% in the same order several to a message: a subscriber that takes many
%% events is woken and sent to once per batch, not once per event.
-spec subscribe(opts()) -> {ok, reference()} | {error, term()}.
subscribe(Opts) when is_map(Opts) ->
    case options(Opts) of
        {ok, Kinds, Names, Buffer, Delivery} ->
            try gen_server:call(?MODULE, {subscribe, self(), Kinds, Names, Buffer, Delivery}, 10000)
            catch exit:{noproc, _} -> {error, not_running}
            end;
        Err -> Err
    end;
subscribe(Opts) ->
    {error, {bad_options, Opts}}.

%% @doc Ends a subscription; no event of it is sent after this returns
%% (those already in the caller's mailbox stay there).
-spec unsubscribe(reference()) -> ok.
unsubscribe(Ref) when is_reference(Ref) ->
    try gen_server:call(?MODULE, {unsubscribe, Ref}, 10000)
    catch exit:{noproc, _} -> ok
    end;
unsubscribe(_) ->
    ok.

%% @doc The feeder of subscription `Ref' (where a relay sends), or `none'.
-spec feeder(reference()) -> pid() | none.
feeder(Ref) ->
    case [F || {R, F, _, _, _, _} <- current(), R =:= Ref] of
        [F] -> F;
        [] -> none
    end.

options(Opts) ->
    Kinds = maps:get(kinds, Opts, ?KINDS),
    Names = maps:get(names, Opts, all),
    Buffer = maps:get(buffer, Opts, ?DEFAULT_BUFFER),
    Delivery = maps:get(delivery, Opts, event),
    case maps:keys(maps:without([kinds, names, buffer, delivery], Opts)) of
        [Bad | _] -> {error, {bad_option, Bad}};
        [] when Delivery =/= event, Delivery =/= batch -> {error, {bad_delivery, Delivery}};
        [] when not is_list(Kinds); Kinds =:= [] -> {error, {bad_kinds, Kinds}};
        [] ->
            case [K || K <- Kinds, not lists:member(K, ?KINDS)] of
                [BadKind | _] -> {error, {bad_kind, BadKind}};
                [] when Names =/= all, not is_list(Names) -> {error, {bad_names, Names}};
                [] ->
                    case Names =:= all orelse lists:all(fun is_atom/1, Names) of
                        false -> {error, {bad_names, Names}};
                        true when not is_integer(Buffer); Buffer < 1 -> {error, {bad_buffer, Buffer}};
                        true -> {ok, lists:usort(Kinds), Names, Buffer, Delivery}
                    end
            end
    end.

%%====================================================================
%% The producers' side
%%====================================================================

%% @doc The subscriptions now in force (read once by a process when it
%% starts, after {@link join/0}; later changes reach it as
%% `{'$toroco_tap', Subs}').
-spec current() -> [sub()].
current() ->
    try ets:lookup(?TABLE, subs) of
        [{subs, Subs}] -> Subs;
        [] -> []
    catch error:badarg -> []
    end.

%% @doc Makes the calling process (a behavior, device or router) one that
%% hears of subscription changes; call it before {@link current/0}.
-spec join() -> ok.
join() ->
    try pg:join(?SCOPE, ?GROUP, self())
    catch exit:{noproc, _} -> ok                % the tap is not running
    end.

%% @doc The sinks of `Kinds' that concern a producer whose events are about
%% `Name'.
-spec select([sub()], [kind()], atom()) -> sinks().
select([], _Kinds, _Name) ->
    #{};
select(Subs, Kinds, Name) ->
    lists:foldl(
      fun({Ref, Feeder, A, Max, SubKinds, Names}, Acc) ->
              case Names =:= all orelse lists:member(Name, Names) of
                  true ->
                      Sink = {Ref, Feeder, A, Max},
                      lists:foldl(fun(K, Acc1) ->
                                          case lists:member(K, SubKinds) of
                                              true -> maps:update_with(K, fun(L) -> L ++ [Sink] end,
                                                                       [Sink], Acc1);
                                              false -> Acc1
                                          end
                                  end, Acc, Kinds);
                  false -> Acc
              end
      end, #{}, Subs).

%% @doc Keeps `Event' in the producer's batch for each sink with room for
%% it, counting a drop where there is none; a batch that reaches
%% `?BATCH_MAX' events is sent at once. A sink found full stays full for
%% the rest of the batch (`full'): what comes until the batch goes is
%% counted as dropped without looking at the sink again, so a producer
%% tapping faster than its subscriber reads pays no more per event than
%% one with room.
-spec tap([sink()], event(), batch()) -> batch().
tap([], _Event, Batch) ->
    Batch;
tap([{Ref, Feeder, A, Max} | Rest], Event, Batch) ->
    case lists:keytake(Ref, 1, Batch) of
        {value, {_, _, _, N, full, D, Evs}, Others} ->
            tap(Rest, Event, [{Ref, Feeder, A, N, full, D + 1, Evs} | Others]);
        {value, {_, _, _, N, Room, D, Evs}, Others} when Room > 0 ->
            tap(Rest, Event, add(Ref, Feeder, A, N + 1, Room - 1, D, [Event | Evs], Others));
        {value, {_, _, _, N, 0, D, Evs}, Others} ->
            case reserve(A, Max) of
                0 -> tap(Rest, Event, [{Ref, Feeder, A, N, full, D + 1, Evs} | Others]);
                Room -> tap(Rest, Event, add(Ref, Feeder, A, N + 1, Room - 1, D, [Event | Evs], Others))
            end;
        false ->
            case reserve(A, Max) of
                0 -> tap(Rest, Event, [{Ref, Feeder, A, 0, full, 1, []} | Batch]);
                Room -> tap(Rest, Event, add(Ref, Feeder, A, 1, Room - 1, 0, [Event], Batch))
            end
    end.

%% Room for up to ?CREDIT events taken at once, or 0: the event is dropped
%% (and counted in the batch, added to the sink's count when it goes). A
%% full sink is seen with reads alone.
reserve(A, Max) ->
    case atomics:get(A, ?HELD) + atomics:get(A, ?SEEN) >= Max of
        true ->
            0;
        false ->
            Over = atomics:add_get(A, ?HELD, ?CREDIT) + atomics:get(A, ?SEEN) - Max,
            if
                Over =< 0 -> ?CREDIT;
                Over >= ?CREDIT -> atomics:sub(A, ?HELD, ?CREDIT), 0;
                true -> atomics:sub(A, ?HELD, Over), ?CREDIT - Over
            end
    end.

add(Ref, Feeder, A, N, Room, D, Evs, Batch) when N >= ?BATCH_MAX ->
    send({Ref, Feeder, A, N, Room, D, Evs}),
    Batch;
add(Ref, Feeder, A, N, Room, D, Evs, Batch) ->
    [{Ref, Feeder, A, N, Room, D, Evs} | Batch].

%% A batch goes; the room it did not use is given back, what it dropped is
%% counted.
send({Ref, Feeder, A, N, Room, D, Evs}) ->
    %% The first drops since the feeder last reported: it may have stopped
    %% looking, so it is told (while drops wait it keeps looking).
    _ = D > 0 andalso atomics:add_get(A, ?DROPPED, D) =:= D andalso N =:= 0
        andalso (Feeder ! ?NUDGE),
    _ = N > 0 andalso (Feeder ! ?BATCH(Ref, self(), lists:reverse(Evs), N)),
    _ = is_integer(Room) andalso Room > 0 andalso atomics:sub(A, ?HELD, Room),
    ok.

%% @doc What a producer (a gen_statem) does with its batch after an event:
%% `Was' says whether it had a batch before the event, `Hurry' whether the
%% event's result sets an event timeout. Returns `keep' (nothing to do) or
%% the batch to keep and the gen_statem actions to add; the producer
%% handles the timeout `{{timeout, '$toroco_tap'}, flush}' with
%% {@link flush/1}.
-spec after_event(boolean(), batch(), boolean()) -> keep | {batch(), [gen_statem:action()]}.
after_event(_Was, [], _Hurry) ->
    keep;
after_event(true, _Batch, false) ->
    keep;                                       % its timer is set
after_event(_Was, Batch, Hurry) ->
    case toroco_clock:lockstep_server() of
        none when Hurry -> {flush(Batch), [{?FLUSH_TIMER, cancel}]};
        none -> {Batch, [{?FLUSH_TIMER, ?FLUSH_MS, flush}]};
        _ -> {flush(Batch), []}
    end.

%% @doc Sends the producer's batch now.
-spec flush(batch()) -> [].
flush(Batch) ->
    lists:foreach(fun send/1, Batch),
    [].

%% @doc Sends `Event' at once to each sink with room for it, counting a
%% drop where there is none (a producer that keeps no batch).
-spec notify([sink()], event()) -> ok.
notify(Sinks, Event) ->
    [] = flush(tap(Sinks, Event, [])),
    ok.

%% @doc The time stamp of events: when the runtime saw it (in lockstep, the
%% simulated time since the run began, `toroco_clock:timestamp_ns/0').
-spec timestamp() -> integer().
timestamp() ->
    toroco_clock:timestamp_ns().

%% @doc A lifecycle event about `Name', for a producer that holds no sinks
%% of its own (the wiring server).
-spec lifecycle(atom(), lifecycle()) -> ok.
lifecycle(Name, What) ->
    lifecycle(select(current(), [lifecycle], Name), Name, What).

%% @doc A lifecycle event about `Name' to the producer's sinks, at once.
-spec lifecycle(sinks(), atom(), lifecycle()) -> ok.
lifecycle(#{lifecycle := Sinks}, Name, What) ->
    notify(Sinks, {lifecycle, timestamp(), Name, What});
lifecycle(#{}, _Name, _What) ->
    ok.

%% @doc A lifecycle event about `Name' into the producer's batch.
-spec lifecycle(sinks(), atom(), lifecycle(), batch()) -> batch().
lifecycle(#{lifecycle := Sinks}, Name, What, Batch) ->
    tap(Sinks, {lifecycle, timestamp(), Name, What}, Batch);
lifecycle(#{}, _Name, _What, Batch) ->
    Batch.

%% @doc Hands events of another node (in order, `N' of them) and the count
%% dropped there to `Feeder', the feeder of subscription `Ref' (a relay's
%% side). Returns `ok', or `busy' if the connection to the feeder's node is
%% congested (nothing was sent: the caller counts them as dropped).
-spec relayed(pid(), reference(), [event()], non_neg_integer()) -> ok | busy.
relayed(Feeder, Ref, Events, Dropped) ->
    Msg = ?RELAYED(Ref, Events, length(Events), Dropped),
    case erlang:send(Feeder, Msg, [nosuspend, noconnect]) of
        ok -> ok;
        _ -> busy
    end.

%%====================================================================
%% The tap server
%%====================================================================

%% The server's state: the subscriptions, and the feeder of each.
-spec init([]) -> {ok, {#{reference() => sub()}, #{reference() => pid()}}}.
init([]) ->
    process_flag(trap_exit, true),
    _ = ets:new(?TABLE, [named_table, protected, set, {read_concurrency, true}]),
    ets:insert(?TABLE, {subs, []}),
    {ok, {#{}, #{}}}.

-spec handle_call(term(), gen_server:from(), State) -> {reply, term(), State}
              when State :: {map(), map()}.
handle_call({subscribe, Pid, Kinds, Names, Buffer, Delivery}, _From, {Subs, Fs}) ->
    Ref = make_ref(),
    A = atomics:new(3, [{signed, true}]),
    F = spawn_feeder(Pid, Ref, A, Buffer, Delivery),
    Subs1 = Subs#{Ref => {Ref, F, A, Buffer, Kinds, Names}},
    publish(Subs1),
    {reply, {ok, Ref}, {Subs1, Fs#{Ref => F}}};
handle_call({unsubscribe, Ref}, _From, {Subs, Fs}) ->
    case Fs of
        #{Ref := F} ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            %% The feeder alone sends to the subscriber: once it is gone,
            %% nothing more of this subscription arrives.
            exit(F, kill),
            receive {'EXIT', F, _} -> ok end,
            {reply, ok, {Subs1, maps:remove(Ref, Fs)}};
        #{} ->
            {reply, ok, {Subs, Fs}}
    end;
handle_call(_Req, _From, State) ->
    {reply, {error, unknown_request}, State}.

-spec handle_cast(term(), State) -> {noreply, State} when State :: {map(), map()}.
handle_cast(_Msg, State) ->
    {noreply, State}.

%% A feeder ends when its subscriber dies: the subscription goes with it.
-spec handle_info(term(), State) -> {noreply, State} when State :: {map(), map()}.
handle_info({'EXIT', Pid, _}, {Subs, Fs}) ->
    case [R || {R, F} <- maps:to_list(Fs), F =:= Pid] of
        [Ref] ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            {noreply, {Subs1, maps:remove(Ref, Fs)}};
        [] ->
            {noreply, {Subs, Fs}}
    end;
handle_info(_Msg, State) ->
    {noreply, State}.

%% The table first, then every running process of the network: a process
%% joins the group before it reads the table in init, so none is missed.
publish(SubsMap) ->
    Subs = maps:values(SubsMap),
    ets:insert(?TABLE, {subs, Subs}),
    Msg = ?WIRE_TAP(Subs),
    _ = [Pid ! Msg || Pid <- pg:get_local_members(?SCOPE, ?GROUP)],
    ok.

%%====================================================================
%% The feeder
%%====================================================================

-record(feed, {sub :: pid(),
               mon :: reference(),
               ref :: reference(),
               a :: atomics:atomics_ref(),
               max :: pos_integer(),
               delivery :: delivery(),
               %% with batch delivery: how many events each message sent
               %% and maybe not read yet holds, newest first
               sent = [] :: [pos_integer()],
               %% batches held for the merge, per producer (each newest
               %% first), how many events, and whether the release is due
               held = #{} :: #{pid() => [[event()]]},
               n = 0 :: non_neg_integer(),
               %% whether a look timer is set
               timer = off :: off | on}).

%% A feeder that fell behind a busy CPU holds many batches for a while;
%% what they leave in its old heap goes at the next full sweep, not at the
%% default's 65,535th collection (a 10-minute soak under load grew 13 %,
%% most of it in feeders' old heaps).
spawn_feeder(Sub, Ref, A, Max, Delivery) ->
    spawn_opt(fun() ->
                      %% The robot first: under load the feeder waits, its
                      %% credit runs out, and the producers drop (cheaply).
                      process_flag(priority, low),
                      Mon = erlang:monitor(process, Sub),
                      feed(#feed{sub = Sub, mon = Mon, ref = Ref, a = A, max = Max,
                                 delivery = Delivery})
              end, [link, {fullsweep_after, 10}]).

feed(F = #feed{ref = Ref, mon = Mon, a = A}) ->
    receive
        ?BATCH(Ref, Producer, Events, N) ->
            %% Room was taken for these by their producer; they wait for
            %% the batches of the other producers (?MERGE_MS).
            feed(hold(Producer, Events, N, F));
        release ->
            feed(settle(release(F)));
        ?RELAYED(Ref, Events, N, Dropped) ->
            Admitted = admit(N, F),
            _ = Dropped + N - Admitted > 0
                andalso atomics:add(A, ?DROPPED, Dropped + N - Admitted),
            F1 = pass(lists:sublist(Events, Admitted), Admitted, F),
            atomics:sub(A, ?HELD, Admitted),
            feed(settle(F1));
        look ->
            feed(look(F#feed{timer = off}));
        ?NUDGE ->
            feed(look(F));
        {'DOWN', Mon, process, _, _} ->
            exit(normal)
    end.

hold(Producer, Events, N, F = #feed{held = H, n = 0}) ->
    _ = erlang:send_after(?MERGE_MS, self(), release),
    F#feed{held = H#{Producer => [Events]}, n = N};
hold(Producer, Events, N, F = #feed{held = H, n = Held}) ->
    F#feed{held = maps:update_with(Producer, fun(L) -> [Events | L] end, [Events], H), n = Held + N}.

%% The held batches go on, merged by time stamp: each producer's events
%% keep their order, and an event caused by another (an emission, then its
%% delivery) mostly comes after it even though their producers' batches
%% came in either order.
release(F = #feed{held = H, n = N, a = A}) ->
    Runs = [lists:append(lists:reverse(Bs)) || Bs <- maps:values(H)],
    Merged = lists:foldl(fun(Run, Acc) -> lists:merge(fun earlier/2, Acc, Run) end, [], Runs),
    F1 = pass(Merged, N, F),
    atomics:sub(A, ?HELD, N),
    F1#feed{held = #{}, n = 0}.

earlier(A, B) -> element(2, A) =< element(2, B).

%% How many of `N' relayed events fit, room taken for them.
admit(N, #feed{a = A, max = Max}) ->
    Over = atomics:add_get(A, ?HELD, N) + atomics:get(A, ?SEEN) - Max,
    case Over > 0 of
        true ->
            Excess = min(N, Over),
            atomics:sub(A, ?HELD, Excess),
            N - Excess;
        false ->
            N
    end.

%% The events go on, counted as pending before their room is given back.
pass(_Events, 0, F) ->
    F;
pass(Events, N, F = #feed{sub = Sub, ref = Ref, a = A, delivery = event}) ->
    atomics:add(A, ?SEEN, N),
    _ = [Sub ! {toroco_event, Ref, E} || E <- Events],
    F;
pass(Events, N, F = #feed{sub = Sub, ref = Ref, a = A, delivery = batch, sent = Sent}) ->
    atomics:add(A, ?SEEN, N),
    Sub ! {toroco_events, Ref, Events},
    F#feed{sent = [N | Sent]}.

%% Events pending in the subscriber's queue of `Len' messages: one each,
%% or with batch delivery what the newest `Len' batches held (the older
%% ones were read).
pending(Len, F = #feed{delivery = event}) ->
    {Len, F};
pending(Len, F = #feed{sent = Sent}) ->
    Unread = lists:sublist(Sent, Len),
    {lists:sum(Unread), F#feed{sent = Unread}}.

%% After passing a batch on: look at the subscriber's queue only if it may
%% be filling up or drops wait to be reported.
settle(F = #feed{a = A, max = Max}) ->
    case tight(A, Max) of
        true -> look(F);
        false -> F
    end.

tight(A, Max) ->
    Pending = atomics:get(A, ?SEEN) + atomics:get(A, ?HELD),
    (Pending > 0 andalso 2 * Pending >= Max) orelse atomics:get(A, ?DROPPED) > 0.

look(F0 = #feed{sub = Sub, a = A, max = Max, timer = T}) ->
    case erlang:process_info(Sub, message_queue_len) of
        {message_queue_len, Len} ->
            {Pending, F1} = pending(Len, F0),
            atomics:put(A, ?SEEN, Pending),
            Dropped = atomics:get(A, ?DROPPED),
            F = case Dropped > 0 andalso Pending < Max of
                    true ->
                        atomics:sub(A, ?DROPPED, Dropped),
                        pass([{dropped, Dropped}], 1, F1);
                    false ->
                        F1
                end,
            case {tight(A, Max), T} of
                {false, _} -> F;
                {true, off} -> _ = erlang:send_after(?LOOK_MS, self(), look),
                               F#feed{timer = on};
                {true, _} -> F
            end;
        undefined ->
            exit(normal)
    end.
