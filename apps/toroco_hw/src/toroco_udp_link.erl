%% @doc A link to remote systems over UDP, one JSON event per datagram (the
%% event format is in `toroco_net').
%%
%% Each value delivered to one of the device's `inputs' is sent to every
%% address in `peers' as `{"input": In, "value": V}'. Each datagram received
%% that reads `{"output": Out, "value": V}' with `Out' one of the device's
%% `outputs' is emitted on `Out' (a `send'; `"latch": true' makes it a
%% `set', `"hold": Ms' gives it a hold, `"unset": true' unsets).
%%
%% Options: `inputs', `outputs' (atom lists, default `[]'), `peers'
%% (`[{Addr, Port}]', default `[]'), `port' (default 0: ephemeral, see
%% `info'), `ip' (bind address, default `{127,0,0,1}'), `allow' (sender
%% addresses, default `any'), `max_datagram' (default 8192 bytes), `recbuf'
%% (kernel receive buffer, default 1 MiB).
%%
%% Bad datagrams are dropped and counted by reason, with a logger warning
%% naming the device at most once a second: `oversized', `not_json',
%% `not_object', `no_output', `unknown_output', `no_value', `bad_value',
%% `bad_field', `not_allowed'. An input value that has no JSON form
%% (a pid, a fun) is counted as `unencodable'; a failed send as
%% `send_errors'.
%%
%% `info/2': `port', `ip', `peers', `accepted', `rejected', `rejected_by',
%% `sent', `unencodable', `send_errors'.
-module(toroco_udp_link).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).

-spec interface(map()) -> #{inputs := [atom()], outputs := [atom()]}.
interface(Opts) ->
    toroco_net:link_interface(Opts).

-spec init(atom(), map()) -> {ok, linked, map()} | {error, term()}.
init(Name, Opts) ->
    Specs = [{port, {port, 0}}, {ip, {ip, {127, 0, 0, 1}}}, {allow, {allow, any}},
             {peers, {peers, []}}, {max_datagram, {pos_integer, 8192}},
             {recbuf, {pos_integer, 1048576}}],
    case toroco_net:link_options(Specs, Opts) of
        {ok, S} -> open(Name, S);
        {error, _} = E -> E
    end.

open(Name, S = #{port := Port, ip := Ip, max_datagram := Max, recbuf := RecBuf}) ->
    case toroco_net:udp_open(Ip, Port, Max, RecBuf) of
        {ok, Sock, Actual} ->
            {ok, linked, S#{name => Name, socket => Sock, port := Actual, accepted => 0,
                            sent => 0, unencodable => 0, send_errors => 0,
                            bad => toroco_bad_input:new(Name)}};
        {error, Reason} ->
            logger:warning("~p (toroco_udp_link) not started: ~0p", [Name, Reason],
                           #{domain => [toroco, hw]}),
            {error, Reason}
    end.

-spec handle_input(atom(), term(), linked, map()) -> toroco_behavior:result().
handle_input(Input, V, _State, D = #{socket := S, peers := Peers, sent := N,
                                     send_errors := E, unencodable := U, name := Name}) ->
    case toroco_net:encode_event(Input, V) of
        {ok, Bin} ->
            Failed = [Why || {Ip, Port} <- Peers,
                             {error, Why} <- [gen_udp:send(S, Ip, Port, Bin)]],
            case Failed of
                [] -> ok;
                [Why | _] -> logger:warning("~p could not send ~p: ~0p", [Name, Input, Why],
                                            #{domain => [toroco, hw]})
            end,
            {keep_state, D#{sent := N + length(Peers) - length(Failed),
                            send_errors := E + length(Failed)}};
        {error, unencodable} ->
            logger:warning("~p: the value on input ~p has no JSON form: ~0P",
                           [Name, Input, V, 10], #{domain => [toroco, hw]}),
            {keep_state, D#{unencodable := U + 1}}
    end.

-spec handle_event(gen_statem:event_type(), term(), linked, map()) ->
          toroco_behavior:result().
handle_event(info, {udp, S, Ip, _Port, Data}, _State, D = #{socket := S, outputs := Outs}) ->
    toroco_net:udp_datagram(Ip, Data, D, fun(Bin) -> toroco_net:decode_event(Bin, Outs) end);
handle_event(info, {udp_passive, S}, _State, #{socket := S}) ->
    toroco_net:udp_rearm(S),
    keep_state_and_data.

-spec info(linked, map()) -> map().
info(_State, D = #{bad := B}) ->
    (maps:with([port, ip, peers, accepted, sent, unencodable, send_errors], D))#{
      rejected => toroco_bad_input:total(B),
      rejected_by => toroco_bad_input:counts(B)}.

-spec terminate(term(), linked, map()) -> ok.
terminate(_Reason, _State, #{socket := S}) ->
    gen_udp:close(S).
