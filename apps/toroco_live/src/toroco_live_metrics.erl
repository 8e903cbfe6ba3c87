%% @doc `GET /metrics': the robot in the Prometheus text format (version
%% 0.0.4), every name prefixed `toroco_'.
%%
%% <table>
%% <tr><th>metric</th><th>type</th><th>labels</th></tr>
%% <tr><td>`toroco_emits_total'</td><td>counter</td><td>`emitter', `output': events emitted (from the tap, since the dashboard started)</td></tr>
%% <tr><td>`toroco_deliveries_total'</td><td>counter</td><td>`receiver', `input': events delivered</td></tr>
%% <tr><td>`toroco_restarts_total'</td><td>counter</td><td>`name'</td></tr>
%% <tr><td>`toroco_mailbox_length'</td><td>gauge</td><td>`name'</td></tr>
%% <tr><td>`toroco_up'</td><td>gauge</td><td>`name', `kind', `status' (1 running, 0.5 suspended, 0 down)</td></tr>
%% <tr><td>`toroco_device_counter'</td><td>gauge</td><td>`device', `counter': each numeric device counter</td></tr>
%% <tr><td>`toroco_vm_memory_bytes'</td><td>gauge</td><td>`kind' (`erlang:memory/0'; with ERTS's allocators off, as in the prod release, `total' (resident, from the OS), `processes' and `ets')</td></tr>
%% <tr><td>`toroco_live_clients'</td><td>gauge</td><td>dashboard WebSocket clients</td></tr>
%% <tr><td>`toroco_live_skipped_total'</td><td>counter</td><td>states a slow client did not get (coalesced)</td></tr>
%% <tr><td>`toroco_live_tap_dropped_total'</td><td>counter</td><td>tap events the dashboard fell behind on</td></tr>
%% <tr><td>`toroco_live_foxglove_clients'</td><td>gauge</td><td>Foxglove clients connected</td></tr>
%% <tr><td>`toroco_live_foxglove_subscriptions'</td><td>gauge</td><td>subscriptions of Foxglove clients to channels</td></tr>
%% <tr><td>`toroco_live_connections'</td><td>gauge</td><td>`listener' (`dashboard', `foxglove', and the other bridges: `rosbridge'): TCP connections holding a slot (`toroco_live_listener')</td></tr>
%% <tr><td>`toroco_live_connections_accepted_total'</td><td>counter</td><td>`listener': connections given a slot</td></tr>
%% <tr><td>`toroco_live_connections_closed_total'</td><td>counter</td><td>`listener', `reason': `request_timeout', `idle_timeout', `shed' (for a newcomer), `too_many_from_peer', `too_many_clients' (refused), `tls_handshake' (failed), `ended'</td></tr>
%% <tr><td>`toroco_live_auth_failures_total'</td><td>counter</td><td>wrong tokens or sessions presented (`toroco_live_auth')</td></tr>
%% <tr><td>`toroco_live_auth_limited_total'</td><td>counter</td><td>checks refused: the address failed ten times within a minute</td></tr>
%% <tr><td>`toroco_live_auth_limited_addresses'</td><td>gauge</td><td>addresses refused now</td></tr>
%% </table>
%%
%% Other applications add their families (`toroco_live_extensions', kind
%% `metrics', made with {@link family/4}): `toroco_ros' the rosbridge
%% server's and clients' (`toroco_ros_metrics'). A bridge's listener is
%% among `toroco_live_connections' under its option's name.
-module(toroco_live_metrics).

-export([text/0, family/4]).

%% @doc The whole exposition.
-spec text() -> iodata().
text() ->
    {_Overview, Readings} = toroco_live_state:readings(),
    Stats = toroco_live_hub:stats(),
    [family(toroco_emits_total, counter, "Events emitted per output.",
            [{[{emitter, E}, {output, O}], N}
             || {{E, O}, N} <- lists:sort(maps:to_list(maps:get(emits, Stats, #{})))]),
     family(toroco_deliveries_total, counter, "Events delivered per input.",
            [{[{receiver, R}, {input, I}], N}
             || {{R, I}, N} <- lists:sort(maps:to_list(maps:get(delivers, Stats, #{})))]),
     family(toroco_restarts_total, counter, "Restarts of each behavior and device.",
            [{[{name, N}], R} || #{name := N, restarts := R} <- Readings]),
     family(toroco_mailbox_length, gauge, "Message queue length of each behavior and device.",
            [{[{name, N}], Q} || #{name := N, mailbox := Q} <- Readings, is_integer(Q)]),
     family(toroco_up, gauge, "1 running, 0.5 suspended, 0 down.",
            [{[{name, N}, {kind, maps:get(kind, I, unknown)}, {status, S}], up(S)}
             || #{name := N, info := I} <- Readings, S <- [maps:get(status, I, down)]]),
     family(toroco_device_counter, gauge, "Counters a device keeps.",
            [{[{device, N}, {counter, K}], V}
             || #{name := N, info := #{device := C}} <- Readings, is_map(C),
                {K, V} <- lists:sort(maps:to_list(C)), is_number(V)]),
     family(toroco_vm_memory_bytes, gauge, "Memory of the Erlang VM.",
            [{[{kind, K}], V} || {K, V} <- vm_memory()]),
     family(toroco_live_clients, gauge, "Dashboard WebSocket clients.",
            [{[], maps:get(clients, Stats, 0)}]),
     family(toroco_live_skipped_total, counter, "States coalesced away for slow clients.",
            [{[], maps:get(skipped, Stats, 0)}]),
     family(toroco_live_tap_dropped_total, counter, "Tap events the dashboard fell behind on.",
            [{[], maps:get(tap_dropped, Stats, 0)}])
     | foxglove() ++ listeners() ++ auth() ++ sources()].

%% erlang:memory/0 needs ERTS's allocators: with them off (`+Mea min', the
%% prod release's config/prod/vm.args) it raises `notsup', and the gauge
%% has what is still known: the node's resident size as the OS counts it
%% (Linux; the processes' and tables' sum elsewhere), its processes, its
%% ETS tables.
vm_memory() ->
    try erlang:memory()
    catch error:notsup ->
        Processes = lists:sum([M || P <- processes(), {memory, M} <- [process_info(P, memory)]]),
        Ets = erlang:system_info(wordsize) *
            lists:sum([M || T <- ets:all(), M <- [ets:info(T, memory)], is_integer(M)]),
        [{total, resident(Processes + Ets)}, {processes, Processes}, {ets, Ets}]
    end.

%% /proc/self/statm's second field: resident pages (4 kB on the machines
%% the release runs on: x86-64, armhf).
resident(Otherwise) ->
    case file:read_file("/proc/self/statm") of
        {ok, Statm} ->
            [_, Pages | _] = binary:split(Statm, <<" ">>, [global]),
            4096 * binary_to_integer(Pages);
        {error, _} ->
            Otherwise
    end.

%% What other applications add (toroco_live_extensions, kind `metrics').
sources() ->
    [begin
         {M, F} = Source,
         try M:F() catch Class:Why -> logger:warning("metrics of ~p: ~p:~0p", [Name, Class, Why],
                                                     #{domain => [toroco, live]}), [] end
     end || {Name, Source} <- toroco_live_extensions:all(metrics)].

%% The token checks (toroco_live_auth), while the dashboard runs.
auth() ->
    case toroco_live_auth:stats() of
        #{failures := F, limited := L, banned_now := B} ->
            [family(toroco_live_auth_failures_total, counter,
                    "Wrong tokens or sessions presented, on any port.", [{[], F}]),
             family(toroco_live_auth_limited_total, counter,
                    "Token checks refused because the address failed too often.", [{[], L}]),
             family(toroco_live_auth_limited_addresses, gauge,
                    "Addresses whose token checks are refused now.", [{[], B}])];
        #{} -> []
    end.

%% The Foxglove bridge's clients, when it runs.
foxglove() ->
    case toroco_live_foxglove:stats() of
        Stats when map_size(Stats) =:= 0 -> [];
        #{clients := Clients, subscriptions := Subs} ->
            [family(toroco_live_foxglove_clients, gauge, "Foxglove clients connected.",
                    [{[], Clients}]),
             family(toroco_live_foxglove_subscriptions, gauge,
                    "Subscriptions of Foxglove clients to channels.", [{[], Subs}])]
    end.

%% The bounded ports (`toroco_live_listener'), those that run.
listeners() ->
    Ports = [{L, S} || {L, Name} <- [{dashboard, toroco_live_http}
                                     | [{Key, Listener}
                                        || {Key, #{listener := Listener}} <- toroco_live_bridge:bridges()]],
                       S <- listener_stats(Name)],
    [family(toroco_live_connections, gauge, "TCP connections holding a slot, per port.",
            [{[{listener, L}], N} || {L, #{connections := N}} <- Ports]),
     family(toroco_live_connections_accepted_total, counter, "Connections given a slot.",
            [{[{listener, L}], N} || {L, #{accepted := N}} <- Ports]),
     family(toroco_live_connections_closed_total, counter,
            "Connections closed or refused, by reason.",
            [{[{listener, L}, {reason, R}], N} || {L, #{closed_by := By}} <- Ports,
                                                  {R, N} <- lists:sort(maps:to_list(By))])].

listener_stats(Name) ->
    case whereis(Name) of
        undefined -> [];
        _ ->
            try [toroco_live_listener:stats(Name)]
            catch exit:_ -> []
            end
    end.

up(running) -> 1;
up(suspended) -> 0.5;
up(_) -> 0.

%% @doc A metric family in the Prometheus text format: its `Name', `Type'
%% (`gauge', `counter'), one line of `Help', and its samples, each its
%% labels and value. For other applications' sources (`metrics' in
%% `toroco_live_extensions').
-spec family(atom(), gauge | counter, string(), [{[{atom(), term()}], number()}]) -> iodata().
family(Name, Type, Help, Samples) ->
    [io_lib:format("# HELP ~s ~s~n# TYPE ~s ~s~n", [Name, Help, Name, Type]),
     [[atom_to_list(Name), labels(Ls), " ", number(V), "\n"] || {Ls, V} <- Samples]].

labels([]) -> "";
labels(Ls) ->
    ["{", lists:join(",", [[atom_to_list(K), "=\"", escape(label(V)), "\""] || {K, V} <- Ls]), "}"].

label(V) when is_atom(V) -> atom_to_list(V);
label(V) when is_binary(V) -> unicode:characters_to_list(V);
label(V) -> io_lib:format("~0tp", [V]).

escape(S) ->
    lists:flatmap(fun($\\) -> "\\\\"; ($") -> "\\\""; ($\n) -> "\\n"; (C) -> [C] end,
                  lists:flatten(S)).

number(V) when is_integer(V) -> integer_to_list(V);
number(V) when is_float(V) -> float_to_list(V, [short]).
