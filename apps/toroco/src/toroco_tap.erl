%% @doc The observer tap of the event path (SPEC §10): whoever watches the
%% robot (watch, top's restart counts, the dashboard, the Foxglove bridge,
%% recording, a user's own process) subscribes here.
%%
%% This module is the tap server (registered `toroco_tap', in `toroco_sup'
%% before the wiring and the network) and the tap's API, for subscribers
%% and for the event path's processes that produce its events:
%% <ul>
%% <li>Subscribers: {@link subscribe/1}, {@link unsubscribe/1},
%%     {@link sync/1}, {@link feeder/1}. Each subscription has a feeder
%%     (`toroco_tap_feeder'), the one process that sends to the
%%     subscriber, and a credit (`toroco_tap_credit') that bounds what it
%%     has pending.</li>
%% <li>Producers (behaviors, devices, routers; the wiring server for
%%     lifecycle events): {@link join/0}, {@link current/0},
%%     {@link select/3}, {@link tap/3}, {@link after_event/3},
%%     {@link flush/1}, {@link flushed/3}, {@link notify/2},
%%     {@link lifecycle/2}, {@link lifecycle/3}, {@link lifecycle/4},
%%     {@link timestamp/0}; a relay of another node: {@link relayed/4}.</li>
%% </ul>
%%
%% The server keeps the subscriptions in a table and, when they change,
%% tells every process of the network (`WIRE_TAP(Subs)'), which find each
%% other in the `pg' scope `toroco_tap_pg' (they join it when they start,
%% {@link join/0}). Each process keeps, in its own state, only the sinks
%% that concern it ({@link select/3}): with no subscriber an emission does
%% no send and no lookup.
%%
%% A producer keeps what it taps in its own batch (`toroco_tap_batch'),
%% sealed and sent as one message per subscription at `?BATCH_MAX' events;
%% {@link after_event/3} says when the rest goes: the first event of a
%% batch arms the producer's named gen_statem timeout `'$toroco_tap''
%% (`?FLUSH_MS'), whose event comes after what was already waiting, so the
%% batch goes once the producer has handled it. A busy period costs the
%% subscriber one message per batch, not one per event. A behavior whose
%% callback just set an event timeout (which any event would cancel) sends
%% its batch at once instead; in lockstep a batch goes at the end of the
%% event that made it (no real timer: SPEC §14). A subscriber that wants
%% everything emitted so far (a recording that stops, a dump, an
%% unsubscription) asks the feeder to drain ({@link sync/1}): it asks every
%% producer of the node for its batch (`WIRE_TAP_FLUSH', answered by
%% {@link flushed/3}), passes on all it holds, and answers.
%%
%% A subscriber on another node's events is fed the same way: the relay
%% there (`toroco_tap_relay') hands its batches to this node's feeder
%% ({@link relayed/4}), which takes room for them as a producer would.
%%
%% Order: each producer's batches go to one feeder, which alone sends to
%% the subscriber, so the events of one source arrive in emission order.
-module(toroco_tap).
-behaviour(gen_server).

-include("toroco_wire.hrl").

-export([start_link/0, subscribe/1, unsubscribe/1, sync/1, feeder/1]).
-export([current/0, join/0, select/3, tap/3, after_event/3, flush/1, flushed/3, notify/2,
         timestamp/0, lifecycle/2, lifecycle/3, lifecycle/4, relayed/4]).
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
%% One subscription as the producers see it: its feeder, credit, kinds and
%% names.
-opaque sub() :: {reference(), pid(), toroco_tap_credit:credit(), [kind()], all | [atom()]}.
%% What a producer keeps: the sinks of each kind that concern it.
-type sinks() :: #{kind() => [toroco_tap_batch:sink()]}.
%% The events a producer tapped and has not sent yet; `[]' when there are
%% none.
-type batch() :: toroco_tap_batch:batch().

-define(TABLE, toroco_tap).
-define(SCOPE, toroco_tap_pg).
-define(GROUP, network).
-define(KINDS, [emit, deliver, router, lifecycle]).
-define(DEFAULT_BUFFER, 10000).
-define(FLUSH_MS, 2).
-define(FLUSH_TIMER, {timeout, '$toroco_tap'}).
%% How long a drain waits for the producers' batches.
-define(SYNC_MS, 5000).

-record(state, {subs = #{} :: #{reference() => sub()},
                feeders = #{} :: #{reference() => pid()}}).

%%====================================================================
%% Subscribers
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

%% @doc Ends a subscription, once every event this node emitted before the
%% call has been sent to the subscriber or counted ({@link sync/1}); no
%% event of it is sent after this returns (those already in the
%% subscriber's mailbox stay there).
-spec unsubscribe(reference()) -> ok.
unsubscribe(Ref) when is_reference(Ref) ->
    _ = sync(Ref),
    try gen_server:call(?MODULE, {unsubscribe, Ref}, 10000)
    catch exit:{noproc, _} -> ok
    end;
unsubscribe(_) ->
    ok.

%% @doc Returns once every event the processes of this node emitted before
%% the call is in the subscriber's mailbox or counted in a `{dropped, N}'
%% there: the subscription's feeder asks each of them for its batch and
%% passes on all it holds. The caller's own batch, if it is a producer,
%% is not waited for. `{error, {timeout, Pids}}' names the producers that
%% did not answer within 5 s (what the others sent is passed on).
-spec sync(reference()) -> ok | {error, term()}.
sync(Ref) ->
    case feeder(Ref) of
        none -> {error, {unknown_subscription, Ref}};
        Feeder -> toroco_tap_feeder:drain(Feeder, producers() -- [self()], ?SYNC_MS)
    end.

%% @doc The feeder of subscription `Ref' (where a relay sends), or `none'.
-spec feeder(reference()) -> pid() | none.
feeder(Ref) ->
    case [F || {R, F, _, _, _} <- current(), R =:= Ref] of
        [F] -> F;
        [] -> none
    end.

producers() ->
    try pg:get_local_members(?SCOPE, ?GROUP)
    catch error:badarg -> []                    % the tap is not running
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
%% Producers
%%====================================================================

%% @doc The subscriptions now in force (read once by a process when it
%% starts, after {@link join/0}; later changes reach it as
%% `WIRE_TAP(Subs)').
-spec current() -> [sub()].
current() ->
    try ets:lookup(?TABLE, subs) of
        [{subs, Subs}] -> Subs;
        [] -> []
    catch error:badarg -> []
    end.

%% @doc Makes the calling process (a behavior, device or router) one that
%% hears of subscription changes and of drains; call it before
%% {@link current/0}.
-spec join() -> ok.
join() ->
    try pg:join(?SCOPE, ?GROUP, self())
    catch exit:{noproc, _} -> ok                % the tap is not running
    end.

%% @doc The sinks of `Kinds' that concern a producer whose events are about
%% `Name'.
-spec select([sub()], [kind()], atom()) -> sinks().
select(Subs, Kinds, Name) ->
    lists:foldl(
      fun({Ref, Feeder, Credit, SubKinds, Names}, Acc) ->
              case Names =:= all orelse lists:member(Name, Names) of
                  true ->
                      Sink = {Ref, Feeder, Credit},
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
%% it, counting a drop where there is none; a sink's part that reaches
%% `?BATCH_MAX' events is sent at once. A sink found full stays full until
%% the batch goes: what comes meanwhile is counted as dropped without
%% looking at the sink again, so a producer tapping faster than its
%% subscriber reads pays no more per event than one with room.
-spec tap([toroco_tap_batch:sink()], event(), batch()) -> batch().
tap([], _Event, Batch) ->
    Batch;
tap([Sink = {_, _, Credit} | Rest], Event, Batch) ->
    {Batch1, Sealed} =
        case toroco_tap_batch:add(Sink, Event, Batch) of
            need_room -> toroco_tap_batch:add(Sink, Event, toroco_tap_credit:reserve(Credit), Batch);
            Added -> Added
        end,
    _ = Sealed =:= [] orelse lists:foreach(fun send/1, Sealed),  % most events seal nothing
    tap(Rest, Event, Batch1).

%% A part of a batch goes; the room it did not use is given back, what it
%% dropped is counted.
send(#{ref := Ref, feeder := Feeder, credit := Credit, events := Events, n := N,
       unused := Unused, dropped := D}) ->
    %% The first drops since the feeder last reported: it may have stopped
    %% looking, so it is told (while drops wait it keeps looking).
    _ = toroco_tap_credit:dropped(Credit, D) andalso N =:= 0 andalso toroco_tap_feeder:nudge(Feeder),
    _ = N > 0 andalso toroco_tap_feeder:batch(Feeder, Ref, Events, N),
    toroco_tap_credit:give_back(Credit, Unused).

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
    lists:foreach(fun send/1, toroco_tap_batch:seal(Batch)),
    [].

%% @doc A producer's answer to `WIRE_TAP_FLUSH(Feeder, Tag)': its batch
%% now, then the word that it went.
-spec flushed(pid(), reference(), batch()) -> [].
flushed(Feeder, Tag, Batch) ->
    [] = flush(Batch),
    ok = toroco_tap_feeder:flushed(Feeder, Tag),
    [].

%% @doc Sends `Event' at once to each sink with room for it, counting a
%% drop where there is none (a producer that keeps no batch).
-spec notify([toroco_tap_batch:sink()], event()) -> ok.
notify(Sinks, Event) ->
    [] = flush(tap(Sinks, Event, toroco_tap_batch:new())),
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

%% @doc Hands events of another node (in order) and the count dropped
%% there to `Feeder', the feeder of subscription `Ref' (a relay's side).
%% Returns `ok', or `busy' if the connection to the feeder's node is
%% congested (nothing was sent: the caller counts them as dropped).
-spec relayed(pid(), reference(), [event()], non_neg_integer()) -> ok | busy.
relayed(Feeder, Ref, Events, Dropped) ->
    toroco_tap_feeder:relayed(Feeder, Ref, Events, Dropped).

%%====================================================================
%% The tap server
%%====================================================================

-spec init([]) -> {ok, #state{}}.
init([]) ->
    process_flag(trap_exit, true),
    _ = ets:new(?TABLE, [named_table, protected, set, {read_concurrency, true}]),
    ets:insert(?TABLE, {subs, []}),
    {ok, #state{}}.

-spec handle_call(term(), gen_server:from(), #state{}) -> {reply, term(), #state{}}.
handle_call({subscribe, Pid, Kinds, Names, Buffer, Delivery}, _From, S = #state{subs = Subs, feeders = Fs}) ->
    Ref = make_ref(),
    Credit = toroco_tap_credit:new(Buffer),
    case toroco_tap_feeder:start_link(Pid, Ref, Credit, Delivery) of
        {ok, F} ->
            Subs1 = Subs#{Ref => {Ref, F, Credit, Kinds, Names}},
            publish(Subs1),
            {reply, {ok, Ref}, S#state{subs = Subs1, feeders = Fs#{Ref => F}}};
        {error, Why} ->
            {reply, {error, {feeder_failed, Why}}, S}
    end;
handle_call({unsubscribe, Ref}, _From, S = #state{subs = Subs, feeders = Fs}) ->
    case Fs of
        #{Ref := F} ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            %% The feeder alone sends to the subscriber: once it is gone,
            %% nothing more of this subscription arrives.
            exit(F, kill),
            receive {'EXIT', F, _} -> ok end,
            {reply, ok, S#state{subs = Subs1, feeders = maps:remove(Ref, Fs)}};
        #{} ->
            {reply, ok, S}
    end;
handle_call(_Req, _From, S) ->
    {reply, {error, unknown_request}, S}.

-spec handle_cast(term(), #state{}) -> {noreply, #state{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

%% A feeder ends when its subscriber dies: the subscription goes with it.
-spec handle_info(term(), #state{}) -> {noreply, #state{}}.
handle_info({'EXIT', Pid, _}, S = #state{subs = Subs, feeders = Fs}) ->
    case [R || {R, F} <- maps:to_list(Fs), F =:= Pid] of
        [Ref] ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            {noreply, S#state{subs = Subs1, feeders = maps:remove(Ref, Fs)}};
        [] ->
            {noreply, S}
    end;
handle_info(_Msg, S) ->
    {noreply, S}.

%% The table first, then every running process of the network: a process
%% joins the group before it reads the table in init, so none is missed.
publish(SubsMap) ->
    Subs = maps:values(SubsMap),
    ets:insert(?TABLE, {subs, Subs}),
    Msg = ?WIRE_TAP(Subs),
    _ = [Pid ! Msg || Pid <- pg:get_local_members(?SCOPE, ?GROUP)],
    ok.
