%% @doc The observer tap of the event path (SPEC §10): whoever watches the
%% robot (watch, top's restart counts, the dashboard, the Foxglove bridge,
%% recording, a user's own process) subscribes here.
%%
%% It sits in `toroco_sup' before the wiring and the network. Three parts:
%% <ul>
%% <li>the tap server (this module, registered `toroco_tap') keeps the
%%     subscriptions in a table and, when they change, tells every process of
%%     the network (`{'$toroco_tap', Subs}'). Each process keeps, in its own
%%     state, only the sinks that concern it ({@link select/3}): with no
%%     subscriber an emission does no send and no lookup;</li>
%% <li>one relay process per subscription, on the subscriber's node, between
%%     the producers and the subscriber: it keeps the subscriber's pending
%%     events under `buffer' and counts what it cannot keep;</li>
%% <li>the producers' side, {@link notify/2}: one bounded send per sink.</li>
%% </ul>
%%
%% Bounding. A sink carries an `atomics' array: (1) events the relay holds
%% (in its mailbox or its queue), (2) events dropped, (3) the subscriber's
%% queue length as the relay last saw it. A producer sends only while
%% held + seen &lt; buffer, else counts a drop; the relay forwards what the
%% subscriber has room for, and while anything is held, seen or dropped it
%% looks again every few milliseconds, so `{dropped, N}' reaches the
%% subscriber as soon as it has room, even if no later event comes. Every
%% event is either received or counted.
%%
%% Per producer, events go producer → relay → subscriber, so the events of
%% one source arrive in emission order.
-module(toroco_tap).
-behaviour(gen_server).

-export([start_link/0, subscribe/1, unsubscribe/1]).
-export([current/0, select/3, notify/2, timestamp/0]).
-export([lifecycle/2, lifecycle/3]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).
-export_type([sinks/0, kind/0, event/0, opts/0, sub/0]).

-type kind() :: emit | deliver | router | lifecycle.
-type lifecycle() :: started | restarted | stopped | suspended | resumed | reset
                   | {layer_removed, non_neg_integer()}.
-type event() :: {emit, integer(), {atom(), atom()}, send | set | unset, term()}
               | {deliver, integer(), {atom(), atom()}, term()}
               | {router, integer(), {atom(), atom()}, map()}
               | {lifecycle, integer(), atom(), lifecycle()}
               | {dropped, pos_integer()}.
-type opts() :: #{kinds => [kind()], names => all | [atom()], buffer => pos_integer()}.
%% One subscription as the producers see it.
-opaque sub() :: {reference(), pid(), atomics:atomics_ref(), pos_integer(),
                  [kind()], all | [atom()]}.
-type sink() :: {reference(), pid(), atomics:atomics_ref(), pos_integer()}.
%% What a producer keeps: the sinks of each kind that concern it.
-type sinks() :: #{kind() => [sink()]}.

-define(TABLE, toroco_tap).
-define(KINDS, [emit, deliver, router, lifecycle]).
-define(DEFAULT_BUFFER, 10000).
-define(POLL_MS, 5).
%% Cells of a sink's atomics array.
-define(HELD, 1).
-define(DROPPED, 2).
-define(SEEN, 3).

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Subscribes the calling process to the events of `kinds' (default
%% all) about `names' (default all), at most `buffer' pending (default
%% 10000). Events come as `{toroco_event, Ref, Event}'.
-spec subscribe(opts()) -> {ok, reference()} | {error, term()}.
subscribe(Opts) when is_map(Opts) ->
    case options(Opts) of
        {ok, Kinds, Names, Buffer} ->
            try gen_server:call(?MODULE, {subscribe, self(), Kinds, Names, Buffer}, 10000)
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

options(Opts) ->
    Kinds = maps:get(kinds, Opts, ?KINDS),
    Names = maps:get(names, Opts, all),
    Buffer = maps:get(buffer, Opts, ?DEFAULT_BUFFER),
    case maps:keys(maps:without([kinds, names, buffer], Opts)) of
        [Bad | _] -> {error, {bad_option, Bad}};
        [] when not is_list(Kinds); Kinds =:= [] -> {error, {bad_kinds, Kinds}};
        [] ->
            case [K || K <- Kinds, not lists:member(K, ?KINDS)] of
                [BadKind | _] -> {error, {bad_kind, BadKind}};
                [] when Names =/= all, not is_list(Names) -> {error, {bad_names, Names}};
                [] ->
                    case Names =:= all orelse lists:all(fun is_atom/1, Names) of
                        false -> {error, {bad_names, Names}};
                        true when not is_integer(Buffer); Buffer < 1 -> {error, {bad_buffer, Buffer}};
                        true -> {ok, lists:usort(Kinds), Names, Buffer}
                    end
            end
    end.

%%====================================================================
%% The producers' side
%%====================================================================

%% @doc The subscriptions now in force (read once by a process when it
%% starts; later changes reach it as `{'$toroco_tap', Subs}').
-spec current() -> [sub()].
current() ->
    try ets:lookup(?TABLE, subs) of
        [{subs, Subs}] -> Subs;
        [] -> []
    catch error:badarg -> []
    end.

%% @doc The sinks of `Kinds' that concern a producer whose events are about
%% `Name'.
-spec select([sub()], [kind()], atom()) -> sinks().
select([], _Kinds, _Name) ->
    #{};
select(Subs, Kinds, Name) ->
    lists:foldl(
      fun({Ref, Relay, A, Max, SubKinds, Names}, Acc) ->
              case Names =:= all orelse lists:member(Name, Names) of
                  true ->
                      lists:foldl(fun(K, Acc1) ->
                                          case lists:member(K, SubKinds) of
                                              true -> maps:update_with(K, fun(L) -> L ++ [{Ref, Relay, A, Max}] end,
                                                                       [{Ref, Relay, A, Max}], Acc1);
                                              false -> Acc1
                                          end
                                  end, Acc, Kinds);
                  false -> Acc
              end
      end, #{}, Subs).

%% @doc Sends `Event' to each sink with room for it, counting a drop where
%% there is none.
-spec notify([sink()], event()) -> ok.
notify([], _Event) ->
    ok;
notify([{Ref, Relay, A, Max} | Rest], Event) ->
    Held = atomics:add_get(A, ?HELD, 1),
    _ = case Held + atomics:get(A, ?SEEN) > Max of
            true ->
                atomics:sub(A, ?HELD, 1),
                atomics:add(A, ?DROPPED, 1);
            false ->
                Relay ! {toroco_event, Ref, Event}
        end,
    notify(Rest, Event).

%% @doc The time stamp of events: when the runtime saw it.
-spec timestamp() -> integer().
timestamp() ->
    erlang:system_time(nanosecond).

%% @doc A lifecycle event about `Name', for a producer that holds no sinks
%% of its own (the wiring server).
-spec lifecycle(atom(), lifecycle()) -> ok.
lifecycle(Name, What) ->
    lifecycle(select(current(), [lifecycle], Name), Name, What).

%% @doc A lifecycle event about `Name' to the producer's sinks.
-spec lifecycle(sinks(), atom(), lifecycle()) -> ok.
lifecycle(#{lifecycle := Sinks}, Name, What) ->
    notify(Sinks, {lifecycle, timestamp(), Name, What});
lifecycle(#{}, _Name, _What) ->
    ok.

%%====================================================================
%% The tap server
%%====================================================================

-spec init([]) -> {ok, #{reference() => sub()}}.
init([]) ->
    process_flag(trap_exit, true),
    _ = ets:new(?TABLE, [named_table, protected, set, {read_concurrency, true}]),
    ets:insert(?TABLE, {subs, []}),
    {ok, #{}}.

-spec handle_call(term(), gen_server:from(), map()) -> {reply, term(), map()}.
handle_call({subscribe, Pid, Kinds, Names, Buffer}, _From, Subs) ->
    Ref = make_ref(),
    A = atomics:new(3, [{signed, true}]),
    Relay = spawn_relay(Pid, Ref, A, Buffer),
    Subs1 = Subs#{Ref => {Ref, Relay, A, Buffer, Kinds, Names}},
    publish(Subs1),
    {reply, {ok, Ref}, Subs1};
handle_call({unsubscribe, Ref}, _From, Subs) ->
    case Subs of
        #{Ref := {_, Relay, _, _, _, _}} ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            unlink(Relay),
            exit(Relay, kill),
            {reply, ok, Subs1};
        #{} ->
            {reply, ok, Subs}
    end;
handle_call(_Req, _From, Subs) ->
    {reply, {error, unknown_request}, Subs}.

-spec handle_cast(term(), map()) -> {noreply, map()}.
handle_cast(_Msg, Subs) ->
    {noreply, Subs}.

%% A relay ends when its subscriber dies: the subscription goes with it.
-spec handle_info(term(), map()) -> {noreply, map()}.
handle_info({'EXIT', Pid, _}, Subs) ->
    case [R || {R, {_, Relay, _, _, _, _}} <- maps:to_list(Subs), Relay =:= Pid] of
        [Ref] ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            {noreply, Subs1};
        [] ->
            {noreply, Subs}
    end;
handle_info(_Msg, Subs) ->
    {noreply, Subs}.

%% The table first, then every running process of the network: a process
%% registers its name before it reads the table in init, so none is missed.
publish(SubsMap) ->
    Subs = maps:values(SubsMap),
    ets:insert(?TABLE, {subs, Subs}),
    Msg = {'$toroco_tap', Subs},
    _ = [erlang:send(Name, Msg) || Name <- erlang:registered(), is_network(Name)],
    ok.

is_network(Name) ->
    case atom_to_binary(Name) of
        <<"toroco:", _/binary>> = B -> binary:longest_common_suffix([B, <<"!gate">>]) =/= 5;
        _ -> false
    end.

%%====================================================================
%% The relay
%%====================================================================

spawn_relay(Sub, Ref, A, Max) ->
    spawn_link(fun() ->
                       process_flag(priority, high),
                       Mon = erlang:monitor(process, Sub),
                       relay(#{sub => Sub, mon => Mon, ref => Ref, a => A, max => Max,
                               q => queue:new(), qlen => 0, timer => false})
               end).

relay(S = #{mon := Mon, ref := Ref}) ->
    receive
        {toroco_event, Ref, Event} ->
            relay(drain(enqueue(Event, S)));
        poll ->
            relay(flush(S#{timer := false}));
        {'DOWN', Mon, process, _, _} ->
            exit(normal)
    end.

%% Takes everything already in the mailbox before forwarding, so that one
%% look at the subscriber's queue serves many events.
drain(S = #{ref := Ref}) ->
    receive
        {toroco_event, Ref, Event} -> drain(enqueue(Event, S))
    after 0 ->
            flush(S)
    end.

enqueue(Event, S = #{q := Q, qlen := N}) ->
    S#{q := queue:in(Event, Q), qlen := N + 1}.

flush(S = #{sub := Sub, a := A, max := Max, q := Q, qlen := N, ref := Ref}) ->
    SubLen = case erlang:process_info(Sub, message_queue_len) of
                 {message_queue_len, L} -> L;
                 undefined -> 0
             end,
    Room = max(0, Max - SubLen),
    K = min(N, Room),
    Q1 = forward(K, Q, Sub, Ref),
    atomics:sub(A, ?HELD, K),
    Dropped = case N - K of
                  0 when Room - K > 0 -> atomics:exchange(A, ?DROPPED, 0);
                  _ -> 0
              end,
    _ = Dropped > 0 andalso (Sub ! {toroco_event, Ref, {dropped, Dropped}}),
    Seen = SubLen + K + min(Dropped, 1),
    atomics:put(A, ?SEEN, Seen),
    S1 = S#{q := Q1, qlen := N - K},
    %% Look again while anything is waiting, unseen or uncounted.
    case N - K > 0 orelse Seen > 0 orelse atomics:get(A, ?DROPPED) > 0 of
        true -> poll(S1);
        false -> S1
    end.

forward(0, Q, _Sub, _Ref) ->
    Q;
forward(K, Q, Sub, Ref) ->
    {{value, Event}, Q1} = queue:out(Q),
    Sub ! {toroco_event, Ref, Event},
    forward(K - 1, Q1, Sub, Ref).

poll(S = #{timer := true}) -> S;
poll(S) ->
    erlang:send_after(?POLL_MS, self(), poll),
    S#{timer := true}.
