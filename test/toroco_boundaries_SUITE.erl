%% The applications' boundaries (STYLE, "Between apps"): the device, robot,
%% library and dashboard applications use the runtime through its API only:
%% `toroco', `toroco_clock', the behaviours a callback implements
%% (`toroco_behavior', `toroco_device') and `toroco_slots' (the bounds of
%% every listener, STYLE "Listeners and clients"). An xref query over the compiled
%% applications finds every call from them into another module of `toroco',
%% and a scan of their sources every include of the runtime's private
%% headers; both must be empty. No application sends to a process another
%% application registers under one of its module names (what they say to
%% each other goes through an API: the simulated world's snapshots through
%% `toroco:publish_world/1'). And no module of `apps/*/src' is over 600
%% lines, no function over 60 (`scripts/sizes'), but for the exceptions
%% listed here with their reason. The suites' support (`toroco_test', its
%% own application so that every application's suites reach it) holds to
%% the same API and is shipped by no release.
-module(toroco_boundaries_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-define(API, [toroco, toroco_clock, toroco_behavior, toroco_device, toroco_slots]).
-define(OTHERS, [toroco_hw, torobot, toroco_lib, toroco_rec, toroco_live, toroco_lua,
                 toroco_ros, toroco_test]).
%% The suites' support: in apps/, never in a release.
-define(TEST_SUPPORT, toroco_test).
%% What toroco_live documents as its API for the applications built on it
%% (toroco_live's module doc, doc/dashboard.md "Built on toroco_live").
-define(LIVE_API, [toroco_live, toroco_live_listener, toroco_live_ws_conn,
                   toroco_live_ws_frame, toroco_live_clients, toroco_live_bridge,
                   toroco_live_extensions, toroco_live_metrics, toroco_live_world,
                   toroco_live_http, toroco_live_auth, toroco_live_digest]).
%% What toroco_rec documents as its API for the applications built on it
%% (toroco_rec's module doc, doc/recording.md "Built on toroco_rec").
-define(REC_API, [toroco_rec, toroco_rec_json, toroco_rec_channels, toroco_rec_tap,
                  toroco_rec_mcap, toroco_rec_profile, toroco_rec_world]).

%% Over the sizes STYLE allows, each with why (none today).
-define(SIZE_EXCEPTIONS, []).

all() ->
    [no_call_into_the_runtimes_insides, no_include_of_the_runtimes_headers,
     suites_use_the_api_only, ros_uses_the_dashboards_api_only, dashboard_never_calls_ros,
     live_and_ros_use_the_records_api_only, records_never_call_live_nor_ros,
     no_send_to_another_apps_process, sizes_within_bounds, test_support_is_never_shipped].

no_call_into_the_runtimes_insides() ->
    [{doc, "No call from toroco_hw, torobot, toroco_lib, toroco_live, toroco_lua, toroco_ros or "
      "toroco_test reaches a module of "
      "toroco outside its API (toroco, toroco_clock, toroco_behavior, toroco_device, "
      "toroco_slots)."}].
no_call_into_the_runtimes_insides(_Config) ->
    {ok, X} = xref:start([{xref_mode, functions}]),
    try
        ok = xref:set_default(X, [{warnings, false}, {verbose, false}]),
        [{ok, App} = xref:add_application(X, code:lib_dir(App), [{name, App}])
         || App <- [toroco | ?OTHERS]],
        Query = lists:flatten(
                  io_lib:format("(E | ~w : App) || (toroco : App - ~w : Mod)", [?OTHERS, ?API])),
        {ok, Calls} = xref:q(X, Query),
        ct:log("~s~n~p", [Query, Calls]),
        ?assertEqual([], Calls)
    after
        xref:stop(X)
    end.

ros_uses_the_dashboards_api_only() ->
    [{doc, "toroco_ros calls toroco_live only through the modules toroco_live documents as "
      "its API"}].
ros_uses_the_dashboards_api_only(_Config) ->
    Query = lists:flatten(io_lib:format("(E | toroco_ros : App) || (toroco_live : App - ~w : Mod)",
                                        [?LIVE_API])),
    ?assertEqual([], xref_query([toroco_live, toroco_ros], Query)).

dashboard_never_calls_ros() ->
    [{doc, "No call from toroco_live reaches toroco_ros (the dependency goes one way)"}].
dashboard_never_calls_ros(_Config) ->
    ?assertEqual([], xref_query([toroco_live, toroco_ros],
                                "(E | toroco_live : App) || toroco_ros : App")).

live_and_ros_use_the_records_api_only() ->
    [{doc, "toroco_live and toroco_ros call toroco_rec only through the modules toroco_rec "
      "documents as its API"}].
live_and_ros_use_the_records_api_only(_Config) ->
    Query = lists:flatten(
              io_lib:format("(E | [toroco_live, toroco_ros] : App) || (toroco_rec : App - ~w : Mod)",
                            [?REC_API])),
    ?assertEqual([], xref_query([toroco_rec, toroco_live, toroco_ros], Query)).

records_never_call_live_nor_ros() ->
    [{doc, "No call from toroco_rec reaches toroco_live or toroco_ros (they are built on it, "
      "the dependency goes one way)"}].
records_never_call_live_nor_ros(_Config) ->
    ?assertEqual([], xref_query([toroco_rec, toroco_live, toroco_ros],
                                "(E | toroco_rec : App) || [toroco_live, toroco_ros] : App")).

xref_query(Apps, Query) ->
    {ok, X} = xref:start([{xref_mode, functions}]),
    try
        ok = xref:set_default(X, [{warnings, false}, {verbose, false}]),
        [{ok, App} = xref:add_application(X, code:lib_dir(App), [{name, App}]) || App <- Apps],
        {ok, Calls} = xref:q(X, Query),
        ct:log("~s~n~p", [Query, Calls]),
        Calls
    after
        xref:stop(X)
    end.

no_include_of_the_runtimes_headers() ->
    [{doc, "No source of the other applications includes a header from apps/toroco/src."}].
no_include_of_the_runtimes_headers(_Config) ->
    Offending = [{File, Line}
                 || App <- ?OTHERS,
                    File <- filelib:wildcard(filename:join([code:lib_dir(App), "src", "*.[eh]rl"])),
                    Line <- lines(File),
                    re:run(Line, "-include(_lib)?\\(\"toroco/src/|toroco_wire\\.hrl") =/= nomatch],
    ?assertEqual([], Offending).

lines(File) ->
    {ok, Bin} = file:read_file(File),
    binary:split(Bin, <<"\n">>, [global]).

suites_use_the_api_only() ->
    [{doc, "The other applications' suites (and their test modules) call the runtime only "
      "through its API, as their code does, and include none of its private headers; "
      "the suites' support (toroco_test) is not the runtime."}].
suites_use_the_api_only(_Config) ->
    _ = application:load(toroco),
    {ok, Modules} = application:get_key(toroco, modules),
    Inside = Modules -- ?API,
    Root = toroco_test_lib:root(),
    Tests = lists:append([filelib:wildcard(filename:join([Root, "apps", App, "test", "*.erl"]))
                          || App <- ?OTHERS]),
    ?assertNotEqual([], Tests, Root),
    Offending = [{filename:basename(File), Mod}
                 || File <- Tests,
                    {ok, Bin} <- [file:read_file(File)],
                    {match, Ms} <- [re:run(Bin, "\\b(toroco_[a-z0-9_]+):[a-z]",
                                           [global, {capture, all_but_first, list}])],
                    Mod <- lists:usort([list_to_atom(M) || [M] <- Ms]),
                    lists:member(Mod, Inside)]
        ++ [{filename:basename(File), header}
            || File <- Tests, Line <- lines(File),
               re:run(Line, "-include(_lib)?\\(\"toroco/src/|toroco_wire\\.hrl") =/= nomatch],
    ?assertEqual([], Offending).

no_send_to_another_apps_process() ->
    [{doc, "No source of an application sends (!, erlang:send, gen_server/gen_statem/gen_event "
      "calls and casts) to a name that is a module of another application, nor looks up "
      "(whereis) such a name of an application it does not depend on."}].
no_send_to_another_apps_process(_Config) ->
    Apps = [toroco | ?OTHERS],
    _ = [application:load(App) || App <- Apps],
    Owner = maps:from_list([{M, App} || App <- Apps,
                                        {ok, Ms} <- [application:get_key(App, modules)], M <- Ms]),
    Offending = [{filename:basename(File), Line, How, Name}
                 || App <- Apps,
                    {ok, Deps} <- [application:get_key(App, applications)],
                    File <- filelib:wildcard(filename:join([code:lib_dir(App), "src", "*.erl"])),
                    {How, Name, Line} <- addressed(tokens(File)),
                    Other <- [maps:get(Name, Owner, App)], Other =/= App,
                    How =/= whereis orelse not lists:member(Other, Deps)],
    ?assertEqual([], Offending).

tokens(File) ->
    {ok, Bin} = file:read_file(File),
    {ok, Tokens, _} = erl_scan:string(unicode:characters_to_list(Bin)),
    Tokens.

%% The atoms a source sends to or looks up, with how and on which line.
addressed([{atom, L, Name}, {'!', _} | Rest]) ->
    [{send, Name, L} | addressed(Rest)];
addressed([{'{', _}, {atom, L, Name}, {',', _}, _, {'}', _}, {'!', _} | Rest]) ->
    [{send, Name, L} | addressed(Rest)];
addressed([{atom, _, Mod}, {':', _}, {atom, _, F}, {'(', _}, {atom, L, Name} | Rest]) ->
    case sends(Mod, F) of
        true -> [{send, Name, L} | addressed(Rest)];
        false when Mod =:= erlang, F =:= whereis -> [{whereis, Name, L} | addressed(Rest)];
        false -> addressed(Rest)
    end;
addressed([{atom, _, whereis}, {'(', _}, {atom, L, Name} | Rest]) ->
    [{whereis, Name, L} | addressed(Rest)];
addressed([_ | Rest]) ->
    addressed(Rest);
addressed([]) ->
    [].

sends(erlang, send) -> true;
sends(Gen, F) when Gen =:= gen_server; Gen =:= gen_statem; Gen =:= gen_event ->
    lists:member(F, [call, cast, send_request, notify, sync_notify]);
sends(_, _) -> false.

sizes_within_bounds() ->
    [{doc, "scripts/sizes finds no module of apps/*/src over 600 lines and no function over "
      "60 but for the listed exceptions (an exception no longer over is logged, to be removed)."}].
sizes_within_bounds(_Config) ->
    Root = toroco_test_lib:root(),
    Script = filename:join([Root, "scripts", "sizes"]),
    Out = os:cmd("cd " ++ Root ++ " && escript " ++ Script ++ " --terms; echo rc=$?"),
    ct:log("~s", [Out]),
    {match, [Rc]} = re:run(Out, "rc=([0-9]+)\\s*$", [{capture, all_but_first, list}]),
    ?assert(lists:member(Rc, ["0", "1"]), Out),
    Found = [case T of
                 {module, Path, _} -> {module, Path};
                 {function, Path, NA, _} -> {function, Path, NA}
             end || T <- terms(Out)],
    ct:log("exceptions within bounds now (remove them): ~p", [?SIZE_EXCEPTIONS -- Found]),
    ?assertEqual([], Found -- ?SIZE_EXCEPTIONS).

%% The script's findings, one term a line.
terms(Out) ->
    [begin
         {ok, Ts, _} = erl_scan:string(Line),
         {ok, T} = erl_parse:parse_term(Ts),
         T
     end || Line <- string:split(Out, "\n", all), lists:prefix("{", Line)].

test_support_is_never_shipped() ->
    [{doc, "No release of rebar.config, under any profile, names toroco_test (the suites' "
      "support), and no other application lists it among its applications"}].
test_support_is_never_shipped(_Config) ->
    {ok, Terms} = file:consult(filename:join(toroco_test_lib:root(), "rebar.config")),
    Releases = releases(Terms),
    %% the default release, the prod profile's
    ?assert(length(Releases) >= 2, Releases),
    ?assertEqual([], [Rel || {Rel, Apps} <- Releases, App <- Apps, app_name(App) =:= ?TEST_SUPPORT]),
    Needing = [App || App <- [toroco | ?OTHERS] -- [?TEST_SUPPORT],
                      _ <- [application:load(App)],
                      Key <- [applications, included_applications],
                      {ok, Needs} <- [application:get_key(App, Key)],
                      lists:member(?TEST_SUPPORT, Needs)],
    ?assertEqual([], Needing).

%% Every {release, {Name, Vsn}, Apps} anywhere in the terms of rebar.config.
releases({release, Rel, Apps}) when is_list(Apps) -> [{Rel, Apps}];
releases(T) when is_tuple(T) -> releases(tuple_to_list(T));
releases(L) when is_list(L) -> lists:append([releases(X) || X <- L]);
releases(_) -> [].

app_name({App, _}) -> App;
app_name({App, _, _}) -> App;
app_name(App) -> App.
