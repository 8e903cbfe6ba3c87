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
%% <li>Building: {@link new/0}, {@link add/3}, {@link add/4}.</li>
%% <li>Sending: {@link seal/1}.</li>
%% </ul>
-module(toroco_tap_batch).

-export([new/0, add/3, add/4, seal/1, max_events/0]).
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

%% @doc `Event' for `Sink' if its part needs no room for it (it has room
%% left, or is `full' and drops it): as {@link add/4} with no grant; or
%% `need_room' (it has none left, or there is no part yet), and then {@link
%% add/4} with the room just taken. Each event costs one look at the batch.
-spec add(sink(), term(), batch()) -> {batch(), [sealed()]} | need_room.
add({Ref, _, _}, Event, Batch) ->
    case lists:keyfind(Ref, #part.ref, Batch) of
        #part{room = 0} -> need_room;
        false -> need_room;
        Part -> kept(Ref, keep(Event, 0, Part), Batch)
    end.

%% @doc `Event' for `Sink' with `Grant', the room just taken when {@link
%% add/3} said `need_room': kept if the grant gives room; otherwise counted
%% as dropped, and the part is full until it goes. A part that reaches
%% `?BATCH_MAX' events leaves the batch, sealed.
-spec add(sink(), term(), non_neg_integer(), batch()) -> {batch(), [sealed()]}.
add({Ref, Feeder, Credit}, Event, Grant, Batch) ->
    Part = case lists:keyfind(Ref, #part.ref, Batch) of
               false -> #part{ref = Ref, feeder = Feeder, credit = Credit};
               P -> P
           end,
    kept(Ref, keep(Event, Grant, Part), Batch).

kept(Ref, Full = #part{n = ?BATCH_MAX}, Batch) ->
    {lists:keydelete(Ref, #part.ref, Batch), [sealed(Full)]};
kept(Ref, Part = #part{}, [#part{ref = Ref}]) ->
    {[Part], []};                               % one subscription: the common case
kept(Ref, Part, Batch) ->
    {lists:keystore(Ref, #part.ref, Batch, Part), []}.

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
