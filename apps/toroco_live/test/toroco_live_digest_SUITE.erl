%% The dashboard's digests without OpenSSL (`toroco_live_digest'): the
%% standards' own test vectors, then agreement with `crypto' (which the
%% tests may load) on random inputs of every length around the block
%% boundaries, and the comparison and random bytes the tokens rely on.
-module(toroco_live_digest_SUITE).
-include_lib("common_test/include/ct.hrl").
-include_lib("proper/include/proper.hrl").
-compile([export_all, nowarn_export_all]).

all() -> [standard_vectors, websocket_accept_key, agrees_with_crypto, equal_is_exact,
          random_bytes_are_fresh].

suite() -> [{timetrap, {minutes, 2}}].

-define(D, toroco_live_digest).

standard_vectors() ->
    [{doc, "SHA-1 and SHA-256 of FIPS 180-4's examples (empty, \"abc\", the 448-bit message, "
      "a million a's); HMAC-SHA-256 of RFC 4231's test cases 1, 2 and 6 (a key longer than "
      "a block)"}].
standard_vectors(_Config) ->
    Long = <<"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq">>,
    Million = binary:copy(<<"a">>, 1000000),
    <<"da39a3ee5e6b4b0d3255bfef95601890afd80709">> = hex(?D:sha(<<>>)),
    <<"a9993e364706816aba3e25717850c26c9cd0d89d">> = hex(?D:sha(<<"abc">>)),
    <<"84983e441c3bd26ebaae4aa1f95129e5e54670f1">> = hex(?D:sha(Long)),
    <<"34aa973cd4c4daa4f61eeb2bdbad27316534016f">> = hex(?D:sha(Million)),
    <<"e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855">> = hex(?D:sha256(<<>>)),
    <<"ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad">> =
        hex(?D:sha256(<<"abc">>)),
    <<"248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1">> = hex(?D:sha256(Long)),
    <<"cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0">> =
        hex(?D:sha256(Million)),
    <<"b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7">> =
        hex(?D:hmac_sha256(binary:copy(<<16#0b>>, 20), <<"Hi There">>)),
    <<"5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843">> =
        hex(?D:hmac_sha256(<<"Jefe">>, <<"what do ya want for nothing?">>)),
    <<"60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54">> =
        hex(?D:hmac_sha256(binary:copy(<<16#aa>>, 131),
                           <<"Test Using Larger Than Block-Size Key - Hash Key First">>)).

websocket_accept_key() ->
    [{doc, "RFC 6455's handshake example: the key dGhlIHNhbXBsZSBub25jZQ== is answered "
      "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="}].
websocket_accept_key(_Config) ->
    <<"s3pPLMBiTxaQ9kYGzzhZRbK+xOo=">> =
        toroco_live_ws_frame:accept_key(<<"dGhlIHNhbXBsZSBub25jZQ==">>).

agrees_with_crypto() ->
    [{doc, "On random data of 0 to 300 bytes (every padding case) and random keys of 0 to "
      "200 bytes, SHA-1, SHA-256 and HMAC-SHA-256 are OpenSSL's"}].
agrees_with_crypto(_Config) ->
    true = proper:quickcheck(
             ?FORALL({Data, Key}, {sized_binary(300), sized_binary(200)},
                     ?D:sha(Data) =:= crypto:hash(sha, Data)
                     andalso ?D:sha256(Data) =:= crypto:hash(sha256, Data)
                     andalso ?D:hmac_sha256(Key, Data) =:= crypto:mac(hmac, sha256, Key, Data)),
             [{numtests, 500}, {to_file, user}]),
    %% and every length across the first blocks, not left to chance
    [] = [N || N <- lists:seq(0, 200), B <- [crypto:strong_rand_bytes(N)],
               ?D:sha256(B) =/= crypto:hash(sha256, B) orelse ?D:sha(B) =/= crypto:hash(sha, B)].

equal_is_exact() ->
    [{doc, "equal/2: true only for the same bytes; a different size or any one bit "
      "different is false"}].
equal_is_exact(_Config) ->
    true = ?D:equal(<<>>, <<>>),
    true = ?D:equal(<<"secret">>, <<"secret">>),
    false = ?D:equal(<<"secret">>, <<"secre">>),
    false = ?D:equal(<<"secret">>, <<"secret!">>),
    S = crypto:strong_rand_bytes(32),
    [] = [I || I <- lists:seq(0, 255),
               ?D:equal(S, flip(S, I))].

random_bytes_are_fresh() ->
    [{doc, "random_bytes/1 gives the size asked for, and 1,000 draws of 16 bytes are all "
      "different"}].
random_bytes_are_fresh(_Config) ->
    <<>> = ?D:random_bytes(0),
    32 = byte_size(?D:random_bytes(32)),
    Draws = [?D:random_bytes(16) || _ <- lists:seq(1, 1000)],
    1000 = length(lists:usort(Draws)).

%%====================================================================
%% Helpers
%%====================================================================

sized_binary(Max) ->
    ?LET(N, choose(0, Max), binary(N)).

flip(Bin, I) ->
    <<Before:I, B:1, After/bitstring>> = Bin,
    <<Before:I, (1 - B):1, After/bitstring>>.

hex(Bin) ->
    string:lowercase(binary:encode_hex(Bin)).
