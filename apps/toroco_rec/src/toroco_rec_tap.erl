%% @doc (API) One subscription to the observer tap (SPEC §10), kept in the state
%% of the process that reads it: the flight recorder (and the recordings it
%% writes), the dashboard's hub and the bridges of `toroco_live', and any
%% other process that watches the robot.
%%
%% The client process keeps a {@link tap()} in its state and passes every
%% message it does not know itself to {@link handle/2}. The subscription
%% follows the runtime: when the tap server goes (the runtime stops or
%% restarts), the subscription goes with it and the client is told
%% `{down, Tap}'; `retry_ms' later (and `retry_ms' after a subscription
%% that failed) it is told `{retry, Tap}' and subscribes again with
%% {@link on/1} if it still wants events.
%%
%% The events come in batches (`delivery => batch', the default here):
%% `{events, Events}', in order, several to a message, so a client taking
%% the robot's every event is woken once per batch; a client that asks for
%% `delivery => event' gets `{event, Event}' one at a time.
%% <pre>
%% T0 = toroco_rec_tap:new(#{buffer => 1000}),
%% {_, T} = toroco_rec_tap:on(T0),
%% ...
%% handle_info(Msg, S = #s{tap = T}) ->
%%     case toroco_rec_tap:handle(Msg, T) of
%%         {events, Events} -> ...;
%%         {down, T1} -> ...;
%%         {retry, T1} -> {_, T2} = toroco_rec_tap:on(T1), ...;
%%         ignore -> ...;
%%         unknown -> ...
%%     end.
%% </pre>
-module(toroco_rec_tap).

-export([new/1, on/1, ensure_on/1, off/1, flush/1, close/1, handle/2, subscribed/1, ref/1]).
-export_type([tap/0, opts/0]).

%% The options of `toroco:subscribe_events/1', how soon to try again
%% (default 1000 ms), and whether the simulated world's snapshots
%% (from `toroco_rec_world''s source, while a world runs) come with the
%% events (default `false'), for `who' (named in the log when the runtime
%% refuses, default `<<"toroco_rec_tap">>').
-type opts() :: #{kinds => [atom()], names => all | [atom()], buffer => pos_integer(),
                  delivery => toroco_tap:delivery(),
                  retry_ms => pos_integer(), world => boolean(), who => binary()}.

-record(tap, {opts :: map(),
              retry_ms :: pos_integer(),
              world :: boolean(),
              who :: binary(),
              ref = none :: reference() | none,
              %% the tap server: when it goes, so does the subscription
              mon = none :: reference() | none,
              %% a retry message is on its way
              retrying = false :: boolean()}).
-opaque tap() :: #tap{}.

-define(RETRY, '$toroco_live_tap_retry').

%% @doc A client's tap, not subscribed yet.
-spec new(opts()) -> tap().
new(Opts) ->
    #tap{opts = maps:merge(#{delivery => batch}, maps:without([retry_ms, world, who], Opts)),
         retry_ms = maps:get(retry_ms, Opts, 1000),
         world = maps:get(world, Opts, false), who = maps:get(who, Opts, <<"toroco_rec_tap">>)}.

%% @doc Subscribes, unless it is already. If the runtime refuses or is not
%% there, `{retry, Tap}' comes later.
-spec on(tap()) -> {ok, tap()} | {error, term(), tap()}.
on(T = #tap{ref = none, opts = Opts}) ->
    try toroco:subscribe_events(Opts) of
        {ok, Ref} ->
            world(subscribe, T),
            {ok, T#tap{ref = Ref, mon = monitor(process, toroco_tap)}};
        {error, Why} -> {error, Why, retry(T)}
    catch exit:Why -> {error, Why, retry(T)}
    end;
on(T) ->
    {ok, T}.

%% @doc {@link on/1} for a client that goes on without events until the
%% retry: a refusal is logged, naming the client.
-spec ensure_on(tap()) -> tap().
ensure_on(T0 = #tap{who = Who}) ->
    case on(T0) of
        {ok, T} -> T;
        {error, Why, T} ->
            logger:warning("~ts: no events from the runtime yet: ~0p", [Who, Why],
                           #{domain => [toroco, rec]}),
            T
    end.

%% @doc Unsubscribes; events of the subscription still in the mailbox are
%% `ignore'd by {@link handle/2}.
-spec off(tap()) -> tap().
off(T = #tap{ref = none}) ->
    T;
off(T = #tap{ref = Ref, mon = Mon}) ->
    _ = demonitor(Mon, [flush]),
    catch toroco:unsubscribe_events(Ref),
    world(unsubscribe, T),
    T#tap{ref = none, mon = none}.

%% @doc Every event emitted before the call that is still on its way
%% (`toroco:flush_events/1'), taken from the mailbox in order: for a client
%% about to write or count what it got (a dump, a recording's end).
-spec flush(tap()) -> [term()].
flush(#tap{ref = none}) ->
    [];
flush(#tap{ref = Ref}) ->
    _ = (catch toroco:flush_events(Ref)),
    taken(Ref).

%% @doc Unsubscribes ({@link off/1}), with the events emitted before the
%% call, in order: for a client that stops (a bridge passes them on before
%% it closes).
-spec close(tap()) -> {[term()], tap()}.
close(T = #tap{ref = none}) ->
    {[], T};
close(T = #tap{ref = Ref}) ->
    T1 = off(T),
    {taken(Ref), T1}.

taken(Ref) ->
    receive
        {toroco_events, Ref, Events} -> Events ++ taken(Ref);
        {toroco_event, Ref, Event} -> [Event | taken(Ref)]
    after 0 -> []
    end.

%% @doc What a message means to the client's tap: one of its events, its
%% subscription gone, time to subscribe again, an event of an earlier
%% subscription (`ignore'), or not the tap's (`unknown').
-spec handle(term(), tap()) ->
          {events, [term()]} | {event, term()} | {down, tap()} | {retry, tap()} | ignore | unknown.
handle({toroco_events, Ref, Events}, #tap{ref = Ref}) ->
    {events, Events};
handle({toroco_event, Ref, Event}, #tap{ref = Ref}) ->
    {event, Event};
handle({toroco_events, _, _}, _T) ->
    ignore;
handle({toroco_event, _, _}, _T) ->
    ignore;
handle({'DOWN', Mon, process, _, _}, T = #tap{mon = Mon}) when Mon =/= none ->
    {down, retry(T#tap{ref = none, mon = none})};
handle(?RETRY, T) ->
    {retry, T#tap{retrying = false}};
handle(_Msg, _T) ->
    unknown.

%% @doc Whether it is subscribed now.
-spec subscribed(tap()) -> boolean().
subscribed(#tap{ref = Ref}) -> Ref =/= none.

%% @doc The subscription's reference (to take the events still coming
%% with a `receive' of the client's own), or `none'.
-spec ref(tap()) -> reference() | none.
ref(#tap{ref = Ref}) -> Ref.

world(_How, #tap{world = false}) ->
    ok;
world(How, #tap{}) ->
    _ = toroco_rec_world:subscribe(How),
    ok.

retry(T = #tap{retrying = true}) ->
    T;
retry(T = #tap{retry_ms = Ms}) ->
    _ = erlang:send_after(Ms, self(), ?RETRY),
    T#tap{retrying = true}.
