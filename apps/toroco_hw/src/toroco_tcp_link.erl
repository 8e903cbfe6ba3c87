%% @doc A link to remote systems over TCP: a listening device whose clients
%% exchange line-delimited JSON events with the network (the event format is
%% in `toroco_net').
%%
%% Each value delivered to one of the device's `inputs' goes to every
%% connected client as one line, `{"input": In, "value": V}\n'. Each line a
%% client sends that reads `{"output": Out, "value": V}' with `Out' one of
%% the device's `outputs' is emitted on `Out' (`"latch"', `"hold"' and
%% `"unset"' as in `toroco_net'). A trailing `\r' is ignored, and so are
%% empty lines (a client that only listens sends one now and then to show
%% it is there).
%%
%% Options: `inputs', `outputs' (atom lists, default `[]'), `port' (default
%% 0: ephemeral, see `info'), `ip' (bind address, default `{127,0,0,1}'),
%% `allow' (client addresses, default `any'), `max_clients' (default 8),
%% `max_line' (default 65536 bytes), `send_timeout' (default 1000 ms: a
%% client that does not read is disconnected after that long), and the
%% bounds on strangers (`toroco_slots'): `line_timeout' (default 5000 ms:
%% a new connection must complete its first line, and a line once begun
%% must end, within it), `idle_timeout' (default 30000 ms without a line),
%% `max_per_peer' (default 4 connections per client address) and `min_age'
%% (default 2000 ms: when every slot, or a peer's share, is taken, the
%% longest-idle client at least this old is closed to admit the newcomer;
%% when none is that old the newcomer is refused).
%%
%% Resources stay bounded whatever clients do: at most `max_clients'
%% connections, `max_per_peer' from one address, at most `max_line' bytes
%% buffered per client (a longer line is dropped as it comes and counted
%% once), a partial line left by a disconnect is dropped, a client too slow
%% or too quiet is closed. One process owns the listening socket and every
%% connection; a linked acceptor process only accepts and hands each
%% connection over. Deadlines are real time (absolute timeouts): clients
%% live outside any simulated clock.
%%
%% Counters in `info/2': `port', `ip', `clients' (connected now), `peers',
%% `connections' (accepted so far), `accepted' and `rejected' lines,
%% `rejected_by' (`oversized', `partial_line', `not_json', `not_object',
%% `no_output', `unknown_output', `no_value', `bad_value', `bad_field'),
%% `refused' and `refused_by' (`not_allowed', `too_many_clients',
%% `too_many_from_peer', `accept_error'), `closed' and `closed_by' (the
%% connections that ended, by reason: `closed' by the client, `error',
%% `send_failed', `line_timeout', `idle_timeout', `shed' to admit another),
%% `sent' lines, `send_errors', `unencodable', and the options above.
-module(toroco_tcp_link).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).

-define(ACCEPTED, '$toroco_tcp_link_accepted').
-define(ACCEPT_ERROR, '$toroco_tcp_link_accept_error').

-spec interface(map()) -> #{inputs := [atom()], outputs := [atom()]}.
interface(Opts) ->
    toroco_net:link_interface(Opts).

-spec init(atom(), map()) -> {ok, listening, map()} | {error, term()}.
init(Name, Opts) ->
    Specs = [{port, {port, 0}}, {ip, {ip, {127, 0, 0, 1}}}, {allow, {allow, any}},
             {max_clients, {pos_integer, 8}}, {max_line, {pos_integer, 65536}},
             {send_timeout, {pos_integer, 1000}}, {line_timeout, {pos_integer, 5000}},
             {idle_timeout, {pos_integer, 30000}}, {max_per_peer, {pos_integer, 4}},
             {min_age, {non_neg_integer, 2000}}],
    case toroco_net:link_options(Specs, Opts) of
        {ok, S} -> listen(Name, S);
        {error, _} = E -> E
    end.

listen(Name, S = #{port := Port, ip := Ip, send_timeout := T, max_clients := Max,
                   max_per_peer := PerPeer, min_age := MinAge, line_timeout := LineT,
                   idle_timeout := IdleT}) ->
    Family = case tuple_size(Ip) of 4 -> inet; 8 -> inet6 end,
    case gen_tcp:listen(Port, [binary, Family, {ip, Ip}, {active, false}, {packet, raw},
                               {reuseaddr, true}, {backlog, 128}, {nodelay, true},
                               {send_timeout, T}, {send_timeout_close, true}]) of
        {ok, L} ->
            {ok, Actual} = inet:port(L),
            {ok, listening, S#{name => Name, lsock => L, port := Actual,
                               acceptor => start_acceptor(L), clients => #{},
                               connections => 0, accepted => 0, sent => 0, send_errors => 0,
                               unencodable => 0, acceptor_restarts => 0,
                               slots => toroco_slots:new(#{max => Max, max_per_peer => PerPeer,
                                                           min_age => MinAge,
                                                           request_timeout => LineT,
                                                           idle_timeout => IdleT}),
                               closed_by => #{},
                               bad => toroco_bad_input:new(Name),
                               refusals => toroco_bad_input:new(Name)}};
        {error, Reason} ->
            logger:warning("~p (toroco_tcp_link) not started: ~0p", [Name, {tcp_listen, {Ip, Port}, Reason}],
                           #{domain => [toroco, hw]}),
            {error, {tcp_listen, {Ip, Port}, Reason}}
    end.

%%====================================================================
%% Events out
%%====================================================================

-spec handle_input(atom(), term(), listening, map()) -> toroco_behavior:result().
handle_input(Input, V, _State, D = #{clients := Cs, sent := N, unencodable := U,
                                     name := Name}) ->
    case toroco_net:encode_event(Input, V) of
        {ok, Bin} ->
            Line = [Bin, $\n],
            {Ok, Failed} = lists:partition(fun(Sock) -> gen_tcp:send(Sock, Line) =:= ok end,
                                           maps:keys(Cs)),
            D1 = lists:foldl(fun(Sock, Acc) -> drop_client(Sock, send_failed, Acc) end,
                             D#{sent := N + length(Ok)}, Failed),
            #{send_errors := E} = D1,
            {keep_state, D1#{send_errors := E + length(Failed)}};
        {error, unencodable} ->
            logger:warning("~p: the value on input ~p has no JSON form: ~0P",
                           [Name, Input, V, 10], #{domain => [toroco, hw]}),
            {keep_state, D#{unencodable := U + 1}}
    end.

%%====================================================================
%% Connections and events in
%%====================================================================

-spec handle_event(gen_statem:event_type(), term(), listening, map()) ->
          toroco_behavior:result().
handle_event(info, {tcp, Sock, Data}, _State, D = #{clients := Cs}) when is_map_key(Sock, Cs) ->
    {Actions, D1} = lines(Sock, Data, D),
    _ = inet:setopts(Sock, [{active, once}]),
    {keep_state, D1, Actions ++ deadline(D1)};
handle_event(info, {tcp, _Sock, _Data}, _State, _D) ->
    %% a client dropped since: its last data was already on its way
    keep_state_and_data;
handle_event(info, {tcp_closed, Sock}, _State, D) ->
    {keep_state, drop_client(Sock, closed, D)};
handle_event(info, {tcp_error, Sock, _Reason}, _State, D) ->
    {keep_state, drop_client(Sock, error, D)};
handle_event(info, {?ACCEPTED, Pid, Sock}, _State, D = #{acceptor := Pid}) ->
    D1 = accepted(Sock, D),
    {keep_state, D1, deadline(D1)};
handle_event({timeout, slots}, expire, _State, D = #{slots := Slots}) ->
    {Gone, Slots1} = toroco_slots:expired(now_ms(), Slots),
    D1 = lists:foldl(fun({Sock, request_timeout}, Acc) -> drop_client(Sock, line_timeout, Acc);
                        ({Sock, idle_timeout}, Acc) -> drop_client(Sock, idle_timeout, Acc)
                     end, D#{slots := Slots1}, Gone),
    {keep_state, D1, deadline(D1)};
handle_event(info, {?ACCEPT_ERROR, Reason}, _State, D = #{refusals := R}) ->
    {keep_state, D#{refusals := toroco_bad_input:count(accept_error, Reason, R)}};
handle_event(info, {'EXIT', Pid, Reason}, _State, D = #{acceptor := Pid, lsock := L, name := Name,
                                                       acceptor_restarts := N}) ->
    case Reason of
        {shutdown, closed} ->
            {stop, {listen_socket_closed, Name}};
        _ ->
            logger:warning("~p: acceptor ended (~0p); starting another", [Name, Reason],
                           #{domain => [toroco, hw]}),
            {keep_state, D#{acceptor := start_acceptor(L), acceptor_restarts := N + 1}}
    end.

%% A newcomer: refused when not allowed; else it takes a slot, perhaps the
%% one of the longest-idle client (`toroco_slots'), or is refused for want
%% of one.
accepted(Sock, D = #{allow := Allow, refusals := R, slots := Slots}) ->
    case inet:peername(Sock) of
        {ok, {Ip, _} = Peer} ->
            case toroco_net:allowed(Ip, Allow) of
                false ->
                    gen_tcp:close(Sock),
                    D#{refusals := toroco_bad_input:count(not_allowed, Peer, R)};
                true ->
                    case toroco_slots:admit(Sock, Ip, now_ms(), Slots) of
                        {ok, Slots1} ->
                            admitted(Sock, Peer, D#{slots := Slots1});
                        {shed, Victim, Slots1} ->
                            admitted(Sock, Peer, drop_client(Victim, shed, D#{slots := Slots1}));
                        {refuse, Why, _} ->
                            gen_tcp:close(Sock),
                            D#{refusals := toroco_bad_input:count(Why, Peer, R)}
                    end
            end;
        {error, _} ->
            %% gone before it was handed over: accepted all the same
            gen_tcp:close(Sock),
            D#{connections := maps:get(connections, D) + 1}
    end.

admitted(Sock, Peer, D = #{clients := Cs, connections := N}) ->
    _ = inet:setopts(Sock, [{active, once}]),
    D#{clients := Cs#{Sock => #{peer => Peer, buf => <<>>, skipping => false}},
       connections := N + 1}.

drop_client(Sock, Why, D = #{clients := Cs, bad := B, slots := Slots, closed_by := By}) ->
    case maps:take(Sock, Cs) of
        {#{buf := Buf, peer := Peer}, Cs1} ->
            gen_tcp:close(Sock),
            B1 = case Why =/= send_failed andalso byte_size(Buf) > 0 of
                     true -> toroco_bad_input:count(partial_line, {Peer, Buf}, B);
                     false -> B
                 end,
            D#{clients := Cs1, bad := B1, slots := toroco_slots:remove(Sock, Slots),
               closed_by := By#{Why => maps:get(Why, By, 0) + 1}};
        error ->
            D
    end.

%% The clients' next deadline, as an absolute (real-time) timeout.
deadline(#{slots := Slots}) ->
    toroco_slots:timeout_action(Slots).

now_ms() ->
    erlang:monotonic_time(millisecond).

%% Splits what came into lines; the incomplete tail stays buffered, unless
%% it is already longer than a line may be.
lines(Sock, Data, D = #{clients := Cs, max_line := Max}) ->
    C = #{buf := Buf, skipping := Skipping} = maps:get(Sock, Cs),
    [Tail | RevLines] = lists:reverse(binary:split(<<Buf/binary, Data/binary>>, <<"\n">>,
                                                   [global])),
    {Lines, Skipping1} = case {Skipping, lists:reverse(RevLines)} of
                             {true, [_SkippedEnd | Rest]} -> {Rest, false};
                             {_, All} -> {All, Skipping}
                         end,
    {Actions, D1} = lists:foldl(fun(L, {As, DAcc}) -> line(L, As, DAcc) end, {[], D}, Lines),
    #{bad := B} = D1,
    {Buf1, Skip2, B1} =
        case byte_size(Tail) > Max of
            true when Skipping1 -> {<<>>, true, B};
            true -> {<<>>, true, toroco_bad_input:count(oversized, Tail, B)};
            false when Skipping1 -> {<<>>, true, B};
            false -> {Tail, false, B}
        end,
    %% a line ended (whatever it said): the client is idle from now on; a
    %% line left begun must end within the line timeout
    #{slots := Slots} = D1,
    Now = now_ms(),
    Slots1 = case RevLines =/= [] of
                 true -> toroco_slots:done(Sock, Now, Slots);
                 false -> Slots
             end,
    Slots2 = case Buf1 =/= <<>> orelse Skip2 of
                 true -> toroco_slots:started(Sock, Now, Slots1);
                 false -> Slots1
             end,
    {lists:reverse(Actions),
     D1#{clients := Cs#{Sock := C#{buf := Buf1, skipping := Skip2}}, bad := B1,
         slots := Slots2}}.

line(L0, As, D = #{max_line := Max, outputs := Outs, accepted := N, bad := B}) ->
    L = case L0 of
            <<Body:(byte_size(L0) - 1)/binary, $\r>> -> Body;
            _ -> L0
        end,
    case L of
        <<>> -> {As, D};
        _ when byte_size(L) > Max -> {As, D#{bad := toroco_bad_input:count(oversized, L, B)}};
        _ ->
            case toroco_net:decode_event(L, Outs) of
                {ok, Action} -> {[Action | As], D#{accepted := N + 1}};
                {error, Reason} -> {As, D#{bad := toroco_bad_input:count(Reason, L, B)}}
            end
    end.

%%====================================================================
%% The acceptor
%%====================================================================

start_acceptor(L) ->
    Device = self(),
    spawn_link(fun() -> accept_loop(Device, L) end).

accept_loop(Device, L) ->
    case gen_tcp:accept(L) of
        {ok, Sock} ->
            case gen_tcp:controlling_process(Sock, Device) of
                ok -> Device ! {?ACCEPTED, self(), Sock}, ok;
                {error, _} -> gen_tcp:close(Sock)
            end,
            accept_loop(Device, L);
        {error, closed} ->
            exit({shutdown, closed});
        {error, Reason} ->
            %% out of file descriptors and the like: let it pass, then go on
            Device ! {?ACCEPT_ERROR, Reason},
            receive after 100 -> ok end,
            accept_loop(Device, L)
    end.

%%====================================================================
%% Inspection and end
%%====================================================================

-spec info(listening, map()) -> map().
info(_State, D = #{clients := Cs, bad := B, refusals := R, closed_by := By}) ->
    (maps:with([port, ip, connections, accepted, sent, send_errors, unencodable,
                acceptor_restarts, max_clients, max_line, line_timeout, idle_timeout,
                max_per_peer, min_age], D))#{
      closed => lists:sum(maps:values(By)),
      closed_by => By,
      clients => map_size(Cs),
      peers => lists:sort([P || #{peer := P} <- maps:values(Cs)]),
      rejected => toroco_bad_input:total(B),
      rejected_by => toroco_bad_input:counts(B),
      refused => toroco_bad_input:total(R),
      refused_by => toroco_bad_input:counts(R)}.

-spec terminate(term(), listening, map()) -> ok.
terminate(_Reason, _State, #{lsock := L, clients := Cs, acceptor := A}) ->
    unlink(A),
    _ = [gen_tcp:close(S) || S <- maps:keys(Cs)],
    gen_tcp:close(L).
