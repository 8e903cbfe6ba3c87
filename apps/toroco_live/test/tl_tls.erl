%% What the TLS cases share: a test certificate authority made with
%% openssl in a case's directory, a server certificate it signed for
%% 127.0.0.1 and localhost, and a stranger (a self-signed certificate for
%% the same names that no one trusts), with what clients pin: the
%% certificates' SHA-256 fingerprints and the CA's key hash (chromium's
%% `--ignore-certificate-errors-spki-list').
-module(tl_tls).
-export([make/1, tls/1, stranger_tls/1, chromium_args/1]).

%% #{ca, cert, key, stranger_cert, stranger_key, fingerprint,
%%   stranger_fingerprint, ca_spki} under Dir.
make(Dir0) ->
    %% A directory of its own each time: suites run from one directory share
    %% their priv_dir, and ssl caches a PEM file by its name.
    Dir = filename:join(Dir0, "tls_" ++ integer_to_list(erlang:unique_integer([positive]))),
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    F = fun(N) -> filename:join(Dir, N) end,
    run(["openssl req -x509 -newkey rsa:2048 -nodes -keyout ", F("ca.key"), " -out ", F("ca.pem"),
         " -days 2 -subj '/CN=toroco test CA' -addext basicConstraints=critical,CA:TRUE"
         " -addext keyUsage=critical,keyCertSign,cRLSign"]),
    run(["openssl req -new -newkey rsa:2048 -nodes -keyout ", F("key.pem"), " -out ", F("csr.pem"),
         " -subj '/CN=127.0.0.1'"]),
    ok = file:write_file(F("ext.cnf"), "subjectAltName=IP:127.0.0.1,DNS:localhost\n"
                                       "extendedKeyUsage=serverAuth\n"
                                       "basicConstraints=critical,CA:FALSE\n"),
    run(["openssl x509 -req -in ", F("csr.pem"), " -CA ", F("ca.pem"), " -CAkey ", F("ca.key"),
         " -CAcreateserial -out ", F("cert.pem"), " -days 2 -extfile ", F("ext.cnf")]),
    run(["openssl req -x509 -newkey rsa:2048 -nodes -keyout ", F("stranger.key"), " -out ",
         F("stranger.pem"), " -days 2 -subj '/CN=127.0.0.1'"
         " -addext subjectAltName=IP:127.0.0.1,DNS:localhost"]),
    Spki = string:trim(os:cmd("openssl x509 -in " ++ F("ca.pem") ++ " -pubkey -noout | "
                              "openssl pkey -pubin -outform der | "
                              "openssl dgst -sha256 -binary | base64")),
    #{ca => F("ca.pem"), cert => F("cert.pem"), key => F("key.pem"),
      stranger_cert => F("stranger.pem"), stranger_key => F("stranger.key"),
      fingerprint => fingerprint(F("cert.pem")),
      stranger_fingerprint => fingerprint(F("stranger.pem")), ca_spki => Spki}.

%% The `tls' option of toroco_live:start/1 with the CA's server certificate
%% (the chain sent with it).
tls(#{cert := C, key := K, ca := Ca}) ->
    #{certfile => C, keyfile => K, cacertfile => Ca}.

%% A server no client of the test CA trusts.
stranger_tls(#{stranger_cert := C, stranger_key := K}) ->
    #{certfile => C, keyfile => K}.

%% chromium trusting the test CA (a profile of its own, which puppeteer gives).
chromium_args(#{ca_spki := Spki}) ->
    ["--ignore-certificate-errors-spki-list=" ++ Spki].

%% The SHA-256 of a PEM certificate's DER, as openssl prints it (AB:CD:...).
fingerprint(Pem) ->
    {ok, Bin} = file:read_file(Pem),
    [{'Certificate', Der, _} | _] = public_key:pem_decode(Bin),
    lists:flatten(lists:join(":", [io_lib:format("~2.16.0B", [B])
                                   || <<B>> <= crypto:hash(sha256, Der)])).

run(Cmd) ->
    Out = os:cmd(lists:flatten([Cmd, " 2>&1; echo \"exit=$?\""])),
    case string:find(Out, "exit=0") of
        nomatch -> error({openssl, lists:flatten(Cmd), Out});
        _ -> ok
    end.
