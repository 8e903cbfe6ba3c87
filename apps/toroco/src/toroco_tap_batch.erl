%% @doc The batch a producer of the observer tap keeps (SPEC §10): the
%% events it tapped and has not sent yet, one part per subscription, as a
%% pure value. It lives in the state of a behavior, device, router or gate
%% (through `toroco_tap:tap/3'); nothing here sends, reads a clock or
%% touches a subscription's credit: the room a part may use is an argument
%% ({@link add/4}), and what goes to a feeder comes back as {@link sealed()}
%% values for `toroco_tap' to send.
%%
%% A part takes room a few events at a time (a grant, `toroco_tap_credit')
%% and keeps events while it has room; a part that asked for room and got
%% none is `full': every event until the part goes is counted as dropped
%% without asking again. A part goes when it holds `?BATCH_MAX' events, or
%% when the whole batch is sealed ({@link seal/1}). Each part keeps the
%% order in which its events came, and every event is either kept or
%% counted (`test/prop_tap_batch.erl' checks both against a model).
%%
%% <ul>
%% <li>Building: {@link new/0}, {@link needs_room/2}, {@link add/4}.</li>
%% <li>Sending: {@link seal/1}.</li>
%% </ul>
-module(toroco_tap_batch).

-export([new/0, needs_room/2, add/4, seal/1, max_events/0]).
-export_type([batch/0, sink/0, sealed/0]).

-define(BATCH_MAX, 128).

%% One subscription as a producer sees it: its reference, its feeder, and
%% its credit (opaque here).
-type sink() :: {reference(), pid(), toroco_tap_credit:credit()}.

-record(part, {ref :: reference(),
               feeder :: pid(),
               credit :: toroco_tap_credit:credit(),
               %% room taken and not used yet; `full' once a grant came empty
               room = 0 :: non_neg_integer() | full,
               n = 0 :: non_neg_integer(),
               dropped = 0 :: non_neg_integer(),
               %% newest first
               events = [] :: [term()]}).

%% `[]' when the producer holds nothing (the engines test for it); its
%% parts are this module's business.
-type batch() :: [#part{}].

%% A part that goes: its events in the order they came, how many, the room
%% it took and did not use (given back), and the events it dropped.
-type sealed() :: #{ref := reference(), feeder := pid(), credit := toroco_tap_credit:credit(),
                    events := [term()], n := non_neg_integer(), unused := non_neg_integer(),
                    dropped := non_neg_integer()}.

%% @doc An empty batch.
-spec new() -> batch().
new() -> [].

%% @doc How many events a part holds at most before it goes by itself.
-spec max_events() -> pos_integer().
max_events() -> ?BATCH_MAX.

%% @doc Whether the part of subscription `Ref' must be granted room before
%% it takes its next event (it has none left, or there is no part yet);
%% a `full' part needs none: it drops.
-spec needs_room(reference(), batch()) -> boolean().
needs_room(Ref, Batch) ->
    case lists:keyfind(Ref, #part.ref, Batch) of
        #part{room = 0} -> true;
        #part{} -> false;
        false -> true
    end.

%% @doc `Event' for `Sink': kept if its part has room, or if `Grant' (the
%% room just taken, when {@link needs_room/2} said so; else 0) gives some;
%% otherwise counted as dropped, and the part is full until it goes. A part
%% that reaches `?BATCH_MAX' events leaves the batch, sealed.
-spec add(sink(), term(), non_neg_integer(), batch()) -> {batch(), [sealed()]}.
add({Ref, Feeder, Credit}, Event, Grant, Batch) ->
    Part = case lists:keyfind(Ref, #part.ref, Batch) of
               false -> #part{ref = Ref, feeder = Feeder, credit = Credit};
               P -> P
           end,
    case keep(Event, Grant, Part) of
        Full = #part{n = ?BATCH_MAX} -> {lists:keydelete(Ref, #part.ref, Batch), [sealed(Full)]};
        Part1 -> {lists:keystore(Ref, #part.ref, Batch, Part1), []}
    end.

keep(_Event, _Grant, P = #part{room = full, dropped = D}) ->
    P#part{dropped = D + 1};
keep(Event, _Grant, P = #part{room = Room, n = N, events = Es}) when Room > 0 ->
    P#part{room = Room - 1, n = N + 1, events = [Event | Es]};
keep(_Event, 0, P = #part{room = 0, dropped = D}) ->
    P#part{room = full, dropped = D + 1};
keep(Event, Grant, P = #part{room = 0}) ->
    keep(Event, 0, P#part{room = Grant}).

%% @doc Every part, sealed: the batch goes.
-spec seal(batch()) -> [sealed()].
seal(Batch) ->
    [sealed(P) || P <- Batch].

sealed(#part{ref = Ref, feeder = F, credit = C, room = Room, n = N, dropped = D, events = Es}) ->
    #{ref => Ref, feeder => F, credit => C, events => lists:reverse(Es), n => N,
      unused => case Room of full -> 0; _ -> Room end, dropped => D}.
