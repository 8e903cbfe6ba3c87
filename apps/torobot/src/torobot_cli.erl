%% @doc The Erlang side of `scripts/run': runs one world with
%% `torobot_sim', prints the live status and the summary, and ends the node
%% with an exit status.
%%
%% Output (stdout): a status line each simulated second (rewritten in place
%% on a terminal), the path of the SVG, and the summary as one JSON object
%% on the last line. Exit status 0 after a run, 1 when the run failed, 2
%% for a bad world or wiring file; the reason goes to stderr.
-module(torobot_cli).

-export([main/1, format_error/1, await_node/2]).

%% @doc `[WorldFile, SvgFile, Status, WiringFile]', then optionally
%% `Speed', `Time' (`realtime' or `lockstep'), a trace path (lockstep) and
%% the main.lua of a program for the original Torocó (SPEC §16), as `erl
%% -run' passes them (an empty one for none); `Status' is `tty' (rewrite one line) or
%% `lines'. Never returns.
-spec main([string()]) -> no_return().
main([World, Svg, Status, Wiring]) ->
    main([World, Svg, Status, Wiring, "1"]);
main([World, Svg, Status, Wiring, Speed]) ->
    main([World, Svg, Status, Wiring, Speed, "realtime"]);
main([World, Svg, Status, Wiring, Speed, Time]) ->
    main([World, Svg, Status, Wiring, Speed, Time, ""]);
main([World, Svg, Status, Wiring, Speed, Time, Trace]) ->
    main([World, Svg, Status, Wiring, Speed, Time, Trace, ""]);
main([World, Svg, Status, Wiring, Speed, Time, Trace, Lua]) ->
    Base0 = #{svg => Svg, wiring => Wiring,
             status => case Status of
                           "tty" -> tty;
                           _ -> true
                       end},
    Base = case Lua of
               "" -> Base0;
               _ -> Base0#{lua => Lua}
           end,
    Opts = case {Time, Trace} of
               {"lockstep", ""} -> Base#{time => lockstep};
               {"lockstep", _} -> Base#{time => lockstep, trace => Trace};
               _ -> Base#{speed => speed(Speed)}
           end,
    case torobot_sim:run(World, Opts) of
        {ok, Summary} ->
            io:format("svg: ~ts~n~s~n", [Svg, torobot_sim:summary_json(Summary)]),
            halt(0);
        {error, Reason} when element(1, Reason) =:= world; element(1, Reason) =:= wiring;
                             element(1, Reason) =:= speed ->
            io:format(standard_error, "torobot: ~ts~n", [format_error(Reason)]),
            halt(2);
        {error, Reason} ->
            io:format(standard_error, "torobot: ~ts~n", [format_error(Reason)]),
            halt(1)
    end;
main(Args) ->
    io:format(standard_error, "torobot: bad arguments ~p~n", [Args]),
    halt(2).

speed(Text) ->
    case {string:to_integer(Text), string:to_float(Text)} of
        {{I, ""}, _} -> I;
        {_, {F, ""}} -> F;
        _ -> Text
    end.

%% @doc Waits until `Node' answers and runs toroco's wiring server (the
%% laptop node of `make run SPLIT=1'), at most `TimeoutMs'; halts with 2
%% if it never does.
-spec await_node(node(), non_neg_integer()) -> ok.
await_node(Node, TimeoutMs) ->
    Up = net_adm:ping(Node) =:= pong andalso
        is_pid(erpc:call(Node, erlang, whereis, [toroco_wiring], 1000)),
    case Up of
        true -> ok;
        false when TimeoutMs =< 0 ->
            io:format(standard_error, "torobot: node ~p did not come up~n", [Node]),
            halt(2);
        false -> timer:sleep(100), await_node(Node, TimeoutMs - 100)
    end.

%% @doc A one-line human reading of a `torobot_sim:run/2' error.
-spec format_error(term()) -> unicode:chardata().
format_error({world, File, {file, Why}}) ->
    io_lib:format("cannot read world file ~ts: ~ts", [File, file_reason(Why)]);
format_error({world, File, Reason}) ->
    io_lib:format("bad world file ~ts: ~ts", [File, world_reason(Reason)]);
format_error({wiring, File, Why}) ->
    io_lib:format("cannot read wiring file ~ts: ~ts", [File, file_reason(Why)]);
format_error({speed, Speed}) ->
    io_lib:format("bad speed ~0p: a number above 0", [Speed]);
format_error(Reason) ->
    io_lib:format("the run failed: ~0p", [Reason]).

file_reason({Line, Module, Desc}) when is_integer(Line) ->
    io_lib:format("line ~b: ~ts", [Line, Module:format_error(Desc)]);
file_reason(Posix) when is_atom(Posix) ->
    file:format_error(Posix);
file_reason(Other) ->
    io_lib:format("~0p", [Other]).

world_reason({bad_term, Term}) -> io_lib:format("bad term ~0p", [Term]);
world_reason({duplicate, Term}) -> io_lib:format("~0p given twice", [Term]);
world_reason({missing, Key}) -> io_lib:format("no ~s term", [Key]);
world_reason({outside_arena, Term}) -> io_lib:format("~0p lies outside the arena", [Term]);
world_reason({several_robots, Names}) ->
    io_lib:format("several robots ~0p where one is expected", [Names]);
world_reason({blocked_start, Robot, Obstacle}) ->
    io_lib:format("~0p starts overlapping ~0p", [Robot, Obstacle]);
world_reason(Other) -> io_lib:format("~0p", [Other]).
