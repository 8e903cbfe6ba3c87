%% @doc The feeder of one subscription to the observer tap (SPEC §10): the
%% one process that sends to the subscriber. `toroco_tap' starts it (linked)
%% when the subscription is made and kills it when it ends; it ends by
%% itself when the subscriber dies.
%%
%% It holds the producers' batches that come within `?MERGE_MS' of each
%% other (state `holding'), merges them by time stamp (each producer's own
%% order kept), and passes them on as `{toroco_event, Ref, Event}' each, or,
%% with `delivery => batch', as one `{toroco_events, Ref, Events}'. It
%% shares the subscription's bound with the producers through its credit
%% (`toroco_tap_credit'), gives the room back by looking at the subscriber's
%% queue (only while it may be filling up or drops wait to be reported:
%% a subscriber that keeps up costs no timer), and sends `{dropped, N}' as
%% soon as the subscriber has room.
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>`BATCH(Ref, Producer, Events, N)' ({@link batch/4})</td>
%%     <td>producer → feeder</td><td>a producer's batch goes, room taken for
%%     its `N' events</td><td>none</td></tr>
%% <tr><td>`NUDGE' ({@link nudge/1})</td><td>producer → feeder</td>
%%     <td>the first drops since the last report, with no event to carry
%%     them</td><td>none: the feeder looks at the subscriber's queue</td></tr>
%% <tr><td>`RELAYED(Ref, Events, N, Dropped)' ({@link relayed/4})</td>
%%     <td>`toroco_tap_relay' (another node) → feeder</td><td>that node's
%%     events</td><td>none; room is taken for them here</td></tr>
%% <tr><td>`{drain, Producers, Timeout}' (a call, {@link drain/3})</td>
%%     <td>`toroco_tap:sync/1' → feeder</td><td>a subscriber wants every
%%     event emitted so far</td><td>`ok' once they are all passed on, or
%%     `{error, {timeout, Pids}}' naming the producers that did not
%%     answer</td></tr>
%% <tr><td>`WIRE_TAP_FLUSH(Feeder, Tag)'</td><td>feeder → each producer of
%%     the drain</td><td>a drain starts</td><td>the producer's batch, then
%%     `FLUSHED'</td></tr>
%% <tr><td>`FLUSHED(Tag, Producer)' ({@link flushed/2})</td><td>producer →
%%     feeder</td><td>after its batch</td><td>none; a producer that dies
%%     instead answers by its `DOWN'</td></tr>
%% <tr><td>`{toroco_event, Ref, E}' / `{toroco_events, Ref, Es}'</td>
%%     <td>feeder → subscriber</td><td>events passed on</td><td>none</td></tr>
%% </table>
%%
%% Priority. The feeder runs at `low' priority so that, under load, the
%% robot's processes (at `normal') go first; its credit runs out and the
%% producers drop, cheaply. It cannot starve: the runtime interleaves the
%% `low' and `normal' run queues (`erlang:process_flag/2', "Priorities":
%% a `low' process is picked less often than a `normal' one, never left
%% out while only `normal' ones are runnable), and nothing of the robot
%% runs at `high' or `max'. While a drain is in progress someone waits on
%% it: the feeder runs at `normal' until it is answered.
%%
%% `sys:get_state/1' shows the state (`waiting' or `holding') and the
%% `#feed{}' record.
-module(toroco_tap_feeder).
-behaviour(gen_statem).

-include("toroco_wire.hrl").

-export([start_link/4, drain/3]).
-export([batch/4, nudge/1, relayed/4, flushed/2]).
-export([callback_mode/0, init/1, handle_event/4]).

-define(BATCH(Ref, Producer, Events, N), {'$toroco_tap_batch', Ref, Producer, Events, N}).
-define(NUDGE, '$toroco_tap_nudge').
-define(RELAYED(Ref, Events, N, Dropped), {'$toroco_tap_relayed', Ref, Events, N, Dropped}).
-define(FLUSHED(Tag, Producer), {'$toroco_tap_flushed', Tag, Producer}).
-define(DRAIN(Producers, Timeout), {drain, Producers, Timeout}).
%% How long a feeder holds the batches that came, to merge them.
-define(MERGE_MS, 3).
%% How often it looks at the subscriber's queue while that may be filling.
-define(LOOK_MS, 5).

-record(feed, {sub :: pid(),
               mon :: reference(),
               ref :: reference(),
               credit :: toroco_tap_credit:credit(),
               delivery :: toroco_tap:delivery(),
               %% with batch delivery: how many events each message sent
               %% and maybe not read yet holds, newest first
               sent = [] :: [pos_integer()],
               %% batches held for the merge, per producer (each newest
               %% first), and how many events
               held = #{} :: #{pid() => [[toroco_tap:event()]]},
               n = 0 :: non_neg_integer(),
               %% whether a look is due (the timeout `look' is set)
               looking = false :: boolean(),
               %% drains in progress: the producers each still waits for
               drains = #{} :: #{reference() => {gen_statem:from(), #{pid() => reference()}}}}).

%%====================================================================
%% API
%%====================================================================

%% @doc Starts the feeder of subscription `Ref' for `Sub'. A feeder that
%% fell behind a busy CPU holds many batches for a while; what they leave in
%% its old heap goes at the next full sweep, not at the default's 65,535th
%% collection (a 10-minute soak under load grew 13 %, most of it in
%% feeders' old heaps).
-spec start_link(pid(), reference(), toroco_tap_credit:credit(), toroco_tap:delivery()) ->
          {ok, pid()} | {error, term()}.
start_link(Sub, Ref, Credit, Delivery) ->
    gen_statem:start_link(?MODULE, {Sub, Ref, Credit, Delivery},
                          [{spawn_opt, [{fullsweep_after, 10}]}]).

%% @doc Passes on every event `Producers' (the event path's processes of
%% this node) tapped before this call, and what the feeder holds, then
%% answers; a producer that has not answered within `Timeout' ms is named
%% in the error.
-spec drain(pid(), [pid()], timeout()) -> ok | {error, term()}.
drain(Feeder, Producers, Timeout) ->
    try gen_statem:call(Feeder, ?DRAIN(Producers, Timeout), Timeout + 1000)
    catch exit:{noproc, _} -> {error, {not_running, tap_feeder}};
          exit:{normal, _} -> {error, {not_running, tap_feeder}};
          exit:{timeout, _} -> {error, {timeout, tap_feeder}}
    end.

%% @doc A producer's batch of `N' events for subscription `Ref'.
-spec batch(pid(), reference(), [toroco_tap:event()], pos_integer()) -> ok.
batch(Feeder, Ref, Events, N) ->
    Feeder ! ?BATCH(Ref, self(), Events, N),
    ok.

%% @doc The first drops since the feeder last reported them.
-spec nudge(pid()) -> ok.
nudge(Feeder) ->
    Feeder ! ?NUDGE,
    ok.

%% @doc Events of another node (in order) and the count dropped there;
%% `busy' if the connection to the feeder's node is congested (nothing was
%% sent).
-spec relayed(pid(), reference(), [toroco_tap:event()], non_neg_integer()) -> ok | busy.
relayed(Feeder, Ref, Events, Dropped) ->
    case erlang:send(Feeder, ?RELAYED(Ref, Events, length(Events), Dropped), [nosuspend, noconnect]) of
        ok -> ok;
        _ -> busy
    end.

%% @doc A producer's answer to `WIRE_TAP_FLUSH(Feeder, Tag)', after its batch.
-spec flushed(pid(), reference()) -> ok.
flushed(Feeder, Tag) ->
    Feeder ! ?FLUSHED(Tag, self()),
    ok.

%%====================================================================
%% The process
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init({pid(), reference(), toroco_tap_credit:credit(), toroco_tap:delivery()}) ->
          {ok, waiting, #feed{}}.
init({Sub, Ref, Credit, Delivery}) ->
    process_flag(priority, low),
    {ok, waiting, #feed{sub = Sub, mon = erlang:monitor(process, Sub), ref = Ref,
                        credit = Credit, delivery = Delivery}}.

-spec handle_event(gen_statem:event_type(), term(), waiting | holding, #feed{}) ->
          gen_statem:event_handler_result(waiting | holding).
%% Room was taken for these by their producer; they wait for the batches
%% of the other producers (?MERGE_MS).
handle_event(info, ?BATCH(Ref, Producer, Events, N), waiting, F = #feed{ref = Ref}) ->
    {next_state, holding, hold(Producer, Events, N, F), [{state_timeout, ?MERGE_MS, release}]};
handle_event(info, ?BATCH(Ref, Producer, Events, N), holding, F = #feed{ref = Ref}) ->
    {keep_state, hold(Producer, Events, N, F)};
handle_event(state_timeout, release, holding, F) ->
    looked(settle(release(F)), waiting);
handle_event(info, ?RELAYED(Ref, Events, N, Dropped), _, F = #feed{ref = Ref, credit = C}) ->
    _ = toroco_tap_credit:dropped(C, Dropped),
    Admitted = toroco_tap_credit:admit(C, N),
    F1 = pass(lists:sublist(Events, Admitted), Admitted, F),
    ok = toroco_tap_credit:passed(C, {0, Admitted}),
    looked(settle(F1), keep);
handle_event({timeout, look}, look, _, F) ->
    looked(look(F#feed{looking = false}), keep);
handle_event(info, ?NUDGE, _, F) ->
    looked(look(F), keep);
handle_event({call, From}, ?DRAIN(Producers, Timeout), St, F) ->
    start_drain(From, Producers, Timeout, St, F);
handle_event(info, ?FLUSHED(Tag, Producer), St, F = #feed{drains = Ds}) ->
    case Ds of
        #{Tag := {_, #{Producer := _}}} -> answered([Tag], Producer, St, F);
        #{} -> keep_state_and_data              % too late: the drain is over
    end;
handle_event({timeout, {drain, Tag}}, expired, St, F = #feed{drains = Ds}) when is_map_key(Tag, Ds) ->
    finish([Tag], St, F);
handle_event(info, {'DOWN', Mon, process, _, _}, _, #feed{mon = Mon}) ->
    {stop, normal};
handle_event(info, {'DOWN', _, process, Pid, _}, St, F = #feed{drains = Ds}) ->
    %% A producer that dies sent its batch first (its terminate).
    answered([Tag || {Tag, {_, W}} <- maps:to_list(Ds), is_map_key(Pid, W)], Pid, St, F);
handle_event(_Type, _Content, _St, _F) ->
    keep_state_and_data.

%%====================================================================
%% Holding and passing on
%%====================================================================

hold(Producer, Events, N, F = #feed{held = H, n = Held}) ->
    F#feed{held = maps:update_with(Producer, fun(L) -> [Events | L] end, [Events], H), n = Held + N}.

%% The held batches go on, merged by time stamp: each producer's events
%% keep their order, and an event caused by another (an emission, then its
%% delivery) mostly comes after it even though their producers' batches
%% came in either order.
release(F = #feed{n = 0}) ->
    F;
release(F = #feed{held = H, n = N, credit = C}) ->
    Runs = [lists:append(lists:reverse(Bs)) || Bs <- maps:values(H)],
    %% by the time stamp, every event's second element; on a tie the one
    %% merged already first
    Merged = lists:foldl(fun(Run, Acc) -> lists:keymerge(2, Acc, Run) end, [], Runs),
    F1 = pass(Merged, N, F),
    ok = toroco_tap_credit:passed(C, {0, N}),
    F1#feed{held = #{}, n = 0}.

%% The events go on, counted as pending before their room is given back
%% (toroco_tap_credit:passed/2 after this).
pass(_Events, 0, F) ->
    F;
pass(Events, N, F = #feed{sub = Sub, ref = Ref, credit = C, delivery = event}) ->
    ok = toroco_tap_credit:passed(C, {N, 0}),
    _ = [Sub ! {toroco_event, Ref, E} || E <- Events],
    F;
pass(Events, N, F = #feed{sub = Sub, ref = Ref, credit = C, delivery = batch, sent = Sent}) ->
    ok = toroco_tap_credit:passed(C, {N, 0}),
    Sub ! {toroco_events, Ref, Events},
    F#feed{sent = [N | Sent]}.

%%====================================================================
%% Looking at the subscriber's queue
%%====================================================================

%% After passing events on: look at the subscriber's queue only if it may
%% be filling up or drops wait to be reported.
settle(F = #feed{credit = C}) ->
    case toroco_tap_credit:tight(C) of
        true -> look(F);
        false -> F
    end.

%% Events pending in the subscriber's queue of `Len' messages: one each,
%% or with batch delivery what the newest `Len' batches held (the older
%% ones were read).
pending(Len, F = #feed{delivery = event}) ->
    {Len, F};
pending(Len, F = #feed{sent = Sent}) ->
    Unread = lists:sublist(Sent, Len),
    {lists:sum(Unread), F#feed{sent = Unread}}.

look(F0 = #feed{sub = Sub, credit = C}) ->
    case erlang:process_info(Sub, message_queue_len) of
        {message_queue_len, Len} ->
            {Pending, F1} = pending(Len, F0),
            F = case toroco_tap_credit:seen(C, Pending) of
                    true -> report_drops(F1);
                    false -> F1
                end,
            F#feed{looking = F#feed.looking orelse toroco_tap_credit:tight(C)};
        undefined ->
            F0                                  % its DOWN is on its way
    end.

report_drops(F = #feed{credit = C}) ->
    case toroco_tap_credit:unreported(C) of
        0 -> F;
        _ -> pass([{dropped, toroco_tap_credit:take_dropped(C)}], 1, F)
    end.

%% The next state, with the look timer set if a look became due.
looked(F = #feed{looking = true}, Next) ->
    Look = {{timeout, look}, ?LOOK_MS, look},
    case Next of
        keep -> {keep_state, F, [Look]};
        St -> {next_state, St, F, [Look]}
    end;
looked(F, keep) ->
    {keep_state, F};
looked(F, St) ->
    {next_state, St, F}.

%%====================================================================
%% Drains
%%====================================================================

start_drain(From, Producers, Timeout, St, F = #feed{drains = Ds}) ->
    Tag = make_ref(),
    Waiting = maps:from_list([{P, erlang:monitor(process, P)} || P <- Producers]),
    _ = [P ! ?WIRE_TAP_FLUSH(self(), Tag) || P <- Producers],
    process_flag(priority, normal),
    F1 = F#feed{drains = Ds#{Tag => {From, Waiting}}},
    case map_size(Waiting) of
        0 -> finish([Tag], St, F1);
        _ -> {keep_state, F1, [{{timeout, {drain, Tag}}, Timeout, expired}]}
    end.

%% `Producer' sent its batch (or died) for the drains `Tags'.
answered(Tags, Producer, St, F0) ->
    {F, Done} = lists:foldl(fun(Tag, {F1 = #feed{drains = Ds}, Acc}) ->
                                    {From, Waiting} = maps:get(Tag, Ds),
                                    erlang:demonitor(maps:get(Producer, Waiting), [flush]),
                                    W1 = maps:remove(Producer, Waiting),
                                    Acc1 = case map_size(W1) of 0 -> [Tag | Acc]; _ -> Acc end,
                                    {F1#feed{drains = Ds#{Tag := {From, W1}}}, Acc1}
                            end, {F0, []}, Tags),
    finish(Done, St, F).

%% The drains `Tags' are answered: everything held goes now, and the drops
%% not reported yet even if the subscriber is behind (it is about to read
%% all it has); the feeder is back at low priority when none is left.
finish([], _St, F) ->
    {keep_state, F};
finish(Tags, _St, F = #feed{drains = Ds}) ->
    F1 = report_drops(release(F#feed{drains = maps:without(Tags, Ds)})),
    _ = map_size(F1#feed.drains) =:= 0 andalso process_flag(priority, low),
    Replies = lists:append([[{reply, From, answer(W)}, {{timeout, {drain, Tag}}, cancel}]
                            || Tag <- Tags, {From, W} <- [maps:get(Tag, Ds)]]),
    {next_state, waiting, F1, Replies}.

answer(Waiting) when map_size(Waiting) =:= 0 ->
    ok;
answer(Waiting) ->
    maps:foreach(fun(_, Mon) -> erlang:demonitor(Mon, [flush]) end, Waiting),
    {error, {timeout, maps:keys(Waiting)}}.
