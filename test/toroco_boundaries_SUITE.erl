%% The applications' boundaries (STYLE, "Between apps"): the device, robot,
%% library and dashboard applications use the runtime through its API only:
%% `toroco', `toroco_clock', the behaviours a callback implements
%% (`toroco_behavior', `toroco_device') and `toroco_slots' (the bounds of
%% every listener, STYLE "Listeners and clients"). An xref query over the compiled
%% applications finds every call from them into another module of `toroco',
%% and a scan of their sources every include of the runtime's private
%% headers; both must be empty. The suites' support (`toroco_test', its
%% own application so that every application's suites reach it) holds to
%% the same API and is shipped by no release.
-module(toroco_boundaries_SUITE).

-include_lib("common_test/include/ct.hrl").
-include_lib("stdlib/include/assert.hrl").

-compile([export_all, nowarn_export_all]).

-define(API, [toroco, toroco_clock, toroco_behavior, toroco_device, toroco_slots]).
-define(OTHERS, [toroco_hw, torobot, toroco_lib, toroco_live, toroco_lua, toroco_ros, toroco_test]).
%% The suites' support: in apps/, never in a release.
-define(TEST_SUPPORT, toroco_test).
%% What toroco_live documents as its API for the applications built on it
%% (toroco_live's module doc, doc/dashboard.md "Built on toroco_live").
-define(LIVE_API, [toroco_live, toroco_live_listener, toroco_live_ws_conn,
                   toroco_live_ws_frame, toroco_live_clients, toroco_live_tap, toroco_live_bridge,
                   toroco_live_profile, toroco_live_extensions, toroco_live_metrics,
                   toroco_live_json, toroco_live_world, toroco_live_channels, toroco_live_http,
                   toroco_live_auth]).

all() ->
    [no_call_into_the_runtimes_insides, no_include_of_the_runtimes_headers,
     suites_use_the_api_only, ros_uses_the_dashboards_api_only, dashboard_never_calls_ros,
     test_support_is_never_shipped].

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
