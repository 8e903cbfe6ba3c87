%% @doc The `toroco:top/0' table: the whole running network as text, for a
%% remote shell (`bin/torobot top' prints it too).
%%
%% It reads the maps of `toroco_inspect', the restart counts of
%% `toroco_restarts' and each process's callback state and queue, and lays
%% them out with a small text-table engine: left-aligned columns, long cells
%% cut, a cell of several lines keeping the rest of its row on the first.
%%
%% <ul>
%% <li>{@link print/0}: prints the table to the caller's group leader.</li>
%% <li>{@link iodata/0}: the same table as text.</li>
%% </ul>
-module(toroco_top).

-export([print/0, iodata/0, row/1]).

%% Cells longer than this are cut (the last column of a table is not).
-define(CELL, 40).
%% Depth to which values are printed.
-define(DEPTH, 8).
%% Device counters wrap at this width.
-define(COUNTERS_WIDTH, 90).
%% How long top waits for a busy behavior to tell its state.
-define(STATE_TIMEOUT, 500).

%% @doc Prints {@link iodata/0} to the caller's group leader.
-spec print() -> ok.
print() ->
    io:put_chars(iodata()).

%% @doc The table as text: the layers, then one row per behavior
%% and device (highest layer first, devices last) with its status, the
%% state of its callback module, its message queue and its restarts (see
%% `toroco_restarts'); then every wired input with its winner, holds (ms
%% left), latched values and last value delivered; the inhibited outputs;
%% and the devices' own counters.
-spec iodata() -> iodata().
iodata() ->
    #{behaviors := Bs, devices := Ds, layers := Layers, removed_layers := Removed} = Overview =
        toroco_inspect:overview(),
    %% A robot on several nodes: each row is read where its thing lives,
    %% and a column says which node that is.
    Where = maps:get(nodes, Overview, #{}),
    Nodes = [row_at(maps:get(N, Where, node()), N) || N <- Bs ++ Ds],
    Sorted = lists:sort(fun(A, B) -> order(A) =< order(B) end, Nodes),
    {UpMs, _} = erlang:statistics(wall_clock),
    [io_lib:format("toroco top  ~w  ~ts  up ~ts~n",
                   [erlang:node(), calendar:system_time_to_rfc3339(erlang:system_time(second)),
                    duration(UpMs)]),
     "layers     ", case lists:reverse(lists:sort(maps:to_list(Layers))) of
                        [] -> "none";
                        Ls -> lists:join("  ", [io_lib:format("~w: ~ts", [L, names(Ns)])
                                                || {L, Ns} <- Ls])
                    end, "\n",
     "taken out  ", case Removed of
                        [] -> "none";
                        _ -> lists:join(" ", [integer_to_list(L) || L <- Removed])
                    end, "\n",
     case toroco_wire:swallowed() of
         #{congested := 0, not_connected := 0} -> [];
         #{congested := Busy, not_connected := Down} ->
             io_lib:format("swallowed  ~b sends to other nodes: ~b congested, ~b not up~n",
                           [Busy + Down, Busy, Down])
     end, "\n",
     case map_size(Where) of
         0 ->
             table(["NODE", "KIND", "LAYER", "STATUS", "STATE", "QUEUE", "RESTARTS", "MODULE"],
                   [[atom_to_list(N), atom_to_list(K), text(L), atom_to_list(St), value(S),
                     text(Q), text(R), atom_to_list(M)]
                    || #{name := N, kind := K, layer := L, status := St, state := S, queue := Q,
                         restarts := R, module := M} <- Sorted]);
         _ ->
             table(["NODE", "ON", "KIND", "LAYER", "STATUS", "STATE", "QUEUE", "RESTARTS", "MODULE"],
                   [[atom_to_list(N), atom_to_list(maps:get(N, Where)), atom_to_list(K), text(L),
                     atom_to_list(St), value(S), text(Q), text(R), atom_to_list(M)]
                    || #{name := N, kind := K, layer := L, status := St, state := S, queue := Q,
                         restarts := R, module := M} <- Sorted])
     end,
     section("INPUT", ["WINNER", "HOLDS (ms left)", "LATCHED", "LAST"],
             [[port(N, I), source(W), holds(Hs), latches(Lt), last(Last)]
              || #{name := N, info := Info} <- Sorted,
                 {I, #{sources := [_ | _], winner := W, holds := Hs, latches := Lt,
                       last := Last}} <- lists:sort(maps:to_list(maps:get(inputs, Info, #{})))]),
     section("INHIBITED OUTPUT", ["BY", "LATCH"],
             [[port(N, O), names([source(S) || S <- Inh]), last(Latch)]
              || #{name := N, info := Info} <- Sorted,
                 {O, #{inhibited := true, inhibitors := Inh, latch := Latch}}
                     <- lists:sort(maps:to_list(maps:get(outputs, Info, #{})))]),
     section("DEVICE", ["COUNTERS"],
             [[atom_to_list(N), counters(C)]
              || #{name := N, info := #{device := C}} <- Sorted, is_map(C)])].

row_at(Node, N) when Node =:= node() -> row(N);
row_at(Node, N) ->
    try erpc:call(Node, ?MODULE, row, [N], 5000)
    catch error:{erpc, _} -> #{name => N, info => #{}, kind => '?', layer => '?', module => '?',
                               status => down, state => '-', queue => '-', restarts => '-'}
    end.

%% @doc One row of the table, read on the node where `N' lives.
-spec row(atom()) -> map().
row(N) ->
    Info = case toroco_inspect:describe(N) of
               #{} = I -> I;
               {error, _} -> #{}
           end,
    Pid = whereis(toroco_names:process(N)),
    #{name => N, info => Info,
      kind => maps:get(kind, Info, '?'), layer => maps:get(layer, Info, '?'),
      module => maps:get(module, Info, '?'), status => maps:get(status, Info, down),
      state => user_state(Pid), queue => queue(Pid), restarts => toroco_restarts:count(N)}.

