%% @doc A listening port of `toroco_live' that strangers can reach (the
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
%% Options (`toroco_live:start/1', app env): `request_timeout' (default
%% 5000 ms), `idle_timeout' (default 30000 ms), `max_connections' (default
%% 128 per port), `max_per_peer' (default 32 per client address),
%% `min_age' (default 2000 ms: when the port, or an address's share, is
%% full, the longest-idle connection at least this old is closed for the
%% newcomer; when none is, the newcomer is closed). Counters ({@link
%% stats/1}, in `/metrics'): connections now, accepted, and closed by
%% reason: `request_timeout', `idle_timeout', `shed', `too_many_from_peer',
%% `too_many_clients' (both refused at once), `ended' (by the client or
%% after a response).
%%
%% Messages between a connection and its guard, built and matched only here:
%% | from | to    | message               | when                          | answer |
%% |------|-------|-----------------------|-------------------------------|--------|
%% | conn | guard | `{admit, Ip}' (call)  | accepted                      | `ok' or `{error, Refusal}' |
%% | conn | guard | `{busy, Conn}'        | a request came, being served  | none |
%% | conn | guard | `{done, Conn}'        | the response went             | none |
%% | guard| conn  | exit `{shutdown, Why}'| a deadline passed, or shed    | none |
-module(toroco_live_listener).
-behaviour(gen_statem).

-export([start_link/2, start_link/4, stop/1, port/1, stats/1, reasons/0]).
-export([connection/4]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).
-export_type([opts/0, stats/0]).

-type opts() :: #{ip := inet:ip_address(), port := inet:port_number(),
                  loop := fun((term()) -> term()),
                  request_timeout => pos_integer(), idle_timeout => pos_integer(),
                  max_connections => pos_integer(), max_per_peer => pos_integer(),
                  min_age => non_neg_integer()}.
-type reason() :: request_timeout | idle_timeout | shed | too_many_from_peer
                | too_many_clients | ended.
-type stats() :: #{port := inet:port_number(), connections := non_neg_integer(),
                   accepted := non_neg_integer(), closed_by := #{reason() => non_neg_integer()},
                   peers := non_neg_integer()}.

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
%% `max_per_peer', `min_age'), the same for every port.
-spec start_link(atom(), map(), inet:port_number(), fun((term()) -> term())) ->
          {ok, pid()} | {error, term()}.
start_link(Name, Config, Port, Loop) ->
    Bounds = maps:with([request_timeout, idle_timeout, max_connections, max_per_peer, min_age],
                       Config),
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
    [request_timeout, idle_timeout, shed, too_many_from_peer, too_many_clients, ended].

%%====================================================================
%% The connection's side (runs in mochiweb's connection process)
%%====================================================================

%% @doc mochiweb's per-connection loop: a slot first, then mochiweb's HTTP
%% loop with `Loop' as the request handler.
-spec connection(term(), list(), pid(), fun((term()) -> term())) -> ok.
connection(Socket, Opts, Guard, Loop) ->
    Admitted = case mochiweb_socket:peername(Socket) of
                   {ok, {Ip, _}} ->
                       try gen_statem:call(Guard, {admit, Ip})
                       catch exit:_ -> {error, no_listener}
                       end;
                   {error, Why} -> {error, Why}
               end,
    case Admitted of
        ok ->
            Self = self(),
            mochiweb_http:loop(Socket, Opts, fun(Req) -> request(Guard, Self, Loop, Req) end);
        {error, _} ->
            _ = mochiweb_socket:close(Socket),
            ok
    end.

request(Guard, Self, Loop, Req) ->
    gen_statem:cast(Guard, {busy, Self}),
    Result = Loop(Req),
    gen_statem:cast(Guard, {done, Self}),
    Result.

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
    case mochiweb_socket_server:start_link([{name, undefined}, {ip, Ip}, {port, Port},
                                            {max, 4 * Max + 1024},
                                            {loop, {?MODULE, connection, [self(), Loop]}}]) of
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

-spec terminate(term(), listening, map()) -> ok.
terminate(_, _, #{server := Server}) ->
    %% from its parent, `shutdown' stops mochiweb's server, and the link
    %% takes every connection process with it; waited for, so the port is
    %% free when this returns
    exit(Server, shutdown),
    receive {'EXIT', Server, _} -> ok
    after 5000 -> ok
    end.
