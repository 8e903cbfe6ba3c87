%% @doc (API) A listening port of `toroco_live' that strangers can reach (the
%% dashboard's HTTP/WebSocket port, the Foxglove bridge's), bounded: this
%% process, the port's guard, owns mochiweb's listener and keeps the slots
%% of its connections (`toroco_slots', the pure core shared with
%% `toroco_tcp_link').
%%
%% mochiweb accepts and runs each connection in its own process, but it
%% gives no hook between accept and the request line, and its own waits
%% (300 s for a request line, 30 s per header) cannot be set. So the
%% listener is mochiweb's socket server with {@link connection/4} as the
%% per-connection loop instead of `mochiweb_http''s: the connection first
%% asks the guard for a slot, then runs `mochiweb_http:loop/3' (mochiweb's
%% request parser, unchanged) with the routes wrapped to tell the guard
%% when a request is being served and when it is done. Deadlines are the
%% guard's: a connection that has not completed its request within
%% `request_timeout', or stays idle between requests for `idle_timeout',
%% is ended by the guard (`exit(Conn, {shutdown, Why})': mochiweb's
%% socket server takes that as a normal end, and the socket closes with
%% its owner). mochiweb's own `max' is kept well above `max_connections'
%% so that it never stops accepting: refusing is the guard's job, and a
%% connection it refuses is closed at once instead of waiting in the
%% kernel's backlog.
%%
%% A connection serving a request, or upgraded to a WebSocket (the
%% dashboard's `/ws', a Foxglove client), is busy: never timed out nor
%% shed here; its own process bounds it (send timeouts, the hub's
%% `max_clients', the bridge's faults).
%%
%% <b>TLS.</b> With `tls' (a map of `ssl' server options, `certfile' and
%% `keyfile' at least) mochiweb still accepts plain TCP, and the
%% connection, once it holds a slot, upgrades the socket itself
%% (`ssl:handshake/3'): a client slow to finish its TLS handshake is a
%% client that has not completed its request, held to `request_timeout'
%% and the same shares as any other; a handshake that fails is closed and
%% counted (`tls_handshake'). mochiweb then serves `{ssl, Socket}' as it
%% serves a TCP socket.
%%
%% Options (`toroco_live:start/1', app env): `request_timeout' (default
%% 5000 ms), `idle_timeout' (default 30000 ms), `max_connections' (default
%% 128 per port), `max_per_peer' (default 32 per client address),
%% `min_age' (default 2000 ms: when the port, or an address's share, is
%% full, the longest-idle connection at least this old is closed for the
%% newcomer; when none is, the newcomer is closed). Counters ({@link
%% stats/1}, in `/metrics'): connections now, accepted, and closed by
%% reason: `request_timeout', `idle_timeout', `shed', `too_many_from_peer',
%% `too_many_clients' (both refused at once), `tls_handshake' (a TLS
%% handshake that failed), `ended' (by the client or after a response).
%%
%% Messages between a connection and its guard, built and matched only here:
%% | from | to    | message               | when                          | answer |
%% |------|-------|-----------------------|-------------------------------|--------|
%% | conn | guard | `{admit, Ip}' (call)  | accepted                      | `ok' or `{error, Refusal}' |
%% | conn | guard | `{busy, Conn}'        | a request came, being served  | none |
%% | conn | guard | `{done, Conn}'        | the response went             | none |
%% | conn | guard | `{tls_failed, Conn}'  | its TLS handshake failed      | none |
%% | guard| conn  | exit `{shutdown, Why}'| a deadline passed, or shed    | none |
-module(toroco_live_listener).
-behaviour(gen_statem).

-export([start_link/2, start_link/4, stop/1, port/1, stats/1, reasons/0]).
-export([connection/4]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).
-export_type([opts/0, stats/0, tls/0]).

-type opts() :: #{ip := inet:ip_address(), port := inet:port_number(),
                  loop := fun((term()) -> term()),
                  request_timeout => pos_integer(), idle_timeout => pos_integer(),
                  max_connections => pos_integer(), max_per_peer => pos_integer(),
                  min_age => non_neg_integer(), tls => tls()}.
%% `ssl' server options as a map: `certfile' and `keyfile' (PEM files) at
%% least; any other key of `ssl:tls_server_option()' goes to `ssl' as is.
-type tls() :: #{certfile := file:filename_all(), keyfile := file:filename_all(), atom() => term()}.
-type reason() :: request_timeout | idle_timeout | shed | too_many_from_peer
                | too_many_clients | tls_handshake | ended.
-type stats() :: #{port := inet:port_number(), connections := non_neg_integer(),
                   accepted := non_neg_integer(), closed_by := #{reason() => non_neg_integer()},
                   peers := non_neg_integer()}.

-define(HANDSHAKE_BACKSTOP_MS, 60000).
-define(LOG, #{domain => [toroco, live, listener]}).
-define(DEFAULTS, #{request_timeout => 5000, idle_timeout => 30000, max_connections => 128,
                    max_per_peer => 32, min_age => 2000}).

%%====================================================================
%% API
%%====================================================================

%% @doc Starts the guard and mochiweb's listener under it; registered as
%% `Name' unless `Name' is `undefined'.
-spec start_link(atom(), opts()) -> {ok, pid()} | {error, term()}.
start_link(undefined, Opts) ->
    gen_statem:start_link(?MODULE, Opts, []);
start_link(Name, Opts) ->
    gen_statem:start_link({local, Name}, ?MODULE, Opts, []).

%% @doc A `toroco_live' port's listener: `Port' and `Loop' with the address
%% and the bounds of the dashboard's configuration (`toroco_live:start/1''s
%% `ip', `request_timeout', `idle_timeout', `max_connections',
%% `max_per_peer', `min_age', and `tls'), the same for every port.
-spec start_link(atom(), map(), inet:port_number(), fun((term()) -> term())) ->
          {ok, pid()} | {error, term()}.
start_link(Name, Config, Port, Loop) ->
    Bounds = maps:with([request_timeout, idle_timeout, max_connections, max_per_peer, min_age,
                        tls], Config),
    start_link(Name, Bounds#{ip => maps:get(ip, Config, {127, 0, 0, 1}), port => Port, loop => Loop}).

%% @doc Stops the listener and every connection it still has.
-spec stop(pid() | atom()) -> ok.
stop(Guard) ->
    gen_statem:stop(Guard).

%% @doc The port the listener got.
-spec port(pid() | atom()) -> inet:port_number().
port(Guard) ->
    gen_statem:call(Guard, port).

%% @doc Connections now, accepted so far, closes by reason.
-spec stats(pid() | atom()) -> stats().
stats(Guard) ->
    gen_statem:call(Guard, stats).

%% @doc Every reason a close is counted under.
-spec reasons() -> [reason()].
reasons() ->
    [request_timeout, idle_timeout, shed, too_many_from_peer, too_many_clients, tls_handshake,
     ended].

%%====================================================================
%% The connection's side (runs in mochiweb's connection process)
%%====================================================================

%% @doc mochiweb's per-connection loop: a slot first, the TLS handshake
%% when the port has TLS (`Tls', `ssl' options, or `none'), then
%% mochiweb's HTTP loop with `Loop' as the request handler.
-spec connection(term(), list(), pid(), {fun((term()) -> term()), [ssl:tls_server_option()] | none}) -> ok.
connection(Socket, Opts, Guard, {Loop, Tls}) ->
    Admitted = case mochiweb_socket:peername(Socket) of
                   {ok, {Ip, _}} ->
                       try gen_statem:call(Guard, {admit, Ip})
                       catch exit:_ -> {error, no_listener}
                       end;
                   {error, Why} -> {error, Why}
               end,
    case Admitted of
        ok ->
            case secure(Socket, Tls) of
                {ok, Secured} ->
                    Self = self(),
                    mochiweb_http:loop(Secured, Opts,
                                       fun(Req) -> request(Guard, Self, Loop, Req) end);
                {error, _} ->
                    %% a client that cannot complete a handshake: closed, counted
                    gen_statem:cast(Guard, {tls_failed, self()}),
                    _ = mochiweb_socket:close(Socket),
                    ok
            end;
        {error, _} ->
            %% refused before any handshake: a refusal costs no TLS
            _ = mochiweb_socket:close(Socket),
            ok
    end.

%% The handshake runs in the connection's process, within its slot: the
%% guard's request_timeout ends it as it ends a slow request (the timeout
%% given to ssl is only a backstop).
secure(Socket, none) ->
    {ok, Socket};
