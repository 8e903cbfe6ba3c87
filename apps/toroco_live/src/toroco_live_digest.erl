%% @doc The few digests the dashboard needs, without OpenSSL: SHA-1 (a
%% WebSocket handshake's `Sec-WebSocket-Accept', RFC 6455), SHA-256 and
%% HMAC-SHA-256 (its session cookies, RFC 2104), a comparison whose time
%% does not depend on where two secrets differ, and random bytes from the
%% kernel (`/dev/urandom').
%%
%% Why not `crypto': its NIF maps OpenSSL's `libcrypto', 3.8 MiB of the
%% node's memory counted whole, for a handful of short digests a
%% connection. A node that serves TLS starts `ssl', and with it `crypto',
%% as it needs them (`toroco_live:start/1'); one that does not never maps
%% OpenSSL (doc/benchmarks.md, "Footprint"). These are the algorithms of
%% FIPS 180-4 written out; the suite checks them against its test vectors
%% and against `crypto' on random inputs.
-module(toroco_live_digest).

-export([sha/1, sha256/1, hmac_sha256/2, equal/2, random_bytes/1]).

-define(M32, 16#FFFFFFFF).
-define(ROTL(X, N), ((((X) bsl (N)) band ?M32) bor ((X) bsr (32 - (N))))).
-define(ROTR(X, N), (((X) bsr (N)) bor (((X) bsl (32 - (N))) band ?M32))).

%%====================================================================
%% API
%%====================================================================

%% @doc SHA-1 of `Data' (20 bytes).
-spec sha(iodata()) -> <<_:160>>.
sha(Data) ->
    Blocks = padded(iolist_to_binary(Data)),
    {A, B, C, D, E} = sha_blocks(Blocks, {16#67452301, 16#EFCDAB89, 16#98BADCFE, 16#10325476,
                                          16#C3D2E1F0}),
    <<A:32, B:32, C:32, D:32, E:32>>.

%% @doc SHA-256 of `Data' (32 bytes).
-spec sha256(iodata()) -> <<_:256>>.
sha256(Data) ->
    {H0, K} = sha256_constants(),
    H = sha256_blocks(padded(iolist_to_binary(Data)), H0, K),
    << <<X:32>> || X <- tuple_to_list(H) >>.

%% @doc HMAC-SHA-256 of `Data' under `Key' (RFC 2104; 32 bytes).
-spec hmac_sha256(iodata(), iodata()) -> <<_:256>>.
hmac_sha256(Key0, Data) ->
    Key1 = iolist_to_binary(Key0),
    Key = case byte_size(Key1) > 64 of
              true -> sha256(Key1);
              false -> Key1
          end,
    Block = <<Key/binary, 0:((64 - byte_size(Key)) * 8)>>,
    Inner = sha256([xor_bytes(Block, 16#36), Data]),
    sha256([xor_bytes(Block, 16#5C), Inner]).

%% @doc Whether two binaries are equal, in a time that depends on their
%% sizes only (a secret against what was presented: hash both first when
%% their sizes may differ).
-spec equal(binary(), binary()) -> boolean().
equal(A, B) when byte_size(A) =:= byte_size(B) ->
    diff(A, B, 0) =:= 0;
equal(A, B) when is_binary(A), is_binary(B) ->
    false.

%% @doc `N' random bytes from the kernel's generator (`/dev/urandom'),
%% fit for keys and tokens.
-spec random_bytes(non_neg_integer()) -> binary().
random_bytes(0) ->
    <<>>;
random_bytes(N) ->
    {ok, F} = file:open("/dev/urandom", [read, raw, binary]),
    try
        {ok, Bytes} = file:read(F, N),
        N = byte_size(Bytes),
        Bytes
    after
        ok = file:close(F)
    end.

%%====================================================================
%% Internals
%%====================================================================

%% The message, a 1 bit, zeros and its length in bits: 64-byte blocks.
padded(Bin) ->
    Len = byte_size(Bin),
    Zeros = (55 - Len) band 63,
    <<Bin/binary, 16#80, 0:(Zeros * 8), (Len * 8):64>>.

diff(<<X, RestA/binary>>, <<Y, RestB/binary>>, Acc) ->
    diff(RestA, RestB, Acc bor (X bxor Y));
diff(<<>>, <<>>, Acc) ->
    Acc.

xor_bytes(Bin, Pad) ->
    << <<(X bxor Pad)>> || <<X>> <= Bin >>.

%% A block's message schedule: its 16 words, then the rest by `Extend'
%% (from W[16], the words so far newest first), as a tuple.
schedule(Block, Extend) ->
    list_to_tuple(Extend(16, lists:reverse([X || <<X:32>> <= Block]))).

%% SHA-1 (FIPS 180-4 §6.1)

sha_blocks(<<Block:64/binary, Rest/binary>>, H = {A, B, C, D, E}) ->
    W = schedule(Block, fun sha_extend/2),
    {A1, B1, C1, D1, E1} = sha_rounds(0, W, H),
    sha_blocks(Rest, {(A + A1) band ?M32, (B + B1) band ?M32, (C + C1) band ?M32,
                      (D + D1) band ?M32, (E + E1) band ?M32});
sha_blocks(<<>>, H) ->
    H.

%% W[t] for t = 16..79 from the 16 before it; the list is newest first.
sha_extend(80, Rev) ->
    lists:reverse(Rev);
sha_extend(T, Rev) ->
    W3 = lists:nth(3, Rev), W8 = lists:nth(8, Rev), W14 = lists:nth(14, Rev),
    W16 = lists:nth(16, Rev),
    X = W3 bxor W8 bxor W14 bxor W16,
    sha_extend(T + 1, [?ROTL(X, 1) | Rev]).

sha_rounds(80, _W, H) ->
    H;
sha_rounds(T, W, {A, B, C, D, E}) ->
    {F, K} = if
                 T < 20 -> {(B band C) bor ((bnot B) band ?M32 band D), 16#5A827999};
                 T < 40 -> {B bxor C bxor D, 16#6ED9EBA1};
                 T < 60 -> {(B band C) bor (B band D) bor (C band D), 16#8F1BBCDC};
                 true -> {B bxor C bxor D, 16#CA62C1D6}
             end,
    Tmp = (?ROTL(A, 5) + F + E + K + element(T + 1, W)) band ?M32,
    sha_rounds(T + 1, W, {Tmp, A, ?ROTL(B, 30), C, D}).

%% SHA-256 (FIPS 180-4 §6.2)

sha256_blocks(<<Block:64/binary, Rest/binary>>, H, K) ->
    W = schedule(Block, fun sha256_extend/2),
    H1 = sha256_rounds(0, W, K, H),
    sha256_blocks(Rest, list_to_tuple([(X + Y) band ?M32
                                       || {X, Y} <- lists:zip(tuple_to_list(H),
                                                              tuple_to_list(H1))]), K);
sha256_blocks(<<>>, H, _K) ->
    H.

sha256_extend(64, Rev) ->
    lists:reverse(Rev);
sha256_extend(T, Rev) ->
    W2 = lists:nth(2, Rev), W7 = lists:nth(7, Rev), W15 = lists:nth(15, Rev),
    W16 = lists:nth(16, Rev),
    S0 = ?ROTR(W15, 7) bxor ?ROTR(W15, 18) bxor (W15 bsr 3),
    S1 = ?ROTR(W2, 17) bxor ?ROTR(W2, 19) bxor (W2 bsr 10),
    sha256_extend(T + 1, [(S1 + W7 + S0 + W16) band ?M32 | Rev]).

sha256_rounds(64, _W, _K, H) ->
    H;
sha256_rounds(T, W, K, {A, B, C, D, E, F, G, H}) ->
    S1 = ?ROTR(E, 6) bxor ?ROTR(E, 11) bxor ?ROTR(E, 25),
    Ch = (E band F) bxor ((bnot E) band ?M32 band G),
    T1 = (H + S1 + Ch + element(T + 1, K) + element(T + 1, W)) band ?M32,
    S0 = ?ROTR(A, 2) bxor ?ROTR(A, 13) bxor ?ROTR(A, 22),
    Maj = (A band B) bxor (A band C) bxor (B band C),
    T2 = (S0 + Maj) band ?M32,
    sha256_rounds(T + 1, W, K, {(T1 + T2) band ?M32, A, B, C, (D + T1) band ?M32, E, F, G}).

%% The initial hash value (the fractional parts of the square roots of the
%% first 8 primes) and the round constants (of the cube roots of the first
%% 64 primes), their first 32 bits each (FIPS 180-4 §4.2.2, §5.3.3):
%% computed once, exactly, in integers, and kept.
sha256_constants() ->
    case persistent_term:get(?MODULE, undefined) of
        undefined ->
            Primes = primes(64),
            H0 = list_to_tuple([iroot(P bsl 64, 2) band ?M32 || P <- lists:sublist(Primes, 8)]),
            K = list_to_tuple([iroot(P bsl 96, 3) band ?M32 || P <- Primes]),
            persistent_term:put(?MODULE, {H0, K}),
            {H0, K};
        Constants ->
            Constants
    end.

primes(N) ->
    primes(2, N, []).

primes(_, 0, Acc) ->
    lists:reverse(Acc);
primes(X, N, Acc) ->
    case lists:any(fun(P) -> X rem P =:= 0 end, Acc) of
        true -> primes(X + 1, N, Acc);
        false -> primes(X + 1, N - 1, [X | Acc])
    end.

%% The integer K-th root of N (the largest R with R^K =< N), by Newton's
%% method from above.
iroot(N, K) ->
    iroot(N, K, 1 bsl (bit_length(N) div K + 1)).

iroot(N, K, X) ->
    Y = ((K - 1) * X + N div pow(X, K - 1)) div K,
    case Y >= X of
        true -> X;
        false -> iroot(N, K, Y)
    end.

pow(X, 1) -> X;
pow(X, K) -> X * pow(X, K - 1).

bit_length(0) -> 0;
bit_length(N) -> 1 + bit_length(N bsr 1).
