%% @doc ROS 2's CDR serialization (XCDR1, little endian: the encapsulation
%% header `00 01 00 00'), pure, of the messages `toroco_live_ros' makes,
%% by their fields (`toroco_live_ros:fields/1'): each primitive aligned to
%% its size from the start of the data, strings as a 32-bit length (with
%% the terminating NUL) and the bytes, fixed arrays element after element.
%% The rosbridge server sends these bytes for the `cbor-raw' compression,
%% which Foxglove's Rosbridge connection asks for.
-module(toroco_live_cdr).

-export([encode/2]).

-spec encode(binary(), toroco_live_ros:message()) -> binary().
encode(Type, Msg) ->
    {Data, _} = struct(Type, Msg, {[], 0}),
    iolist_to_binary([<<0, 1, 0, 0>> | lists:reverse(Data)]).

struct(Type, Msg, Acc) ->
    lists:foldl(fun({Name, FT}, A) -> field(FT, maps:get(Name, Msg), A) end,
                Acc, toroco_live_ros:fields(Type)).

field(float64, V, A) -> put(8, <<(float(V)):64/float-little>>, A);
field(float32, V, A) -> put(4, <<(float(V)):32/float-little>>, A);
field(int32, V, A) -> put(4, <<V:32/signed-little>>, A);
field(uint32, V, A) -> put(4, <<V:32/unsigned-little>>, A);
field(uint8, V, A) -> put(1, <<V:8>>, A);
field(string, V, A) ->
    {Data, Off} = put(4, <<(byte_size(V) + 1):32/little>>, A),
    {[<<V/binary, 0>> | Data], Off + byte_size(V) + 1};
field({array, E, _N}, L, A) -> lists:foldl(fun(X, Acc) -> field(E, X, Acc) end, A, L);
field(Type, V, A) when is_binary(Type) -> struct(Type, V, A).

%% Padding up to a multiple of Align, then Bin.
put(Align, Bin, {Data, Off}) ->
    Pad = (Align - Off rem Align) rem Align,
    {[Bin, <<0:(Pad * 8)>> | Data], Off + Pad + byte_size(Bin)}.
