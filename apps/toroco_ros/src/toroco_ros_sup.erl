%% @doc The root of `toroco_ros'.
%%
%% ```
%% toroco_ros_sup (one_for_one)
%%   toroco_ros_server        the rosbridge v2 server's hub (a toroco_live_bridge):
%%                            a process while toroco_live's dashboard runs with
%%                            the option `rosbridge' a port
%%   toroco_ros_client_sup    the rosbridge clients, one per server dialled
%% '''
%%
%% one_for_one: the server and the clients are independent views of the
%% robot; one crashing takes neither the other nor `toroco_live' with it.
-module(toroco_ros_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    Flags = #{strategy => one_for_one, intensity => 5, period => 10},
    Server = toroco_live_bridge:child_spec(rosbridge, toroco_ros_server),
    Clients = #{id => toroco_ros_client_sup, start => {toroco_ros_client_sup, start_link, []},
                type => supervisor},
    {ok, {Flags, [Server, Clients]}}.
