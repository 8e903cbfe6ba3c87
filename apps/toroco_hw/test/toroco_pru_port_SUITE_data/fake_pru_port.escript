#!/usr/bin/env escript
%%! -noinput
%% A stand-in for the pru_port program, for the owner's tests: it speaks
%% the protocol's framing (PROTOCOL.md) on stdin/stdout, answers `pong' to
%% ping and `ok' to every other request, and appends each frame it receives
%% to DIR/frames.log as `{OsPid, Frame}.' (after `{OsPid, started}.'), DIR
%% being its --sysfs-root. DIR/fake.conf (read at start, optional) changes
%% it: `{hello_after_ms, Ms | never}.' withholds the hello;
%% `{stall, Tag}.' leaves requests `Tag' unanswered. It exits on stdin EOF,
%% and when its owner is gone (a reply into a closed pipe).
main(Args) ->
    process_flag(trap_exit, true),
    Dir = dir(Args),
    Conf = case file:consult(filename:join(Dir, "fake.conf")) of
               {ok, Terms} -> Terms;
               {error, _} -> []
           end,
    Log = filename:join(Dir, "frames.log"),
    log(Log, started),
    P = open_port({fd, 0, 1}, [binary, {packet, 2}, eof]),
    Wait = case proplists:get_value(hello_after_ms, Conf, 0) of
               never -> infinity;
               Ms -> Ms
           end,
    receive
        {P, eof} -> halt(0);
        {'EXIT', P, _} -> halt(0)
    after Wait ->
        port_command(P, term_to_binary({hello, 1, sim}))
    end,
    loop(P, Log, proplists:get_value(stall, Conf)).

loop(P, Log, Stall) ->
    receive
        {P, {data, Bin}} ->
            Frame = binary_to_term(Bin),
            log(Log, Frame),
            case Frame of
                {Ref, Request} ->
                    case tag(Request) of
                        Stall -> ok;
                        ping -> port_command(P, term_to_binary({reply, Ref, pong}));
                        _ -> port_command(P, term_to_binary({reply, Ref, ok}))
                    end;
                _ -> ok
            end,
            loop(P, Log, Stall);
        {P, eof} ->
            halt(0);
        {'EXIT', P, _} ->
            halt(0)
    end.

tag(T) when is_tuple(T) -> element(1, T);
tag(A) -> A.

log(Log, Term) ->
    ok = file:write_file(Log, io_lib:format("~0p.~n", [{list_to_integer(os:getpid()), Term}]),
                         [append]).

dir(["--sysfs-root", Dir | _]) -> Dir;
dir([_ | Rest]) -> dir(Rest);
dir([]) -> ".".
