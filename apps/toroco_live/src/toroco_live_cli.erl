%% @doc The dashboard for `scripts/run' (`make run'): started before the
%% simulated run, from the command line (`erl -s toroco_live_cli start'),
%% with its address and token printed on stdout before anything else, and
%% the Foxglove bridge's and the rosbridge server's addresses after it.
%% When the configured port is taken (another run, another program), it
%% takes any free port instead and says so.
-module(toroco_live_cli).

-export([start/0]).

%% @doc Starts `toroco_live' and prints the dashboard's URL.
-spec start() -> ok.
start() ->
    case application:ensure_all_started(toroco_live) of
        {ok, _} -> print();
        {error, Reason} -> io:format(standard_error, "dashboard: not started: ~0p~n", [Reason])
    end.

print() ->
    case toroco_live:url() of
        not_running ->
            %% The app env's port is taken: any free one will do for a run.
            Env = maps:from_list(application:get_all_env(toroco_live)),
            Opts = (maps:with([ip, token, foxglove, rosbridge, tls, insecure], Env))#{http => 0},
            case toroco_live:start(Opts#{foxglove => free(maps:get(foxglove, Opts, off)),
                                         rosbridge => free(maps:get(rosbridge, Opts, off))}) of
                {ok, _} -> print();
                {error, Reason} -> io:format(standard_error, "dashboard: not started: ~0p~n", [Reason])
            end;
        Url ->
            io:format("dashboard: ~ts~n", [Url]),
            Info = toroco_live:info(),
            Ws = case Info of
                     #{tls := true} -> "wss";
                     _ -> "ws"
                 end,
            case Info of
                #{foxglove := Port} when is_integer(Port) ->
                    io:format("foxglove: ~s://localhost:~b~n", [Ws, Port]);
                _ -> ok
            end,
            case Info of
                #{rosbridge := Ros} when is_integer(Ros) ->
                    io:format("rosbridge: ~s://127.0.0.1:~b~n", [Ws, Ros]);
                _ -> ok
            end
    end.

free(off) -> off;
free(_) -> 0.
