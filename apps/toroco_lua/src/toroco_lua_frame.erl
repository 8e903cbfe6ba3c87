%% @doc The frames between `toroco_lua_port' and the `lua_port' program
%% (`c_src/lua_port/PROTOCOL.md'), as pure functions: a request's frame and
%% whether a value can cross, the frames cut from the bytes read, an
%% answer's ref read from its first bytes, an answer decoded, and what its
%% caller gets.
%%
%% Functions: `frame/3', `crossable/1', `cut/1', `ref/1', `decode/1',
%% `result/4'.
-module(toroco_lua_frame).

-export([frame/3, crossable/1, cut/1, ref/1, decode/1, result/4]).

-define(FRAME_MAX, 1 bsl 20).                  % PROTOCOL.md
-define(DEPTH_MAX, 32).

%% @doc The frame of a request to state `Id' with ref `Ref', or
%% `{error, {bad_value, Id}}' for an input value the program cannot read
%% ({@link crossable/1}) or a frame over the protocol's bound.
-spec frame(toroco_lua_port:request(), toroco_lua_port:ref(), toroco_lua_port:id()) ->
          {ok, binary()} | {error, {bad_value, toroco_lua_port:id()}}.
frame({input, Now, Input, Value}, Ref, Id) ->
    case crossable(Value) of
        true -> sized(term_to_binary({input, Ref, Id, Now, Input, Value}), Id);
        false -> {error, {bad_value, Id}}
    end;
frame({timer, Now, Task, Seq}, Ref, Id) -> {ok, term_to_binary({timer, Ref, Id, Now, Task, Seq})};
frame(waits, Ref, Id) -> {ok, term_to_binary({waits, Ref, Id})};
frame(memory, Ref, Id) -> {ok, term_to_binary({memory, Ref, Id})}.

sized(Frame, Id) when byte_size(Frame) > ?FRAME_MAX -> {error, {bad_value, Id}};
sized(Frame, _Id) -> {ok, Frame}.

%% @doc Whether the program can read `Value' (PROTOCOL.md): numbers (whole
%% ones of up to 64 bits), atoms, binaries, proper lists, tuples and maps,
%% nested at most 31 deep inside a frame. Anything else would be a frame the
%% program cannot read, answered with no ref to route it by.
-spec crossable(term()) -> boolean().
crossable(Value) ->
    crossable(Value, 1).

crossable(_, D) when D > ?DEPTH_MAX -> false;
crossable(V, _) when is_integer(V) -> V > -(1 bsl 64) andalso V < 1 bsl 64;
crossable(V, _) when is_float(V); is_atom(V); is_binary(V) -> true;
crossable(V, D) when is_list(V) -> list_crossable(V, D + 1);
crossable(V, D) when is_tuple(V) -> list_crossable(tuple_to_list(V), D + 1);
crossable(V, D) when is_map(V) ->
    list_crossable(maps:keys(V), D + 1) andalso list_crossable(maps:values(V), D + 1);
crossable(_, _) -> false.

list_crossable([], _D) -> true;
list_crossable([H | T], D) -> crossable(H, D) andalso list_crossable(T, D);
list_crossable(_Improper, _D) -> false.

%% @doc The whole frames in the bytes read (each after its 4-byte length),
%% and what is left of the next one.
-spec cut(binary()) -> {[binary()], binary()}.
cut(Bytes) ->
    cut(Bytes, []).

cut(<<Len:32, Frame:Len/binary, Rest/binary>>, Acc) -> cut(Rest, [Frame | Acc]);
cut(Rest, Acc) -> {lists:reverse(Acc), binary:copy(Rest)}.

%% @doc The ref of an answer `{reply, Ref, _}', read from its first bytes as the
%% program writes them (ei: version, small tuple, the atom, an integer of
%% one byte, four, or a small big); an answer written otherwise (an ei that
%% encodes atoms another way) is decoded whole; anything else is not a
%% state's answer.
-spec ref(binary()) -> integer() | none.
ref(<<131, 104, 3, 119, 5, "reply", Int/binary>>) ->
    case Int of
        <<97, Ref, _/binary>> -> Ref;
        <<98, Ref:32/signed, _/binary>> -> Ref;
        <<110, N, 0, Ref:N/little-unit:8, _/binary>> -> Ref;
        _ -> none
    end;
ref(Bin) ->
    case decode(Bin) of
        {reply, Ref, _} when is_integer(Ref) -> Ref;
        _ -> none
    end.

%% @doc A frame of the program as a term, or `{undecodable, Bin}'. The
%% program's atoms are all known here, so nothing it sends makes atoms.
-spec decode(binary()) -> term().
decode(Bin) ->
    try binary_to_term(Bin, [safe])
    catch error:badarg -> {undecodable, Bin}
    end.

%% @doc What the caller of request `Req' (ref `Ref') gets for the program's
%% answer: an opened or attached state's id and port with its actions, the
%% result, or an error naming what came instead.
-spec result(term(), toroco_lua_port:ref(), term(), port()) -> term().
result({reply, Ref, {ok, Actions}}, Ref, {open, Id, _, _, _, _, _, _}, Port) ->
    {ok, Id, Port, Actions};
result({reply, Ref, {ok, Actions}}, Ref, {attach, Id, _, _, _}, Port) ->
    {ok, Id, Port, Actions};
result({reply, Ref, Result}, Ref, _Req, _Port) -> Result;
result({reply, _, Result}, _Ref, raw, _Port) -> Result;
result({bad_frame, Why}, _Ref, raw, _Port) -> {bad_frame, Why};
result({bad_frame, Why}, _Ref, _Req, _Port) -> {error, {bad_frame, Why}};
result(Other, _Ref, _Req, _Port) -> {error, {lua_port_answer, Other}}.
