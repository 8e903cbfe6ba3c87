%% @doc Looking inside a running network: the maps of `toroco:inspect/0,1',
%% the `toroco:top/0' table and the `toroco:wiring_dot/0' graph.
%%
%% Everything here runs in the caller's process: it asks the wiring server for
%% the wiring (data only) and asks routers, gates and emitters for their state
%% directly, so inspecting never holds up the wiring server.
-module(toroco_inspect).

-export([overview/0, node/1, top/0, top_iodata/0, dot/0]).
-compile({no_auto_import, [node/1]}).

%%====================================================================
%% inspect/0,1
%%====================================================================

-spec overview() -> #{behaviors := [atom()], devices := [atom()],
                      layers := #{non_neg_integer() => [atom()]},
                      removed_layers := [non_neg_integer()]}.
overview() ->
    {W, Removed} = toroco_wiring:call(wiring),
    Nodes = lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
    Behaviors = [{N, L} || {N, #{kind := behavior, layer := L}} <- Nodes],
    #{behaviors => [N || {N, _} <- Behaviors],
      devices => [N || {N, #{kind := device}} <- Nodes],
      layers => lists:foldl(fun({N, L}, Acc) ->
                                    maps:update_with(L, fun(Ns) -> Ns ++ [N] end, [N], Acc)
                            end, #{}, Behaviors),
      removed_layers => Removed}.

-spec node(atom()) -> map() | {error, term()}.
node(Name) ->
    case toroco_wiring:call({node, Name}) of
        {ok, Info} -> describe(Name, Info);
        Err -> Err
    end.

describe(Name, #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs,
                 inputs_wired := Wired, inhibitors := Inhs, gates := Gates}) ->
    Engine = case toroco_behavior:info(Name) of
                 #{} = I -> I;
                 {error, _} -> #{status => down, latches => #{}}
             end,
    Latches = maps:get(latches, Engine),
    Base = #{name => Name, kind => Kind, module => M, layer => L,
             status => maps:get(status, Engine),
             inputs => maps:from_list([{I, input(Name, I, Wired)} || I <- Ins]),
             outputs => maps:from_list(
                          [{O, output(Name, O, maps:get(O, Inhs, []), Gates, Latches)}
                           || O <- Outs])},
    B1 = case Wired of
             #{'$reset' := #{sources := Srcs}} -> Base#{reset => [S || {S, _} <- Srcs]};
             #{} -> Base
         end,
    case Engine of
        #{device := Counters} -> B1#{device => Counters};
        #{} -> B1
    end.

input(Name, I, Wired) ->
    case Wired of
        #{I := #{sources := Srcs, buffer := B}} ->
            case toroco_router:info({Name, I}) of
                #{} = Info -> maps:with([sources, winner, holds, latches, last, buffer], Info);
                none -> #{sources => [S || {S, _} <- Srcs], winner => none, holds => [],
                          latches => [], last => none, buffer => B}
            end;
        #{} ->
            #{sources => [], winner => none, holds => [], latches => [], last => none}
    end.

output(Name, O, Inhibitors, Gates, Latches) ->
    {Inhibited, Holds} = case Gates of
                             #{{Name, O} := Key} ->
                                 case toroco_gate:info(Key) of
                                     #{{Name, O} := #{inhibited := I, holds := H}} -> {I, H};
                                     _ -> {false, []}
                                 end;
                             #{} -> {false, []}
                         end,
    #{inhibited => Inhibited, inhibitors => [S || {S, _} <- Inhibitors],
      inhibitor_holds => Holds,
      latch => case Latches of
                   #{O := V} -> {value, V};
                   #{} -> none
               end}.

%%====================================================================
%% top/0
%%====================================================================

%% Cells longer than this are cut (the last column of a table is not).
-define(CELL, 40).
%% Depth to which values are printed.
-define(DEPTH, 8).
%% Device counters wrap at this width.
-define(COUNTERS_WIDTH, 90).
%% How long top waits for a busy behavior to tell its state.
-define(STATE_TIMEOUT, 500).

%% @doc Prints {@link top_iodata/0} to the caller's group leader.
-spec top() -> ok.
top() ->
    io:put_chars(top_iodata()).