secure(Socket, Tls) ->
    case ssl:handshake(Socket, Tls, ?HANDSHAKE_BACKSTOP_MS) of
        {ok, Ssl} -> {ok, {ssl, Ssl}};
        {error, _} = E -> E
    end.

request(Guard, Self, Loop, Req) ->
    gen_statem:cast(Guard, {busy, Self}),
    Result = try Loop(Req)
             catch Class:Why:Stack when Class =:= error; Class =:= throw ->
                     %% Not the request, nor the reason or the stack's
                     %% arguments: a query may hold the token. Its path,
                     %% what failed and where.
                     logger:error("toroco_live: ~s ~ts failed: ~0p:~0p in ~0p",
                                  [mochiweb_request:get(method, Req),
                                   mochiweb_request:get(path, Req), Class, kind(Why), top(Stack)],
                                  ?LOG),
                     exit({shutdown, request_failed})
             end,
    gen_statem:cast(Guard, {done, Self}),
    Result.

kind(Why) when is_atom(Why) -> Why;
kind(Why) when is_tuple(Why), is_atom(element(1, Why)) -> element(1, Why);
kind(_) -> other.

top([{M, F, A, _} | _]) when is_list(A) -> {M, F, length(A)};
top([{M, F, A, _} | _]) -> {M, F, A};
top(_) -> unknown.

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> handle_event_function.
callback_mode() ->
    handle_event_function.

