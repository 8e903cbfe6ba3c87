%% @doc What the network devices (`toroco_udp_camera', `toroco_udp_link',
%% `toroco_tcp_link') share: their address options, the allow-list, the UDP
%% socket, and the JSON events of the links.
%%
%% <b>Options</b>: {@link option/3} checks `ip' (a tuple or a string such as
%% `"0.0.0.0"'; default `{127,0,0,1}'), `port' (0..65535, 0 = ephemeral),
%% `allow' (`any' or a list of peer addresses), `peers' (`[{Addr, Port}]')
%% and positive integers.
%%
%% <b>Link events</b>, one JSON object each (a datagram, or a line on TCP):
%% <ul>
%% <li>out, for each value delivered to a link's input `In':
%%     `{"input": "In", "value": V}', plus `"as": "tuple"' when the value
%%     was a tuple and `"as": "atom"' when it was an atom other than
%%     `true', `false', `null'.</li>
%% <li>in, emitted on the link's declared output `Out':
%%     `{"output": "Out", "value": V}' is a `send'; with `"latch": true' a
%%     `set'; with `"hold": Ms' (or `"infinity"') a send with that hold;
%%     `{"output": "Out", "unset": true}' an `unset'. `"as": "tuple"' turns
%%     an array value into a tuple, `"as": "atom"' a string into an atom
%%     that already exists (no atom is ever made from the network). An
%%     object that names `"input"' and no `"output"' (what another link
%%     sends) is taken as naming that output: two links, each with the
%%     other's outputs as inputs, make a wire between two nodes.</li>
%% </ul>
%% Values map as Erlang term to JSON: numbers, `true'/`false'/`null',
%% other atoms and UTF-8 binaries as strings, lists and tuples as arrays,
%% maps (atom, binary or integer keys) as objects; and back from JSON:
%% objects to maps with binary keys, arrays to lists, strings to binaries.
%% Anything else (pids, funs, non-UTF-8 binaries) is not encodable.
-module(toroco_net).

-export([option/3, options/2, link_options/2, names/2, link_interface/1, allowed/2, udp_open/4, udp_rearm/1,
         udp_check/4, udp_datagram/4, decode_event/2, encode_event/2]).
-export_type([allow/0]).

-type allow() :: any | [inet:ip_address()].
-type kind() :: ip | port | allow | peers | pos_integer | non_neg_integer.

-define(ACTIVE_N, 100).

%%====================================================================
%% Options
%%====================================================================

%% @doc Checks option `Key' of kind `Kind' in `Opts' (`Default' when absent).
-spec option(atom(), {kind(), term()}, map()) -> {ok, term()} | {error, term()}.
option(Key, {Kind, Default}, Opts) ->
    V = maps:get(Key, Opts, Default),
    case check(Kind, V) of
        {ok, V1} -> {ok, V1};
        error -> {error, {bad_option, {Key, V}}}
    end.

%% @doc A link's options: `inputs' and `outputs' (lists of names) and the
%% `Specs' as in {@link options/2}; any other key is refused. The checked
%% values by key, with `outputs'.
-spec link_options([{atom(), {kind(), term()}}], map()) -> {ok, map()} | {error, term()}.
link_options(Specs, Opts) ->
    Allowed = [inputs, outputs | [K || {K, _} <- Specs]],
    case {[K || K <- maps:keys(Opts), not lists:member(K, Allowed)],
          names(inputs, Opts), names(outputs, Opts), options(Specs, Opts)} of
        {[K | _], _, _, _} -> {error, {unknown_option, K}};
        {[], {error, _} = E, _, _} -> E;
        {[], _, {error, _} = E, _} -> E;
        {[], _, _, {error, _} = E} -> E;
        {[], {ok, _}, {ok, Outs}, {ok, S}} -> {ok, S#{outputs => Outs}}
    end.

%% @doc Checks each `{Key, {Kind, Default}}' in turn; the checked values by key.
-spec options([{atom(), {kind(), term()}}], map()) -> {ok, map()} | {error, term()}.
options(Specs, Opts) ->
    lists:foldl(fun(_, {error, _} = E) -> E;
                   ({K, Spec}, {ok, Acc}) ->
                        case option(K, Spec, Opts) of
                            {ok, V} -> {ok, Acc#{K => V}};
                            Err -> Err
                        end
                end, {ok, #{}}, Specs).

check(ip, V) -> address(V);
check(port, P) when is_integer(P), P >= 0, P =< 65535 -> {ok, P};
check(allow, any) -> {ok, any};
check(allow, L) when is_list(L) -> all(fun address/1, L);
check(peers, L) when is_list(L) ->
    all(fun({A, P}) when is_integer(P), P > 0, P =< 65535 ->
                case address(A) of
                    {ok, Ip} -> {ok, {Ip, P}};
                    error -> error
                end;
           (_) -> error
        end, L);
check(pos_integer, N) when is_integer(N), N > 0 -> {ok, N};
check(non_neg_integer, N) when is_integer(N), N >= 0 -> {ok, N};
check(_, _) -> error.

address(T) when is_tuple(T) ->
    case inet:ntoa(T) of
        {error, _} -> error;
        _ -> {ok, T}
    end;
address(S) when is_list(S) ->
    case io_lib:printable_latin1_list(S) andalso inet:parse_address(S) of
        {ok, Ip} -> {ok, Ip};
        _ -> error
    end;
address(B) when is_binary(B) ->
    address(binary_to_list(B));
address(_) ->
    error.

all(F, L) ->
    lists:foldr(fun(_, error) -> error;
                   (X, {ok, Acc}) ->
                        case F(X) of
                            {ok, Y} -> {ok, [Y | Acc]};
                            error -> error
                        end
                end, {ok, []}, L).

%% @doc A link's `inputs' or `outputs' option: a list of names (atoms),
%% default `[]'.
-spec names(inputs | outputs, map()) -> {ok, [atom()]} | {error, {bad_option, {atom(), term()}}}.
names(Key, Opts) ->
    case maps:get(Key, Opts, []) of
        L when is_list(L) ->
            case lists:all(fun is_atom/1, L) of
                true -> {ok, L};
                false -> {error, {bad_option, {Key, L}}}
            end;
        Other -> {error, {bad_option, {Key, Other}}}
    end.

%% @doc A link's interface: its `inputs' and `outputs' options, the names
%% in them (an option that is not a list of names is refused by `init/2',
%% through {@link names/2}).
-spec link_interface(map()) -> #{inputs := [atom()], outputs := [atom()]}.
link_interface(Opts) ->
    #{inputs => atoms(maps:get(inputs, Opts, [])), outputs => atoms(maps:get(outputs, Opts, []))}.

atoms(L) when is_list(L) -> lists:usort([A || A <- L, is_atom(A)]);
atoms(_) -> [].

%% @doc Whether a peer address may talk to the device.
-spec allowed(inet:ip_address(), allow()) -> boolean().
allowed(_Ip, any) -> true;
allowed(Ip, List) -> lists:member(Ip, List).

%%====================================================================
%% UDP
%%====================================================================

%% @doc Opens a UDP socket bound to `Ip':`Port', delivering datagrams as
%% messages to the caller. Datagrams longer than `MaxDatagram' arrive cut to
%% `MaxDatagram + 1' bytes, which is how {@link udp_check/4} tells them.
-spec udp_open(inet:ip_address(), inet:port_number(), pos_integer(), pos_integer()) ->
          {ok, gen_udp:socket(), inet:port_number()} | {error, term()}.
udp_open(Ip, Port, MaxDatagram, RecBuf) ->
    Family = case tuple_size(Ip) of 4 -> inet; 8 -> inet6 end,
    case gen_udp:open(Port, [binary, Family, {ip, Ip}, {active, ?ACTIVE_N},
                             {buffer, MaxDatagram + 1}, {recbuf, RecBuf}]) of
        {ok, S} ->
            {ok, Actual} = inet:port(S),
            {ok, S, Actual};
        {error, Reason} ->
            {error, {udp_open, {Ip, Port}, Reason}}
    end.

%% @doc After `{udp_passive, S}': take the next batch of datagrams.
-spec udp_rearm(gen_udp:socket()) -> ok.
udp_rearm(S) ->
    _ = inet:setopts(S, [{active, ?ACTIVE_N}]),
    ok.

%% @doc Whether a datagram is worth decoding.
-spec udp_check(inet:ip_address(), binary(), allow(), pos_integer()) ->
          ok | {error, not_allowed | oversized}.
udp_check(Ip, Data, Allow, Max) ->
    case allowed(Ip, Allow) of
        false -> {error, not_allowed};
        true when byte_size(Data) > Max -> {error, oversized};
        true -> ok
    end.

%% @doc A datagram a UDP device received from `Ip', in the device's
%% `handle_event': checked ({@link udp_check/4}) against the data's `allow'
%% and `max_datagram', then read by `Read' into the action to take. What
%% is taken counts in the data's `accepted', what is refused in its `bad'
%% (`toroco_bad_input').
-spec udp_datagram(inet:ip_address(), binary(), map(),
                   fun((binary()) -> {ok, toroco_behavior:action()} | {error, atom()})) ->
          {keep_state, map()} | {keep_state, map(), [toroco_behavior:action()]}.
udp_datagram(Ip, Data, D = #{allow := Allow, max_datagram := Max}, Read) ->
    Result = case udp_check(Ip, Data, Allow, Max) of
                 ok -> Read(Data);
                 Err -> Err
             end,
    case Result of
        {ok, Action} ->
            #{accepted := N} = D,
            {keep_state, D#{accepted := N + 1}, [Action]};
        {error, Reason} ->
            #{bad := B} = D,
            {keep_state, D#{bad := toroco_bad_input:count(Reason, Data, B)}}
    end.

%%====================================================================
%% Link events
%%====================================================================

%% @doc The toroco action a remote event asks for, on one of `Outputs'.
-spec decode_event(binary(), [atom()]) -> {ok, toroco_behavior:action()} | {error, atom()}.
decode_event(Bin, Outputs) ->
    try jiffy:decode(Bin, [return_maps]) of
        M when is_map(M) -> event(M, Outputs);
        _ -> {error, not_object}
    catch
        _:_ -> {error, not_json}
    end.

event(#{<<"input">> := Name} = M, Outputs) when not is_map_key(<<"output">>, M) ->
    %% what another link sends: two links make a wire between two nodes
    event(maps:remove(<<"input">>, M#{<<"output">> => Name}), Outputs);
event(#{<<"output">> := Name} = M, Outputs) when is_binary(Name) ->
    case [O || O <- Outputs, atom_to_binary(O, utf8) =:= Name] of
        [Out | _] -> op(Out, M);
        [] -> {error, unknown_output}
    end;
event(#{<<"output">> := _}, _) ->
    {error, bad_field};
event(_, _) ->
    {error, no_output}.

op(Out, #{<<"unset">> := true}) ->
    {ok, {unset, [Out]}};
op(_Out, #{<<"unset">> := U}) when U =/= false ->
    {error, bad_field};
op(Out, M = #{<<"value">> := V0}) ->
    case value(maps:get(<<"as">>, M, null), V0) of
        {ok, V} ->
            case {maps:get(<<"latch">>, M, false), maps:get(<<"hold">>, M, null)} of
                {true, null} -> {ok, {set, #{Out => V}}};
                {false, null} -> {ok, {send, #{Out => V}}};
                {false, <<"infinity">>} -> {ok, {send, #{Out => V}, #{hold => infinity}}};
                {false, H} when is_integer(H), H >= 0, H < 1 bsl 32 ->
                    {ok, {send, #{Out => V}, #{hold => H}}};
                _ -> {error, bad_field}
            end;
        error ->
            {error, bad_value}
    end;
op(_Out, _M) ->
    {error, no_value}.

value(null, V) -> {ok, V};
value(<<"tuple">>, L) when is_list(L) -> {ok, list_to_tuple(L)};
value(<<"atom">>, B) when is_binary(B) ->
    try {ok, binary_to_existing_atom(B, utf8)}
    catch error:badarg -> error
    end;
value(_, _) -> error.

%% @doc One JSON object (no newline) for a value delivered to input `Input'.
-spec encode_event(atom(), term()) -> {ok, binary()} | {error, unencodable}.
encode_event(Input, V) ->
    As = if is_tuple(V) -> [{<<"as">>, <<"tuple">>}];
            V =:= true; V =:= false; V =:= null -> [];
            is_atom(V) -> [{<<"as">>, <<"atom">>}];
            true -> []
         end,
    try
        Obj = maps:from_list([{<<"input">>, atom_to_binary(Input, utf8)},
                              {<<"value">>, to_json(V)} | As]),
        {ok, iolist_to_binary(jiffy:encode(Obj))}
    catch
        _:_ -> {error, unencodable}
    end.

to_json(V) when is_number(V); V =:= true; V =:= false; V =:= null -> V;
to_json(V) when is_atom(V) -> atom_to_binary(V, utf8);
to_json(V) when is_binary(V) -> V;            % jiffy refuses non-UTF-8
to_json(V) when is_list(V) -> [to_json(X) || X <- V];
to_json(V) when is_tuple(V) -> [to_json(X) || X <- tuple_to_list(V)];
to_json(V) when is_map(V) -> maps:from_list([{key(K), to_json(X)} || {K, X} <- maps:to_list(V)]);
to_json(V) -> error({unencodable, V}).

key(K) when is_atom(K) -> atom_to_binary(K, utf8);
key(K) when is_binary(K) -> K;
key(K) when is_integer(K) -> integer_to_binary(K);
key(K) -> error({unencodable, K}).
