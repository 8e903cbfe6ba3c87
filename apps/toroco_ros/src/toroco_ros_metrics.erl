%% @doc What `toroco_ros' adds to `GET /metrics' (a `metrics' source of
%% `toroco_live_extensions', made with `toroco_live_metrics:family/4'):
%% the rosbridge server's counters while it runs, and each rosbridge
%% client's (SPEC §15).
%%
%% <table>
%% <tr><th>metric</th><th>type</th><th>labels</th></tr>
%% <tr><td>`toroco_live_rosbridge_clients'</td><td>gauge</td><td>rosbridge clients connected</td></tr>
%% <tr><td>`toroco_live_rosbridge_subscriptions'</td><td>gauge</td><td>subscriptions of rosbridge clients to topics</td></tr>
%% <tr><td>`toroco_live_rosbridge_total'</td><td>counter</td><td>`counter': the rosbridge server's totals (`toroco_ros_server:stats/0': `connections', `messages', `dropped', `tap_dropped', `published', `publish_dropped', `refused_unauthorized', `faults', `disconnected', `fragments_expired')</td></tr>
%% <tr><td>`toroco_live_rosclient_connected'</td><td>gauge</td><td>`url': a rosbridge client (SPEC §15, client mode), 1 connected, 0 dialling or waiting to</td></tr>
%% <tr><td>`toroco_live_rosclient_attempts'</td><td>gauge</td><td>`url': failed attempts since it was last connected</td></tr>
%% <tr><td>`toroco_live_rosclient_connects_total'</td><td>counter</td><td>`url': connections made</td></tr>
%% <tr><td>`toroco_live_rosclient_sent_total'</td><td>counter</td><td>`url': the robot's messages published there</td></tr>
%% <tr><td>`toroco_live_rosclient_received_total'</td><td>counter</td><td>`url': messages received on inbound topics</td></tr>
%% <tr><td>`toroco_live_rosclient_dropped_total'</td><td>counter</td><td>`url': the robot's messages not sent (queue full, connection lost)</td></tr>
%% <tr><td>`toroco_live_rosclient_refused_total'</td><td>counter</td><td>`url': received messages that did not fit their type</td></tr>
%% </table>
-module(toroco_ros_metrics).

-export([families/0]).

-define(TOTALS, [connections, messages, dropped, tap_dropped, published, publish_dropped,
                 refused_unauthorized, faults, disconnected, fragments_expired]).

%% @doc The families, as `toroco_live_metrics' asks for them.
-spec families() -> iodata().
families() ->
    [server(), clients()].

%% The rosbridge server's counters, when it runs.
server() ->
    case whereis(toroco_ros_server) of
        undefined -> [];
        _ ->
            Stats = toroco_ros_server:stats(),
            [family(toroco_live_rosbridge_clients, gauge, "rosbridge clients connected.",
                    [{[], maps:get(clients, Stats, 0)}]),
             family(toroco_live_rosbridge_subscriptions, gauge, "Subscriptions of rosbridge clients to topics.",
                    [{[], maps:get(subscriptions, Stats, 0)}]),
             family(toroco_live_rosbridge_total, counter, "The rosbridge server's totals.",
                    [{[{counter, K}], maps:get(K, Stats, 0)} || K <- ?TOTALS])]
    end.

%% The rosbridge clients (toroco_ros_client).
clients() ->
    Clients = toroco_ros:clients(),
    Each = fun(Key) -> [{[{url, U}], maps:get(Key, C)} || #{url := U} = C <- Clients] end,
    [family(toroco_live_rosclient_connected, gauge, "A rosbridge client: 1 connected, 0 not.",
            [{[{url, U}], case S of connected -> 1; _ -> 0 end} || #{url := U, state := S} <- Clients]),
     family(toroco_live_rosclient_attempts, gauge, "Failed attempts since last connected.",
            Each(attempts)),
     family(toroco_live_rosclient_connects_total, counter, "Connections made.", Each(connects)),
     family(toroco_live_rosclient_sent_total, counter, "Messages published to the server.",
            Each(sent)),
     family(toroco_live_rosclient_received_total, counter, "Messages received on inbound topics.",
            Each(received)),
     family(toroco_live_rosclient_dropped_total, counter, "The robot's messages not sent.",
            Each(dropped)),
     family(toroco_live_rosclient_refused_total, counter, "Received messages refused.",
            Each(refused))].

family(Name, Type, Help, Samples) ->
    toroco_live_metrics:family(Name, Type, Help, Samples).
