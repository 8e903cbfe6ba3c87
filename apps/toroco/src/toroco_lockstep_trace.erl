%% @doc The lockstep trace's lines (SPEC §14, §17): one canonical line per
%% step, with its simulated time (and its node in a world of several),
%% naming no pid, so that two runs of the same world can be compared
%% byte for byte.
-module(toroco_lockstep_trace).

-include("toroco_wire.hrl").
-include("toroco_lockstep.hrl").

-export([trace/4, note/2, term/1, reason/1, pname/1]).

-spec trace(term(), pid() | undefined | remote, term(), #s{}) -> #s{}.
trace(_To, _Pid, _Msg, S = #s{trace = off}) ->
    S;
trace(To, Pid, Msg, S = #s{trace = Lines, now = Now, world = none}) ->
    %% as io_lib:format("~b ~ts ~ts~n") would write it, without its cost
    %% (a run's steps are most of the lab's work)
    S#s{trace = [[integer_to_list(Now), $\s, name(To, Pid), $\s, line(Msg), $\n] | Lines]};
trace(To, Pid, Msg, S = #s{trace = Lines, now = Now}) ->
    Node = toroco_lockstep_nodes:node_of(case Pid of
                                             _ when is_pid(Pid) -> Pid;
                                             _ -> To
                                         end),
    S#s{trace = [[integer_to_list(Now), $\s, text(Node), $\s, name(To, Pid), $\s, line(Msg), $\n]
                 | Lines]}.

name({Reg, _Node}, _Pid) -> atom_to_list(Reg);
name(Reg, _Pid) when is_atom(Reg) -> atom_to_list(Reg);
name(_To, Pid) when is_pid(Pid), node(Pid) =/= node() ->
    pname(Pid);
name(_To, Pid) when is_pid(Pid) ->
    case erlang:process_info(Pid, registered_name) of
        {registered_name, Reg} -> atom_to_list(Reg);
        _ -> "-"
    end;
name(_To, _) ->
    "-".

line(?WIRE_EVENT({E, O}, Op)) -> ["emit ", text(E), $., text(O), $\s, op(Op)];
line(?WIRE_GATED({E, O}, Op)) -> ["gated ", text(E), $., text(O), $\s, op(Op)];
line(?WIRE_IN(I, V)) -> ["deliver ", text(I), $\s, term(V)];
line(?WIRE_IN(I, V, _)) -> ["deliver ", text(I), $\s, term(V)];
line(?WIRE_ACK(I)) -> ["ack ", text(I)];
line(?WIRE_ALIVE(_, {E, O}, _)) -> ["alive ", text(E), $., text(O)];
%% a link timer (toroco_clock:link_timer/3) shows as the timer it is
line(?WIRE_TIMER(Kind, {'$toroco_link', Msg})) -> ["timer ", term(Kind), $\s, term(Msg)];
line(?WIRE_TIMER(Kind, Msg)) -> ["timer ", term(Kind), $\s, term(Msg)];
line({stimulus, Msg}) -> ["stimulus ", term(Msg)];
line({notice, _, Shown}) -> ["notice ", term(strip(Shown))];
line({exit, Reason}) -> ["fault exit ", term(strip(Reason))];
line({'DOWN', _, process, _, Reason}) -> ["down ", reason(Reason)];
line(Msg) -> term(strip(Msg)).

op({send, V, Hold}) -> ["send ", term(V), $\s, term(Hold)];
op({set, V}) -> ["set ", term(V)];
op(unset) -> "unset".

%% `~s' of a name
text(A) when is_atom(A) -> atom_to_list(A);
text(T) -> io_lib:format("~s", [T]).

%% @private `~0tp' of a term, the common cases (integers, atoms, tuples
%% of them) written directly: the same characters (toroco_lockstep_SUITE
%% checks).
-spec term(term()) -> iolist().
term(T) when is_integer(T) -> integer_to_list(T);
term(T) when is_atom(T) -> atom(T);
term({}) -> "{}";
term(T) when is_tuple(T) -> [${, lists:join($,, [term(E) || E <- tuple_to_list(T)]), $}];
term(T) -> io_lib:format("~0tp", [T]).

%% An atom as ~0tp writes it (quoted where it must be), remembered: a run
%% names the same few atoms thousands of times, and deciding on the
%% quotes is most of writing one.
atom(A) ->
    case get({?MODULE, A}) of
        undefined ->
            Text = io_lib:write_atom(A),
            _ = length(get()) < 4096 andalso put({?MODULE, A}, Text),
            Text;
        Text ->
            Text
    end.

%% Pids are not the same from one run to the next: a line names none.
strip(T) when is_pid(T) -> pid;
strip(T) when is_reference(T) -> ref;
strip(T) when is_tuple(T) -> list_to_tuple([strip(E) || E <- tuple_to_list(T)]);
strip(T) when is_list(T) -> [strip(E) || E <- T];
strip(T) -> T.

%% An exit's reason as the trace shows it: no pids, no stack.
-spec reason(term()) -> iolist().
reason({Reason, Stack}) when is_list(Stack), Stack =/= [], is_tuple(hd(Stack)),
                             tuple_size(hd(Stack)) =:= 4 ->
    reason(Reason);
reason(Reason) ->
    io_lib:format("~0tp", [strip(Reason)]).

-spec note(iodata(), #s{}) -> #s{}.
note(_Line, S = #s{trace = off}) ->
    S;
note(Line, S = #s{trace = Lines, now = Now, world = none}) ->
    S#s{trace = [io_lib:format("~b ~ts~n", [Now, Line]) | Lines]};
note(Line, S = #s{trace = Lines, now = Now}) ->
    S#s{trace = [io_lib:format("~b ~s ~ts~n", [Now, node(), Line]) | Lines]}.

-spec pname(pid()) -> string().
pname(Pid) when node(Pid) =/= node() ->
    toroco_lockstep_nodes:regname(Pid);
pname(Pid) ->
    case erlang:process_info(Pid, registered_name) of
        {registered_name, Reg} -> atom_to_list(Reg);
        _ -> "~"
    end.
