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
%% <li>the producers' side, {@link notify/2}: one bounded send per sink,
%%     straight to the subscriber;</li>
%% <li>one watcher process per subscription, beside the subscriber, that
%%     looks at the subscriber's queue every few milliseconds, tells the
%%     producers how full it is, and reports what they dropped.</li>
%% </ul>
%%
%% Bounding. A sink carries an `atomics' array: (1) events sent since the
%% watcher last looked, (2) events dropped, (3) the subscriber's queue
%% length when the watcher last looked. A producer sends only while
%% sent + seen &lt; buffer, else counts a drop. The watcher looks every
%% 5 ms while anything is sent, seen or dropped (every 50 ms otherwise),
%% and as soon as the subscriber has room it sends `{dropped, N}', even if
%% no later event comes. Every event is either received or counted; the
%% count errs on the side of dropping early, never of growing the queue.
%%
%% Events go from each producer straight to the subscriber, so the events
%% of one source arrive in emission order.
-module(toroco_tap).
-behaviour(gen_server).

-include("toroco_wire.hrl").

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
-type sink() :: {reference(), pid(), atomics:atomics_ref(), pos_integer()}.  % subscriber
%% What a producer keeps: the sinks of each kind that concern it.
-type sinks() :: #{kind() => [sink()]}.

-define(TABLE, toroco_tap).
-define(KINDS, [emit, deliver, router, lifecycle]).
-define(DEFAULT_BUFFER, 10000).
-define(POLL_MS, 5).
-define(IDLE_POLL_MS, 50).
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
      fun({Ref, Sub, A, Max, SubKinds, Names}, Acc) ->
              case Names =:= all orelse lists:member(Name, Names) of
                  true ->
                      lists:foldl(fun(K, Acc1) ->
                                          case lists:member(K, SubKinds) of
                                              true -> maps:update_with(K, fun(L) -> L ++ [{Ref, Sub, A, Max}] end,
                                                                       [{Ref, Sub, A, Max}], Acc1);
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
notify([{Ref, Sub, A, Max} | Rest], Event) ->
    Held = atomics:add_get(A, ?HELD, 1),
    _ = case Held + atomics:get(A, ?SEEN) > Max of
            true ->
                atomics:sub(A, ?HELD, 1),
                atomics:add(A, ?DROPPED, 1);
            false ->
                Sub ! {toroco_event, Ref, Event}
        end,
    notify(Rest, Event).

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

%% @doc A lifecycle event about `Name' to the producer's sinks.
-spec lifecycle(sinks(), atom(), lifecycle()) -> ok.
lifecycle(#{lifecycle := Sinks}, Name, What) ->
    notify(Sinks, {lifecycle, timestamp(), Name, What});
lifecycle(#{}, _Name, _What) ->
    ok.

%%====================================================================
%% The tap server
%%====================================================================

%% The server's state: the subscriptions, and the watcher of each.
-spec init([]) -> {ok, {#{reference() => sub()}, #{reference() => pid()}}}.
init([]) ->
    process_flag(trap_exit, true),
    _ = ets:new(?TABLE, [named_table, protected, set, {read_concurrency, true}]),
    ets:insert(?TABLE, {subs, []}),
    {ok, {#{}, #{}}}.

-spec handle_call(term(), gen_server:from(), State) -> {reply, term(), State}
              when State :: {map(), map()}.
handle_call({subscribe, Pid, Kinds, Names, Buffer}, _From, {Subs, Ws}) ->
    Ref = make_ref(),
    A = atomics:new(3, [{signed, true}]),
    W = spawn_watcher(Pid, Ref, A, Buffer),
    Subs1 = Subs#{Ref => {Ref, Pid, A, Buffer, Kinds, Names}},
    publish(Subs1),
    {reply, {ok, Ref}, {Subs1, Ws#{Ref => W}}};
handle_call({unsubscribe, Ref}, _From, {Subs, Ws}) ->
    case Ws of
        #{Ref := W} ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            unlink(W),
            exit(W, kill),
            {reply, ok, {Subs1, maps:remove(Ref, Ws)}};
        #{} ->
            {reply, ok, {Subs, Ws}}
    end;
handle_call(_Req, _From, State) ->
    {reply, {error, unknown_request}, State}.

-spec handle_cast(term(), State) -> {noreply, State} when State :: {map(), map()}.
handle_cast(_Msg, State) ->
    {noreply, State}.

%% A watcher ends when its subscriber dies: the subscription goes with it.
-spec handle_info(term(), State) -> {noreply, State} when State :: {map(), map()}.
handle_info({'EXIT', Pid, _}, {Subs, Ws}) ->
    case [R || {R, W} <- maps:to_list(Ws), W =:= Pid] of
        [Ref] ->
            Subs1 = maps:remove(Ref, Subs),
            publish(Subs1),
            {noreply, {Subs1, maps:remove(Ref, Ws)}};
        [] ->
            {noreply, {Subs, Ws}}
    end;
handle_info(_Msg, State) ->
    {noreply, State}.

%% The table first, then every running process of the network: a process
%% registers its name before it reads the table in init, so none is missed.
publish(SubsMap) ->
    Subs = maps:values(SubsMap),
    ets:insert(?TABLE, {subs, Subs}),
    Msg = ?WIRE_TAP(Subs),
    _ = [erlang:send(Name, Msg) || Name <- erlang:registered(), is_network(Name)],
    ok.

is_network(Name) ->
    case atom_to_binary(Name) of
        <<"toroco:", _/binary>> = B -> binary:longest_common_suffix([B, <<"!gate">>]) =/= 5;
        _ -> false
    end.

%%====================================================================
%% The watcher
%%====================================================================

spawn_watcher(Sub, Ref, A, Max) ->
    spawn_link(fun() ->
                       Mon = erlang:monitor(process, Sub),
                       watch(Sub, Mon, Ref, A, Max)
               end).

watch(Sub, Mon, Ref, A, Max) ->
    Sent = atomics:get(A, ?HELD),
    case erlang:process_info(Sub, message_queue_len) of
        {message_queue_len, Len} ->
            Dropped = atomics:get(A, ?DROPPED),
            Seen = case Dropped > 0 andalso Len < Max of
                       true ->
                           Sub ! {toroco_event, Ref, {dropped, Dropped}},
                           atomics:sub(A, ?DROPPED, Dropped),
                           Len + 1;
                       false ->
                           Len
                   end,
            atomics:put(A, ?SEEN, Seen),
            %% What was sent before the look is in the queue length now.
            atomics:sub(A, ?HELD, Sent),
            Busy = Sent > 0 orelse Seen > 0 orelse atomics:get(A, ?DROPPED) > 0,
            receive
                {'DOWN', Mon, process, _, _} -> exit(normal)
            after case Busy of true -> ?POLL_MS; false -> ?IDLE_POLL_MS end ->
                    watch(Sub, Mon, Ref, A, Max)
            end;
        undefined ->
            exit(normal)
    end.
