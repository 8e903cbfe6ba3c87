%% @doc (API) The clients of a WebSocket hub (the Foxglove bridge's and the
%% rosbridge server's), kept in the hub's state: who is connected
%% (monitored), what each subscribed to (keys of the hub's choosing:
%% channel ids, topic names), how many messages each missed, and the hub's
%% tap subscription (SPEC §10), held only while someone is connected so a
%% hub nobody watches costs the robot nothing.
%%
%% Pure but for the monitors, the tap and the sends: every function takes
%% and returns the `clients()'.
-module(toroco_live_clients).

-export([new/1, join/2, stop/1]).
-export([member/2, pids/1, size/1, subscriptions/1]).
-export([subscribe/3, unsubscribe/3, forget/2, subscribers/2, subscribed/2]).
-export([offer/5, broadcast/2, handle/2]).

-export_type([clients/0]).

-record(clients, {conns = #{} :: #{pid() => reference()},
                  subs = #{} :: #{term() => [pid()]},
                  dropped = #{} :: #{pid() => pos_integer()},
                  tap :: toroco_rec_tap:tap()}).
-opaque clients() :: #clients{}.

%% @doc Nobody connected; `TapOpts' as `toroco_rec_tap:new/1''s.
-spec new(toroco_rec_tap:opts()) -> clients().
new(TapOpts) ->
    #clients{tap = toroco_rec_tap:new(TapOpts)}.

%% @doc `Conn' joined: it is monitored and the tap is taken.
-spec join(pid(), clients()) -> clients().
join(Conn, Cl = #clients{conns = Conns, tap = Tap}) ->
    Conns1 = case Conns of
                 #{Conn := _} -> Conns;
                 #{} -> Conns#{Conn => monitor(process, Conn)}
             end,
    Cl#clients{conns = Conns1, tap = toroco_rec_tap:ensure_on(Tap)}.

%% A client gone: it is forgotten with its subscriptions, and the tap is
%% let go when it was the last.
down(Conn, Cl = #clients{conns = Conns}) ->
    Cl1 = unsubscribe(Conn, maps:keys(Cl#clients.subs),
                      Cl#clients{conns = maps:remove(Conn, Conns),
                                 dropped = maps:remove(Conn, Cl#clients.dropped)}),
    case map_size(Cl1#clients.conns) of
        0 -> Cl1#clients{tap = toroco_rec_tap:off(Cl1#clients.tap), subs = #{}};
        _ -> Cl1
    end.

%% @doc The hub stops: the tap is let go, and the events emitted before,
%% still on their way, are returned for the hub to pass on.
-spec stop(clients()) -> [term()].
stop(#clients{tap = Tap}) ->
    {Events, _} = toroco_rec_tap:close(Tap),
    Events.

-spec member(pid(), clients()) -> boolean().
member(Conn, #clients{conns = Conns}) -> is_map_key(Conn, Conns).

-spec pids(clients()) -> [pid()].
pids(#clients{conns = Conns}) -> maps:keys(Conns).

-spec size(clients()) -> non_neg_integer().
size(#clients{conns = Conns}) -> map_size(Conns).

%% @doc How many subscriptions there are, counting each client's to each key.
-spec subscriptions(clients()) -> non_neg_integer().
subscriptions(#clients{subs = Subs}) ->
    maps:fold(fun(_, Conns, N) -> N + length(Conns) end, 0, Subs).

%% @doc `Conn' subscribes to `Keys' (a subscription twice is one).
-spec subscribe(pid(), [term()], clients()) -> clients().
subscribe(Conn, Keys, Cl = #clients{subs = Subs}) ->
    Subs1 = lists:foldl(fun(K, S) -> maps:update_with(K, fun(L) -> lists:usort([Conn | L]) end, [Conn], S) end,
                        Subs, Keys),
    Cl#clients{subs = Subs1}.

-spec unsubscribe(pid(), [term()], clients()) -> clients().
unsubscribe(Conn, Keys, Cl = #clients{subs = Subs}) ->
    Subs1 = lists:foldl(fun(K, S) ->
                                case maps:get(K, S, []) -- [Conn] of
                                    [] -> maps:remove(K, S);
                                    L -> S#{K => L}
                                end
                        end, Subs, Keys),
    Cl#clients{subs = Subs1}.

%% @doc Every subscription to `Keys' goes (the keys are gone).
-spec forget([term()], clients()) -> clients().
forget(Keys, Cl = #clients{subs = Subs}) ->
    Cl#clients{subs = maps:without(Keys, Subs)}.

-spec subscribers(term(), clients()) -> [pid()].
subscribers(Key, #clients{subs = Subs}) -> maps:get(Key, Subs, []).

-spec subscribed(term(), clients()) -> boolean().
subscribed(Key, #clients{subs = Subs}) -> is_map_key(Key, Subs).

%% @doc `toroco_live_ws_conn:offer/5' with this hub's drop counts: a
%% client behind by more than `Max' messages misses this one, and hears how
%% many it missed (`DroppedMsg(N)') once it has caught up.
-spec offer(pid(), term(), fun((pos_integer()) -> term()), pos_integer(), clients()) ->
          {sent | dropped | gone, clients()}.
offer(Conn, Msg, DroppedMsg, Max, Cl = #clients{dropped = D}) ->
    {What, D1} = toroco_live_ws_conn:offer(Conn, Msg, DroppedMsg, Max, D),
    {What, Cl#clients{dropped = D1}}.

%% @doc `Msg' to every client, unbounded: for the rare messages (the tap's
%% own drops, channels coming and going).
-spec broadcast(term(), clients()) -> ok.
broadcast(Msg, #clients{conns = Conns}) ->
    _ = [C ! Msg || C <- maps:keys(Conns)],
    ok.

%% @doc A message that may be about the clients or the tap: `{down, Conn,
%% Cl}' when a client's process went (forgotten, see above), `{events, Es}'
%% for a batch of events (among them `{dropped, N}'), `{retapped, Cl}' when
%% the tap was taken again after the runtime came back (with clients
%% connected), `{ok, Cl}' for the tap's own bookkeeping and `ignore' for
%% anything else.
-spec handle(term(), clients()) ->
          {down, pid(), clients()} | {events, [term()]} | {retapped | ok, clients()} | ignore.
handle({'DOWN', _, process, Conn, _}, Cl = #clients{conns = Conns}) when is_map_key(Conn, Conns) ->
    {down, Conn, down(Conn, Cl)};
handle(Info, Cl = #clients{tap = Tap, conns = Conns}) ->
    case toroco_rec_tap:handle(Info, Tap) of
        {events, Events} -> {events, Events};
        {down, Tap1} -> {ok, Cl#clients{tap = Tap1}};
        {retry, Tap1} when map_size(Conns) > 0 ->
            {retapped, Cl#clients{tap = toroco_rec_tap:ensure_on(Tap1)}};
        {retry, Tap1} -> {ok, Cl#clients{tap = Tap1}};
        _ -> ignore
    end.
