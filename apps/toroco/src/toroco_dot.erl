%% @doc The wiring picture of `toroco:wiring_dot/0': the network's wiring
%% as a Graphviz `dot' graph, which `toroco_ops:wiring_svg/1' renders. It
%% reads the wiring from the wiring server (data only) and nothing else, so
%% the picture shows how the network is wired, not what it is doing.
%%
%% The graph is drawn as Brooks drew his networks: each behavior a box with
%% its inputs on the left, its outputs on the right and its layer under its
%% name; devices in grey with rounded corners. Wires run left to right, from
%% sensors to actuators (a column per layer would stretch the picture without
%% saying more than the labels). A wire from an output to the one input it
%% feeds is a plain arrow. Where an input has several sources, their wires
%% meet in a blue suppressor node `S' whose incoming wires are numbered by
%% priority (1 = highest; a wiring entry's hold is added, `h 500'). An
%% inhibited output goes through a red inhibitor node `I' before it reaches
%% anything, and each inhibitor's wire into it is dashed red with a flat end.
%% A reset wire is dotted and ends on the behavior's name.
-module(toroco_dot).

-export([wiring/0]).

%% @doc The current wiring as `dot' text.
-spec wiring() -> iodata().
wiring() ->
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
