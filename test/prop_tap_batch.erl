%% @doc Properties of a producer's tap batch (`toroco_tap_batch', SPEC §10):
%% random sequences of events tapped for up to three subscriptions, with
%% random grants of room (0 to 16, as `toroco_tap_credit:reserve/1' gives),
%% and flushes, checked against a model that says, event by event, which
%% are kept and which are dropped.
%% <ul>
%% <li>{@link prop_order/0}: what goes to each subscription's feeder, part
%% after part, is the events tapped for it that the model keeps, in the
%% order they were tapped.</li>
%% <li>{@link prop_counts/0}: every event is kept or counted as dropped,
%% exactly once; the drops are the model's; the room a part gives back is
%% what it took and did not use; no part holds more than the batch's
%% maximum.</li>
%% </ul>
%% Sections: generators, running a sequence, the model, properties.
-module(prop_tap_batch).

-define(PROPER_NO_TRANS, true).
-include_lib("proper/include/proper.hrl").

-export([prop_order/0, prop_counts/0]).

-define(SINKS, 3).

%%====================================================================
%% Generators
%%====================================================================

%% `{tap, Sink, Grant}': an event for subscription Sink; Grant is the room
%% the credit gives if the part asks for it. `flush': the batch goes.
%% Long runs of taps, so that parts fill to the maximum.
command() ->
    frequency([{40, {tap, range(1, ?SINKS), grant()}},
               {1, flush}]).

grant() ->
    frequency([{6, 16}, {2, range(1, 15)}, {2, 0}]).

commands() ->
    ?SIZED(Size, resize(Size * 6, list(command()))).

%%====================================================================
%% Running a sequence through toroco_tap_batch
%%====================================================================

%% The sealed parts in the order they went, and the grants taken per sink.
run(Commands) ->
    Sinks = maps:from_list([{I, {make_ref(), self(), none}} || I <- lists:seq(1, ?SINKS)]),
    {Batch, Sealed, Taken, _} =
        lists:foldl(fun(C, Acc) -> step(C, Sinks, Acc) end,
                    {toroco_tap_batch:new(), [], #{}, 1}, Commands),
    {Sinks, lists:reverse(Sealed, toroco_tap_batch:seal(Batch)), Taken}.

step({tap, I, Grant}, Sinks, {Batch, Sealed, Taken, Seq}) ->
    Sink = maps:get(I, Sinks),
    {{Batch1, Out}, Given} = case toroco_tap_batch:add(Sink, {I, Seq}, Batch) of
                                 need_room -> {toroco_tap_batch:add(Sink, {I, Seq}, Grant, Batch),
                                               Grant};
                                 Done -> {Done, 0}
                             end,
    {Batch1, lists:reverse(Out, Sealed), maps:update_with(I, fun(G) -> G + Given end, Given, Taken),
     Seq + 1};
step(flush, _Sinks, {Batch, Sealed, Taken, Seq}) ->
    {toroco_tap_batch:new(), lists:reverse(toroco_tap_batch:seal(Batch), Sealed), Taken, Seq}.

%%====================================================================
%% The model
%%====================================================================

%% Per sink, event by event: a part has room it took; when it has none it
%% takes the next grant; a grant of 0 makes it full, and every event until
%% the part goes is dropped; the part goes at a flush or when it holds the
%% maximum. Returns, per sink, the events kept (in order) and the number
%% dropped.
model(Commands) ->
    Max = toroco_tap_batch:max_events(),
    Init = maps:from_list([{I, {fresh, [], 0, 0}} || I <- lists:seq(1, ?SINKS)]),
    {Parts, _} = lists:foldl(fun(C, {M, Seq}) -> model_step(C, Seq, Max, M) end, {Init, 1}, Commands),
    maps:map(fun(_, {_, Kept, Dropped, _}) -> {lists:reverse(Kept), Dropped} end, Parts).

model_step(flush, Seq, _Max, M) ->
    {maps:map(fun(_, {_, Kept, D, _}) -> {fresh, Kept, D, 0} end, M), Seq};
model_step({tap, I, Grant}, Seq, Max, M) ->
    {Room, Kept, D, InPart} = maps:get(I, M),
    Part = case Room of
               full -> {full, Kept, D + 1, InPart};
               R when is_integer(R), R > 0 -> {R - 1, [{I, Seq} | Kept], D, InPart + 1};
               _ when Grant > 0 -> {Grant - 1, [{I, Seq} | Kept], D, InPart + 1};
               _ -> {full, Kept, D + 1, InPart}
           end,
    Part1 = case Part of
                {_, K, D1, Max} -> {fresh, K, D1, 0};
                _ -> Part
            end,
    {M#{I := Part1}, Seq + 1}.

%%====================================================================
%% Properties
%%====================================================================

prop_order() ->
    ?FORALL(Commands, commands(),
            begin
                {Sinks, Sealed, _} = run(Commands),
                Model = model(Commands),
                Bad = [{I, #{sent => Sent, model => Kept}}
                       || I <- lists:seq(1, ?SINKS),
                          {Ref, _, _} <- [maps:get(I, Sinks)],
                          Sent <- [lists:append([Es || #{ref := R, events := Es} <- Sealed, R =:= Ref])],
                          {Kept, _} <- [maps:get(I, Model)],
                          Sent =/= Kept],
                ?WHENFAIL(io:format("per sink: ~p~n", [Bad]), Bad =:= [])
            end).

prop_counts() ->
    ?FORALL(Commands, commands(),
            begin
                {Sinks, Sealed, Taken} = run(Commands),
                Model = model(Commands),
                Bad = [{I, Facts} || I <- lists:seq(1, ?SINKS),
                                     Facts <- [counts(I, Commands, Sinks, Sealed, Taken, Model)],
                                     not maps:get(ok, Facts)],
                ?WHENFAIL(io:format("per sink: ~p~n", [Bad]), Bad =:= [])
            end).

counts(I, Commands, Sinks, Sealed, Taken, Model) ->
    {Ref, _, _} = maps:get(I, Sinks),
    Parts = [P || P = #{ref := R} <- Sealed, R =:= Ref],
    Sum = fun(K) -> lists:sum([maps:get(K, P) || P <- Parts]) end,
    Tapped = length([x || {tap, J, _} <- Commands, J =:= I]),
    {_, ModelDropped} = maps:get(I, Model),
    Max = toroco_tap_batch:max_events(),
    Facts = #{tapped => Tapped, kept => Sum(n), dropped => Sum(dropped),
              model_dropped => ModelDropped, unused => Sum(unused), taken => maps:get(I, Taken, 0)},
    Facts#{ok => Sum(n) + Sum(dropped) =:= Tapped
               andalso Sum(dropped) =:= ModelDropped
               andalso Sum(n) + Sum(unused) =:= maps:get(I, Taken, 0)
               andalso lists:all(fun(#{n := N, events := Es}) -> N =:= length(Es) andalso N =< Max end,
                                 Parts)}.
