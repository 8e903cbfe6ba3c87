%% @doc What a device does with input it cannot use: count it by reason and
%% say so through `logger', at most once a second per device.
%%
%% Every device of `toroco_hw' that reads the outside world (datagrams,
%% TCP lines, port events, polled functions, actuator functions) keeps one of
%% these in its data and shows {@link counts/1} in its `info/2' map, so the
%% counters appear under `device' in `toroco:inspect(Name)'. A flood of bad
%% input costs one warning a second, naming the device, the reason, a short
%% excerpt of the culprit and how many warnings were held back since the last.
-module(toroco_bad_input).

-export([new/1, count/3, counts/1, total/1]).
-export_type([t/0]).

-define(INTERVAL_MS, 1000).
-define(EXCERPT_BYTES, 64).

-opaque t() :: #{device := atom(),
                 counts := #{atom() => pos_integer()},
                 last_log := integer() | never,
                 held := non_neg_integer()}.

%% @doc Counters for device `Device'.
-spec new(atom()) -> t().
new(Device) ->
    #{device => Device, counts => #{}, last_log => never, held => 0}.

%% @doc One bad input, for `Reason'; `Culprit' is shown (shortened) in the
%% warning if one is logged now.
-spec count(atom(), term(), t()) -> t().
count(Reason, Culprit, T = #{device := Dev, counts := C, last_log := Last, held := Held}) ->
    T1 = T#{counts := C#{Reason => maps:get(Reason, C, 0) + 1}},
    Now = erlang:monotonic_time(millisecond),
    case Last =:= never orelse Now - Last >= ?INTERVAL_MS of
        true ->
            logger:warning("~p dropped bad input (~p): ~ts~ts",
                           [Dev, Reason, excerpt(Culprit), held_note(Held)],
                           #{domain => [toroco, hw], device => Dev}),
            T1#{last_log := Now, held := 0};
        false ->
            T1#{held := Held + 1}
    end.

%% @doc Counts by reason.
-spec counts(t()) -> #{atom() => pos_integer()}.
counts(#{counts := C}) -> C.

%% @doc All bad inputs counted so far.
-spec total(t()) -> non_neg_integer().
total(#{counts := C}) -> lists:sum(maps:values(C)).

held_note(0) -> "";
held_note(N) -> io_lib:format(" (~b more since the last warning)", [N]).

excerpt(B) when is_binary(B), byte_size(B) > ?EXCERPT_BYTES ->
    io_lib:format("~0p... (~b bytes)", [binary:part(B, 0, ?EXCERPT_BYTES), byte_size(B)]);
excerpt(Term) ->
    io_lib:format("~0P", [Term, 12]).
