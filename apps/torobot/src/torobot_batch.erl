-module(torobot_batch).
-export([run/1]).
-export_type([opts/0, report/0]).
-type opts() :: map().
-type report() :: map().
-spec run(opts()) -> {ok, report()} | {error, term()}.
run(_) -> {error, todo}.