%% Behaviors from the highest layer down, then devices; by name within.
order(#{kind := behavior, layer := L, name := N}) when is_integer(L) -> {0, -L, N};
order(#{kind := device, name := N}) -> {1, 0, N};
order(#{name := N}) -> {2, 0, N}.

%% The callback module's state (the gen_statem state of the engine).
user_state(undefined) -> '-';
user_state(Pid) ->
    try sys:get_state(Pid, ?STATE_TIMEOUT) of
        {S, _Data} -> {value, S};
        _ -> '?'
    catch exit:_ -> busy
    end.

queue(undefined) -> '-';
queue(Pid) ->
    case erlang:process_info(Pid, message_queue_len) of
        {message_queue_len, Q} -> Q;
        undefined -> '-'
    end.

section(_Title, _Header, []) ->
    [];
section(Title, Header, Rows) ->
    ["\n", table([Title | Header], Rows)].

%% Left-aligned columns two spaces apart; cells cut at ?CELL characters
%% except in the last column. A cell `{lines, [Line]}' takes a line each,
%% the other cells of its row stay on the first.
table(Header, Rows) ->
    All = [Header | lists:append([expand(Row) || Row <- Rows])],
    Widths = lists:foldl(fun(Row, Ws) -> [max(W, string:length(C)) || {W, C} <- lists:zip(Ws, Row)] end,
                         [0 || _ <- Header], All),
    [[string:trim(lists:join("  ", [string:pad(C, W) || {C, W} <- lists:zip(Row, Widths)]),
                  trailing), "\n"]
     || Row <- All].

%% One table row as the lines it takes, each a list of cell strings.
expand(Row) ->
    N = length(Row),
    Cells = [case {K, C} of
                 {N, {lines, Ls}} -> [unicode:characters_to_list(L) || L <- Ls];
                 {_, {lines, Ls}} -> [cut(L) || L <- Ls];
                 {N, _} -> [unicode:characters_to_list(C)];
                 _ -> [cut(C)]
             end || {K, C} <- lists:zip(lists:seq(1, N), Row)],
    Height = lists:max([length(C) || C <- Cells]),
    [[case length(C) >= K of
          true -> lists:nth(K, C);
          false -> ""
      end || C <- Cells] || K <- lists:seq(1, Height)].

cut(Chars) ->
    S = unicode:characters_to_list(Chars),
    case string:length(S) > ?CELL of
        true -> string:slice(S, 0, ?CELL - 3) ++ "...";
        false -> S
    end.

text(T) when is_atom(T) -> atom_to_list(T);
text(T) when is_integer(T) -> integer_to_list(T);
text(T) -> io_lib:format("~tw", [T]).

value({value, V}) -> show(V, ?DEPTH);
value(Other) -> text(Other).

port(N, P) -> io_lib:format("~w.~w", [N, P]).

source(none) -> "-";
source({E, O}) -> port(E, O).

names([]) -> "-";
names(Ns) -> lists:join(" ", [case N of
                                  A when is_atom(A) -> atom_to_list(A);
                                  S -> S
                              end || N <- Ns]).

%% One line per source, in priority order.
holds([]) -> "-";
holds(Hs) -> {lines, [[source(S), "=", case Ms of
                                          infinity -> "inf";
                                          _ -> integer_to_list(Ms)
                                      end] || {S, Ms} <- Hs]}.

latches([]) -> "-";
latches(Ls) -> {lines, [[source(S), "=", value({value, V})] || {S, V} <- Ls]}.

last({value, V}) -> value({value, V});
last(none) -> "-".

%% key=value pairs, as many on a line as fit in ?COUNTERS_WIDTH characters.
counters(C) ->
    Pairs = [unicode:characters_to_list([text(K), "=", show(V, 6)])
             || {K, V} <- lists:sort(maps:to_list(C))],
    {lines, [lists:join(" ", Line) || Line <- fill(Pairs, [], 0, [])]}.

fill([], [], _, Lines) -> lists:reverse(Lines);
fill([], Line, _, Lines) -> lists:reverse([lists:reverse(Line) | Lines]);
fill([P | Ps], [], _, Lines) -> fill(Ps, [P], string:length(P), Lines);
fill([P | Ps], Line, Len, Lines) ->
    case Len + 1 + string:length(P) > ?COUNTERS_WIDTH of
        true -> fill([P | Ps], [], 0, [lists:reverse(Line) | Lines]);
        false -> fill(Ps, [P | Line], Len + 1 + string:length(P), Lines)
    end.

%% A value on one line, strings as strings, cut at depth `Depth'.
show(V, Depth) -> io_lib:format("~9999tP", [V, Depth]).

duration(Ms) ->
    S = Ms div 1000,
    io_lib:format("~w:~2..0w:~2..0w", [S div 3600, S rem 3600 div 60, S rem 60]).
