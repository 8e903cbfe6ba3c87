%% @doc Replay (SPEC §12): `toroco_rec:replay/2' (`toroco_live:replay/2')
%% re-emits a recording's events of the listed sources (normally the
%% sensors) into the running wiring, at their recorded pace, and compares
%% what the actuators then receive with what the recording says they
%% received.
%%
%% The file is read whole and checked (`toroco_rec_mcap:read/1'): a file
%% that is not MCAP, is truncated, has a bad CRC, or was not written by
%% `toroco_rec' (whose files name the library `toroco_live', as those
%% written before it was an application of its own) is refused with a
%% reason before anything is injected.
%%
%% Each recorded emission (`/toroco/out/S/O') of a listed source becomes
%% `toroco:inject/2' (a `send') or `inject/3' with `latch' (a `set'); an
%% `unset' cannot be injected and is skipped. Its term is read back with
%% `toroco_rec_json:parse_term/1'. The actuators are the receivers of the
%% recording's `/toroco/in/R/I' channels that are devices of the running
%% wiring and not sources; their deliveries from the first replayed event
%% on are compared in order, per input, with those seen now (through the
%% tap). The call returns when the last event has been replayed and the
%% actuators have had `?SETTLE_MS' to answer.
%%
%% A recording in another profile (`ros2', a `toroco_rec_profile') replays
%% too: its wrapper channels (`std_msgs/msg/String') carry the same JSON,
%% which the profile reads back (`text_json/1'), so the outputs recorded
%% that way are replayed and the deliveries compared; an output recorded
%% with a typed message (a range sensor's Range) cannot be, and is not.
-module(toroco_rec_replay).

-export([replay/2]).

-define(SETTLE_MS, 500).
-define(MAX_DIFFS, 50).

-spec replay(file:filename_all(), #{sources := [atom()]}) ->
          {ok, #{replayed := non_neg_integer(), matched := non_neg_integer(), differed := [map()]}}
              | {error, term()}.
replay(Path, #{sources := Sources} = Opts) when is_list(Sources) ->
    case maps:keys(maps:without([sources], Opts)) of
        [] ->
            case file:read_file(Path) of
                {ok, Bin} -> replay_contents(toroco_rec_mcap:read(Bin), Sources);
                {error, Why} -> {error, {cannot_read, Path, Why}}
            end;
        [Bad | _] -> {error, {bad_option, Bad}}
    end;
replay(_Path, Opts) ->
    {error, {bad_option, Opts}}.

replay_contents({error, _} = Err, _) ->
    Err;
replay_contents({ok, #{library := Lib} = C}, Sources) ->
    Ours = toroco_rec_mcap:library(),
    case binary:longest_common_prefix([Lib, Ours]) >= byte_size(<<"toroco_live">>) of
        true -> run(messages(C), Sources);
        false -> {error, {not_a_toroco_recording, Lib}}
    end.

%% Each message as {T, Key, Json}; channels that are not ours are left out.
messages(#{channels := Chs, schemas := Schemas, messages := Ms}) ->
    Keys = maps:map(fun(_, Ch = #{topic := T}) ->
                            case {toroco_rec_channels:key(T), json_of(Ch, Schemas)} of
                                {{ok, K}, {ok, Json}} -> {ok, K, Json};
                                _ -> error
                            end
                    end, Chs),
    [{T, K, Json} || #{channel := Ch, log_time := T, data := D} <- Ms,
                     {ok, K, JsonOf} <- [maps:get(Ch, Keys, error)],
                     {ok, Json} <- [JsonOf(D)]].

%% How a channel's message becomes the JSON of SPEC §12: as it is, or (the
%% profile of another application) its text type's JSON.
json_of(#{encoding := <<"json">>}, _) ->
    {ok, fun(D) -> {ok, D} end};
json_of(#{schema := S}, Schemas) ->
    case Schemas of
        #{S := #{name := Name}} ->
            case [M || {_, M} <- toroco_rec_profile:all(), M:text_type() =:= Name] of
                [Module | _] -> {ok, fun Module:text_json/1};
                [] -> error
            end;
        #{} -> error
    end;
json_of(_, _) ->
    error.

run(Messages, Sources) ->
    Emissions = [{T, E, O, Kind, Term}
                 || {T, {out, E, O}, D} <- Messages, lists:member(E, Sources),
                    {ok, Kind, Term} <- [emission(D)]],
    case Emissions of
        [] -> {error, {nothing_to_replay, Sources}};
        [{T0, _, _, _, _} | _] ->
            Devices = maps:get(devices, toroco:inspect()),
            Actuators = lists:usort([R || {_, {in, R, _}, _} <- Messages,
                                          lists:member(R, Devices), not lists:member(R, Sources)]),
            Recorded = [{{R, I}, Term} || {T, {in, R, I}, D} <- Messages, T >= T0,
                                          lists:member(R, Actuators),
                                          {ok, Term} <- [delivery(D)]],
            {ok, Tap} = toroco:subscribe_events(#{kinds => [deliver], names => Actuators}),
            Replayed = emit_all(Emissions, T0, erlang:monotonic_time(millisecond), 0),
            Seen = collect(Tap, erlang:monotonic_time(millisecond) + ?SETTLE_MS, []),
            toroco:unsubscribe_events(Tap),
            {Matched, Differed} = compare(group(Recorded), group(Seen)),
            {ok, #{replayed => Replayed, matched => Matched, differed => Differed}}
    end.

emission(Data) ->
    try jiffy:decode(Data, [return_maps]) of
        #{<<"kind">> := Kind, <<"term">> := Text} when Kind =:= <<"send">>; Kind =:= <<"set">> ->
            case toroco_rec_json:parse_term(Text) of
                {ok, Term} -> {ok, binary_to_existing_atom(Kind), Term};
                Err -> Err
            end;
        _ -> skip
    catch _:_ -> skip
    end.

delivery(Data) ->
    try jiffy:decode(Data, [return_maps]) of
        #{<<"term">> := Text} -> toroco_rec_json:parse_term(Text);
        _ -> skip
    catch _:_ -> skip
    end.

emit_all([], _, _, N) ->
    N;
emit_all([{T, E, O, Kind, Term} | Rest], T0, Start, N) ->
    Due = Start + (T - T0) div 1000000,
    Wait = Due - erlang:monotonic_time(millisecond),
    Wait > 0 andalso timer:sleep(Wait),
    Result = case Kind of
                 send -> toroco:inject({E, O}, Term);
                 set -> toroco:inject({E, O}, Term, #{latch => true})
             end,
    emit_all(Rest, T0, Start, case Result of ok -> N + 1; _ -> N end).

collect(Tap, Until, Acc) ->
    Left = max(0, Until - erlang:monotonic_time(millisecond)),
    receive
        {toroco_event, Tap, {deliver, _, Input, Value}} -> collect(Tap, Until, [{Input, Value} | Acc]);
        {toroco_event, Tap, _} -> collect(Tap, Until, Acc)
    after Left -> lists:reverse(Acc)
    end.

group(Pairs) ->
    lists:foldr(fun({K, V}, M) -> maps:update_with(K, fun(L) -> [V | L] end, [V], M) end, #{}, Pairs).

%% Per input, the recorded and the replayed deliveries side by side.
compare(Recorded, Seen) ->
    Inputs = lists:usort(maps:keys(Recorded) ++ maps:keys(Seen)),
    {Matched, Diffs} =
        lists:foldl(fun(In, {M, D}) ->
                            {M1, D1} = zip(In, 1, maps:get(In, Recorded, []), maps:get(In, Seen, []), M, D),
                            {M1, D1}
                    end, {0, []}, Inputs),
    {Matched, lists:sublist(lists:reverse(Diffs), ?MAX_DIFFS)}.

zip(_, _, [], [], M, D) -> {M, D};
zip(In, I, [V | R], [V | S], M, D) -> zip(In, I + 1, R, S, M + 1, D);
zip(In, I, R, S, M, D) ->
    {Rec, R1} = first(R),
    {Got, S1} = first(S),
    zip(In, I + 1, R1, S1, M, [#{input => In, index => I, recorded => Rec, replayed => Got} | D]).

first([]) -> {missing, []};
first([V | R]) -> {{value, V}, R}.