%% @doc The `top/0' table as text: the layers, then one row per behavior
%% and device (highest layer first, devices last) with its status, the
%% state of its callback module, its message queue and its restarts (see
%% `toroco_restarts'); then every wired input with its winner, holds (ms
%% left), latched values and last value delivered; the inhibited outputs;
%% and the devices' own counters.
-spec top_iodata() -> iodata().
top_iodata() ->
    _ = toroco_restarts:install(),
    #{behaviors := Bs, devices := Ds, layers := Layers, removed_layers := Removed} = overview(),
    Nodes = [row(N) || N <- Bs ++ Ds],
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
                    end, "\n\n",
     table(["NODE", "KIND", "LAYER", "STATUS", "STATE", "QUEUE", "RESTARTS", "MODULE"],
           [[atom_to_list(N), atom_to_list(K), text(L), atom_to_list(St), value(S),
             text(Q), text(R), atom_to_list(M)]
            || #{name := N, kind := K, layer := L, status := St, state := S, queue := Q,
                 restarts := R, module := M} <- Sorted]),
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

row(N) ->
    Info = case node(N) of
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

%%====================================================================
%% wiring_dot/0
%%====================================================================

%% @doc The wiring as a Graphviz `dot' graph, drawn as Brooks drew his
%% networks: each behavior a box with its inputs on the left, its outputs on
%% the right and its layer under its name; devices in grey with rounded
%% corners. Wires run left to right, from sensors to actuators (a column per
%% layer would stretch the picture without saying more than the labels). A
%% wire from an output to the one input it feeds is a plain arrow. Where an
%% input has several sources, their wires meet in a blue suppressor node `S'
%% whose incoming wires are numbered by priority (1 = highest; a wiring
%% entry's hold is added, `h 500'). An inhibited output goes through a red
%% inhibitor node `I' before it reaches anything, and each inhibitor's wire
%% into it is dashed red with a flat end. A reset wire is dotted and ends on
%% the behavior's name. `toroco_ops:wiring_svg/1' renders it.
-spec dot() -> iodata().
dot() ->
    {W, _} = toroco_wiring:call(wiring),
    Nodes = lists:sort(maps:to_list(toroco_wiring_core:nodes(W))),
    Inhibited = [{{E, O}, Inhs} || {E, #{outputs := Outs}} <- Nodes, O <- Outs,
                                   Inhs <- [toroco_wiring_core:inhibitors_of(W, {E, O})],
                                   Inhs =/= []],
    Inputs = [{{R, I}, Spec} || {R, _} <- Nodes,
                                {I, Spec} <- lists:sort(maps:to_list(
                                                          toroco_wiring_core:inputs_of(W, R)))],
    %% Where the wire of an output starts: its port, or its inhibitor node.
    From = fun(Src) -> case lists:keymember(Src, 1, Inhibited) of
                           true -> [id("I", Src)];
                           false -> [out_port(Src)]
                       end end,
    ["digraph toroco {\n"
     "  rankdir=LR; nodesep=0.25; ranksep=0.4;\n"
     "  node [fontname=\"Helvetica\", fontsize=10];\n"
     "  edge [fontname=\"Helvetica\", fontsize=9, arrowsize=0.7];\n",
     [["  ", box(N, Info), "\n"] || {N, Info} <- Nodes],
     %% Inhibitor nodes on the outputs they inhibit.
     [[io_lib:format("  ~s [shape=circle, label=\"I\", width=0.25, fixedsize=true, "
                     "color=red3, fontcolor=red3];~n", [id("I", Src)]),
       io_lib:format("  ~s -> ~s [arrowhead=none, color=red3];~n", [out_port(Src), id("I", Src)]),
       [io_lib:format("  ~s -> ~s [style=dashed, color=red3, arrowhead=tee~s];~n",
                      [F, id("I", Src), case H of
                                            0 -> "";
                                            _ -> [", label=\"", hold(H), "\""]
                                        end])
        || {Inh, H} <- Inhs, F <- From(Inh)]]
      || {Src, Inhs} <- Inhibited],
     %% Inputs: one source is a plain wire, several meet in a suppressor.
     [case Srcs of
          [{S, H}] ->
              [io_lib:format("  ~s -> ~s~s;~n", [F, to(R, I), case H of
                                                                 0 -> "";
                                                                 _ -> [" [label=\"", hold(H), "\"]"]
                                                             end])
               || F <- From(S)];
          _ ->
              [io_lib:format("  ~s [shape=circle, label=\"S\", width=0.25, fixedsize=true, "
                             "color=blue3, fontcolor=blue3];~n", [id("S", {R, I})]),
               io_lib:format("  ~s -> ~s [color=blue3];~n", [id("S", {R, I}), to(R, I)]),
               [io_lib:format("  ~s -> ~s [color=blue3, label=\"~w~s\"];~n",
                              [F, id("S", {R, I}), P, case H of
                                                          0 -> "";
                                                          _ -> [" ", hold(H)]
                                                      end])
                || {P, {S, H}} <- lists:zip(lists:seq(1, length(Srcs)), Srcs), F <- From(S)]]
      end
      || {{R, I}, #{sources := Srcs}} <- Inputs, Srcs =/= []],
     "}\n"].

%% A behavior or device as an HTML-like table: inputs left, outputs right.
box(N, #{kind := Kind, module := M, layer := L, inputs := Ins, outputs := Outs}) ->
    Rows = max(1, max(length(Ins), length(Outs))),
    Cell = fun(Dir, Ps, K) ->
                   case lists:nth(K, Ps ++ lists:duplicate(Rows, none)) of
                       none -> "<TD BORDER=\"0\"></TD>";
                       P -> io_lib:format("<TD PORT=\"~s\" ALIGN=\"~s\">~ts</TD>",
                                          [port_id(Dir, P), case Dir of
                                                                in -> "LEFT";
                                                                out -> "RIGHT"
                                                            end, html(P)])
                   end
           end,
    Sub = case Kind of
              behavior -> io_lib:format("layer ~w &middot; ~ts", [L, html(M)]);
              device -> html(M)
          end,
    Name = io_lib:format("<TD ROWSPAN=\"~w\" PORT=\"name\"><B>~ts</B><BR/>"
                         "<FONT POINT-SIZE=\"8\">~ts</FONT></TD>", [Rows, html(N), Sub]),
    Body = [["<TR>", Cell(in, Ins, K), case K of 1 -> Name; _ -> "" end, Cell(out, Outs, K), "</TR>"]
            || K <- lists:seq(1, Rows)],
    Style = case Kind of
                device -> " style=\"rounded\" bgcolor=\"grey92\"";
                behavior -> ""
            end,
    io_lib:format("~s [shape=plaintext, label=<<TABLE BORDER=\"1\" CELLBORDER=\"0\" "
                  "CELLSPACING=\"0\" CELLPADDING=\"3\"~s>~s</TABLE>>];",
                  [quote(N), Style, Body]).

to(R, '$reset') -> [quote(R), ":name:n [style=dotted, label=\"reset\"]"];
to(R, I) -> in_port({R, I}).

%% A wiring entry's hold, as the edge label shows it.
hold(infinity) -> "h inf";
hold(H) -> ["h ", integer_to_list(H)].

out_port({N, P}) -> [quote(N), ":", port_id(out, P), ":e"].
in_port({N, P}) -> [quote(N), ":", port_id(in, P), ":w"].

port_id(Dir, P) -> io_lib:format("~s_~s", [Dir, word(P)]).

id(Kind, {N, P}) -> [$", escape(lists:flatten(io_lib:format("~s:~w/~w", [Kind, N, P]))), $"].

quote(N) -> [$", escape(atom_to_list(N)), $"].

escape(S) -> lists:flatmap(fun($") -> "\\\""; ($\\) -> "\\\\"; (C) -> [C] end, S).

%% Port names must be plain words; atoms need not be, and are then written
%% in hex.
word(A) ->
    S = atom_to_list(A),
    case re:run(S, "^[A-Za-z_][A-Za-z0-9_]*$", [{capture, none}]) of
        match -> S;
        nomatch -> ["x", binary:encode_hex(atom_to_binary(A))]
    end.

html(A) when is_atom(A) ->
    lists:flatmap(fun($<) -> "&lt;"; ($>) -> "&gt;"; ($&) -> "&amp;"; ($") -> "&quot;"; (C) -> [C] end,
                  atom_to_list(A)).