-spec init(opts()) -> {ok, listening, map()} | {stop, term()}.
init(Opts0) ->
    process_flag(trap_exit, true),
    Opts = maps:merge(?DEFAULTS, Opts0),
    #{ip := Ip, port := Port, loop := Loop, max_connections := Max} = Opts,
    _ = mochiweb_clock:start(),
    %% mochiweb stops accepting at its `max': far above ours, so the
    %% refused are closed by us at once rather than left in the backlog
    Tls = case Opts of
              #{tls := T} -> ssl_options(T);
              #{} -> none
          end,
    case mochiweb_socket_server:start_link([{name, undefined}, {ip, Ip}, {port, Port},
                                            {max, 4 * Max + 1024},
                                            {loop, {?MODULE, connection, [self(), {Loop, Tls}]}}]) of
        {ok, Server} ->
            Limits = maps:with([max_per_peer, min_age, request_timeout, idle_timeout], Opts),
            {ok, listening, #{server => Server,
                              port => mochiweb_socket_server:get(Server, port),
                              slots => toroco_slots:new(Limits#{max => Max}),
                              monitors => #{}, accepted => 0,
                              closed_by => maps:from_list([{R, 0} || R <- reasons()])}};
        {error, Why} ->
            {stop, Why}
    end.

-spec handle_event(gen_statem:event_type(), term(), listening, map()) ->
          gen_statem:event_handler_result(listening).
handle_event({call, {Conn, _} = From}, {admit, Ip}, _, D = #{slots := Slots}) ->
    case toroco_slots:admit(Conn, Ip, now_ms(), Slots) of
        {ok, Slots1} ->
            admitted(From, Conn, D#{slots := Slots1});
        {shed, Victim, Slots1} ->
            admitted(From, Conn, close(Victim, shed, D#{slots := Slots1}));
        {refuse, Why, _} ->
            {keep_state, count(Why, D), [{reply, From, {error, Why}}]}
    end;
handle_event({call, From}, port, _, #{port := Port}) ->
    {keep_state_and_data, [{reply, From, Port}]};
handle_event({call, From}, stats, _, D = #{port := Port, slots := Slots}) ->
    {keep_state_and_data,
     [{reply, From, #{port => Port, connections => toroco_slots:size(Slots),
                      accepted => maps:get(accepted, D), closed_by => maps:get(closed_by, D),
                      peers => map_size(toroco_slots:peers(Slots))}}]};
handle_event(cast, {busy, Conn}, _, D = #{slots := Slots}) ->
    {keep_state, D#{slots := toroco_slots:busy(Conn, Slots)}};
handle_event(cast, {tls_failed, Conn}, _, D = #{slots := Slots, monitors := Ms}) ->
    case maps:take(Conn, Ms) of
        {Ref, Ms1} ->
            demonitor(Ref, [flush]),
            D1 = D#{slots := toroco_slots:remove(Conn, Slots), monitors := Ms1},
            {keep_state, count(tls_handshake, D1), deadline(D1)};
        error ->
            keep_state_and_data
    end;
handle_event(cast, {done, Conn}, _, D = #{slots := Slots}) ->
    D1 = D#{slots := toroco_slots:done(Conn, now_ms(), Slots)},
    {keep_state, D1, deadline(D1)};
handle_event({timeout, slots}, expire, _, D = #{slots := Slots}) ->
    {Gone, Slots1} = toroco_slots:expired(now_ms(), Slots),
    D1 = lists:foldl(fun({Conn, Why}, Acc) -> close(Conn, Why, Acc) end, D#{slots := Slots1}, Gone),
    {keep_state, D1, deadline(D1)};
handle_event(info, {'DOWN', _, process, Conn, _}, _, D = #{slots := Slots, monitors := Ms}) ->
    {keep_state, count(ended, D#{slots := toroco_slots:remove(Conn, Slots),
                                 monitors := maps:remove(Conn, Ms)})};
handle_event(info, {'EXIT', Server, Why}, _, #{server := Server}) ->
    {stop, {listener, Why}};
handle_event(info, {'EXIT', _, _}, _, _) ->
    keep_state_and_data.

admitted(From, Conn, D = #{monitors := Ms, accepted := N}) ->
    D1 = D#{monitors := Ms#{Conn => monitor(process, Conn)}, accepted := N + 1},
    {keep_state, D1, [{reply, From, ok} | deadline(D1)]}.

%% Ends a connection the slots let go (already out of them).
close(Conn, Why, D = #{monitors := Ms}) ->
    case maps:take(Conn, Ms) of
        {Ref, Ms1} ->
            demonitor(Ref, [flush]),
            exit(Conn, {shutdown, Why}),
            count(Why, D#{monitors := Ms1});
        error ->
            D
    end.

count(Why, D = #{closed_by := By}) ->
    D#{closed_by := By#{Why => maps:get(Why, By, 0) + 1}}.

deadline(#{slots := Slots}) ->
    toroco_slots:timeout_action(Slots).

now_ms() ->
    erlang:monotonic_time(millisecond).

%% The port's `ssl' options: the map's, TLS 1.2 at least, and ssl's own
%% log kept to errors: every stranger's failed handshake is counted
%% (`tls_handshake'), and a log line each would let strangers fill the log.
ssl_options(Tls) ->
    maps:to_list(maps:merge(#{versions => ['tlsv1.3', 'tlsv1.2'], log_level => error}, Tls)).

-spec terminate(term(), listening, map()) -> ok.
terminate(_, _, #{server := Server}) ->
    %% from its parent, `shutdown' stops mochiweb's server, and the link
    %% takes every connection process with it; waited for, so the port is
    %% free when this returns
    exit(Server, shutdown),
    receive {'EXIT', Server, _} -> ok
    after 5000 -> ok
    end.
