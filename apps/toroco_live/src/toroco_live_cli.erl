%% @doc The dashboard for `scripts/run' (`make run'): started before the
%% simulated run, from the command line (`erl -s toroco_live_cli start',
%% or `-s toroco_live_cli start toroco_ros' to start the applications
%% built on `toroco_live' too), with its address and token printed on
%% stdout before anything else, and each bridge's address after it (the
%% Foxglove bridge's, the rosbridge server's). When a configured port is
%% taken (another run, another program), it takes any free port instead.
-module(toroco_live_cli).

-export([start/0, start/1]).

%% @doc Starts `toroco_live' and prints the dashboard's URL.
-spec start() -> ok.
start() ->
    start([]).

%% @doc Starts `toroco_live' and then `Apps' (built on it), and prints the
%% dashboard's URL and the bridges' addresses.
-spec start([atom()]) -> ok.
start(Apps) ->
    case ensure_started([toroco_live | Apps]) of
        ok -> print();
        {error, Reason} -> io:format(standard_error, "dashboard: not started: ~0p~n", [Reason])
    end.

ensure_started([]) -> ok;
ensure_started([App | Rest]) ->
    case application:ensure_all_started(App) of
        {ok, _} -> ensure_started(Rest);
        {error, _} = E -> E
    end.

print() ->
    Env = maps:from_list(application:get_all_env(toroco_live)),
    Wanted = [K || {K, _} <- toroco_live_bridge:bridges(), is_integer(maps:get(K, Env, off))],
    Info = toroco_live:info(),
    case is_map(Info) andalso lists:all(fun(K) -> is_integer(maps:get(K, Info)) end, Wanted) of
        true ->
            print(Info);
        false ->
            %% A configured port is taken: any free one will do for a run.
            toroco_live:stop(),
            Opts = (maps:with([ip, token, tls, insecure], Env))#{http => 0},
            Free = maps:from_list([{K, free(maps:get(K, Env, off))}
                                   || {K, _} <- toroco_live_bridge:bridges()]),
            case toroco_live:start(maps:merge(Opts, Free)) of
                {ok, Started} -> print(Started);
                {error, Reason} -> io:format(standard_error, "dashboard: not started: ~0p~n", [Reason])
            end
    end.

print(Info) ->
    io:format("dashboard: ~ts~n", [toroco_live:url()]),
    Ws = case Info of
             #{tls := true} -> "wss";
             _ -> "ws"
         end,
    _ = [io:format("~s: ~s://~s:~b~n", [K, Ws, host(K), Port])
         || {K, _} <- toroco_live_bridge:bridges(), Port <- [maps:get(K, Info, off)],
            is_integer(Port)],
    ok.

%% The Foxglove app resolves `localhost' as the page does.
host(foxglove) -> "localhost";
host(_) -> "127.0.0.1".

free(off) -> off;
free(_) -> 0.
