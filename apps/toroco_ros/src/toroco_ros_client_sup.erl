%% @doc The rosbridge clients (SPEC §15, client mode): one
%% `toroco_ros_client' per server the robot dials, added by
%% `toroco_live:rosbridge_connect/2' and taken away by
%% `toroco_live:rosbridge_disconnect/1'.
%%
%% simple_one_for_one, transient: a client reconnects by itself (its
%% backoff), so the supervisor only restarts one that crashed, and one
%% that was disconnected stays away.
-module(toroco_ros_client_sup).
-behaviour(supervisor).

-export([start_link/0, start_client/2, stop_client/1, clients/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

%% @doc A new client of `Url'.
-spec start_client(binary() | string(), toroco_ros_client:opts()) -> {ok, pid()} | {error, term()}.
start_client(Url, Opts) ->
    supervisor:start_child(?MODULE, [Url, Opts]).

%% @doc Ends a client; `{error, not_found}' when `Pid' is not one.
-spec stop_client(pid()) -> ok | {error, not_found}.
stop_client(Pid) ->
    case lists:member(Pid, clients()) of
        true -> supervisor:terminate_child(?MODULE, Pid);
        false -> {error, not_found}
    end.

%% @doc The clients running.
-spec clients() -> [pid()].
clients() ->
    case whereis(?MODULE) of
        undefined -> [];
        _ -> [Pid || {_, Pid, _, _} <- supervisor:which_children(?MODULE), is_pid(Pid)]
    end.

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    Flags = #{strategy => simple_one_for_one, intensity => 5, period => 10},
    Client = #{id => toroco_ros_client, start => {toroco_ros_client, start_link, []},
               restart => transient, shutdown => 5000},
    {ok, {Flags, [Client]}}.
