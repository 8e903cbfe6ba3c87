%% @doc CBOR (RFC 8949) encoding, pure, for the rosbridge server's `cbor'
%% and `cbor-raw' compressions (`toroco_ros_server_conn'): integers,
%% floats (always 64-bit), `true', `false', `null', other atoms and binaries
%% as text strings, `{bytes, Binary}' as a byte string, lists as arrays,
%% maps (atom or binary keys) as maps.
-module(toroco_ros_cbor).

-export([encode/1]).

-type value() :: integer() | float() | atom() | binary() | {bytes, binary()} | [value()]
               | #{atom() | binary() => value()}.
-export_type([value/0]).

-spec encode(value()) -> binary().
encode(V) -> iolist_to_binary(enc(V)).

enc(N) when is_integer(N), N >= 0 -> head(0, N);
enc(N) when is_integer(N) -> head(1, -1 - N);
enc(F) when is_float(F) -> <<16#fb, F:64/float>>;
enc(false) -> <<16#f4>>;
enc(true) -> <<16#f5>>;
enc(null) -> <<16#f6>>;
enc(A) when is_atom(A) -> enc(atom_to_binary(A, utf8));
enc(B) when is_binary(B) -> [head(3, byte_size(B)), B];
enc({bytes, B}) when is_binary(B) -> [head(2, byte_size(B)), B];
enc(L) when is_list(L) -> [head(4, length(L)) | [enc(X) || X <- L]];
enc(M) when is_map(M) ->
    [head(5, map_size(M)) | [[enc(K), enc(V)] || {K, V} <- lists:sort(maps:to_list(M))]].

head(Major, N) when N < 24 -> <<Major:3, N:5>>;
head(Major, N) when N < 16#100 -> <<Major:3, 24:5, N:8>>;
head(Major, N) when N < 16#10000 -> <<Major:3, 25:5, N:16>>;
head(Major, N) when N < 16#100000000 -> <<Major:3, 26:5, N:32>>;
head(Major, N) -> <<Major:3, 27:5, N:64>>.
