%% @doc A mouse read through Linux evdev: a sensor whose outputs `left' and
%% `right' send `pressed' and `released' as the buttons go down and up. The
%% thesis' verification programs were driven by one.
%%
%% `toroco:add_device(mouse, toroco_mouse, #{device => "/dev/input/event3"})'.
%% Options: `device', the event device to read (default: the first
%% `/dev/input/by-id/*-event-mouse'); `retry_ms' (default 1000), how long to
%% wait before reopening a device that failed (unplugged, not yet plugged in,
%% no permission: the user must be in group `input'), and how often to look
%% again at the end of a regular file; `event_size', the size of the kernel's
%% `struct input_event' (default `8 + 2 * wordsize', i.e. 24 on a 64-bit
%% system and 16 on the BeagleBone's 32-bit one).
%%
%% A linked reader process does the blocking reads and hands the bytes over;
%% this device decodes whole events with {@link decode/2} (a pure function,
%% keeping an incomplete tail for the next read), sends a button event for
%% each `EV_KEY' of `BTN_LEFT' or `BTN_RIGHT' with value 1 (pressed) or 0
%% (released), and ignores the rest: motion, wheel, sync and auto-repeat. A
%% failing device is logged once and reopened every `retry_ms' until it
%% works; the device process itself never crashes for it. A regular file
%% holding recorded events is read like a device and followed as it grows,
%% which is how the events can be replayed without a mouse.
%%
%% `toroco:inspect(Name)' shows, under `device', the path, whether it is
%% open, and how many bytes, button events and reopenings there were.
%%
%% Stopping the device kills the reader; a read already blocked in the
%% kernel returns (and the file is closed) at the device's next event.
-module(toroco_mouse).
-behaviour(toroco_device).

-export([decode/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).

-define(EV_KEY, 1).
-define(BTN_LEFT, 16#110).
-define(BTN_RIGHT, 16#111).
-define(READ_EVENTS, 64).

-type button_event() :: {left | right, pressed | released}.

%%====================================================================
%% Decoding
%%====================================================================

%% @doc Splits `Bytes' into whole `struct input_event's of `EventSize' bytes
%% (native byte order: a timeval of two longs, then type, code and value) and
%% returns the button events among them, oldest first, with the bytes of an
%% incomplete event left over.
-spec decode(binary(), 16 | 24) -> {[button_event()], binary()}.
decode(Bytes, EventSize) ->
    decode(Bytes, EventSize, []).

decode(Bytes, Size, Acc) when byte_size(Bytes) >= Size ->
    TimeBytes = Size - 8,
    <<_Time:TimeBytes/binary, Type:16/native, Code:16/native, Value:32/native-signed,
      Rest/binary>> = Bytes,
    decode(Rest, Size, button(Type, Code, Value, Acc));
decode(Rest, _Size, Acc) ->
    {lists:reverse(Acc), Rest}.

button(?EV_KEY, Code, Value, Acc) when Code =:= ?BTN_LEFT; Code =:= ?BTN_RIGHT ->
    Button = case Code of
                 ?BTN_LEFT -> left;
                 ?BTN_RIGHT -> right
             end,
    case Value of
        1 -> [{Button, pressed} | Acc];
        0 -> [{Button, released} | Acc];
        _ -> Acc                                % 2: auto-repeat
    end;
button(_Type, _Code, _Value, Acc) ->
    Acc.

%%====================================================================
%% toroco_device
%%====================================================================

-spec interface(map()) -> #{inputs := [], outputs := [left | right]}.
interface(_Opts) -> #{inputs => [], outputs => [left, right]}.

-spec init(atom(), map()) -> {ok, closed, map(), toroco_behavior:actions()} | {error, term()}.
init(Name, Opts) ->
    Size = maps:get(event_size, Opts, 8 + 2 * erlang:system_info(wordsize)),
    Retry = maps:get(retry_ms, Opts, 1000),
    case {device_path(Opts), Size, Retry} of
        {{error, Reason}, _, _} ->
            {error, {Reason, Name}};
        {_, S, _} when S =/= 16, S =/= 24 ->
            {error, {bad_option, {Name, {event_size, S}}}};
        {_, _, R} when not is_integer(R); R < 1 ->
            {error, {bad_option, {Name, {retry_ms, R}}}};
        {{ok, Path}, _, _} ->
            {ok, closed, #{name => Name, path => Path, size => Size, retry => Retry,
                           reader => undefined, rest => <<>>, error => none,
                           bytes => 0, buttons => 0, reopened => 0},
             [{{timeout, open}, 0, open}]}
    end.

device_path(#{device := Path}) when is_list(Path); is_binary(Path) ->
    {ok, Path};
device_path(#{device := Bad}) ->
    {error, {bad_option, {device, Bad}}};
device_path(#{}) ->
    case lists:sort(filelib:wildcard("/dev/input/by-id/*-event-mouse")) of
        [Path | _] -> {ok, Path};
        [] -> {error, no_mouse_found}
    end.

-spec handle_input(atom(), term(), closed | open, map()) -> keep_state_and_data.
handle_input(_Input, _Value, _State, _Data) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), closed | open, map()) ->
          toroco_behavior:result().
handle_event({timeout, open}, open, closed, D = #{path := Path, size := Size, retry := Retry}) ->
    Owner = self(),
    Reader = spawn_link(fun() -> reader(Owner, Path, Size * ?READ_EVENTS, Retry) end),
    {keep_state, D#{reader := Reader, rest := <<>>}};
handle_event(info, {?MODULE, Reader, opened}, closed, D = #{reader := Reader, error := E,
                                                            name := Name, path := Path}) ->
    _ = E =/= none andalso
        logger:notice("toroco_mouse ~p: ~ts readable again", [Name, Path]),
    {next_state, open, D#{error := none}};
handle_event(info, {?MODULE, Reader, Bytes}, _State,
             D = #{reader := Reader, rest := Rest, size := Size, bytes := B, buttons := N}) ->
    {Events, Rest1} = decode(<<Rest/binary, Bytes/binary>>, Size),
    {keep_state, D#{rest := Rest1, bytes := B + byte_size(Bytes), buttons := N + length(Events)},
     [{send, #{Button => Event}} || {Button, Event} <- Events]};
handle_event(info, {'EXIT', Reader, Reason}, _State,
             D = #{reader := Reader, error := E, name := Name, path := Path, retry := Retry,
                   reopened := R}) ->
    Error = reader_error(Reason),
    _ = Error =/= E andalso
        logger:warning("toroco_mouse ~p: cannot read ~ts (~p); retrying every ~p ms",
                       [Name, Path, Error, Retry]),
    {next_state, closed, D#{reader := undefined, error := Error, reopened := R + 1},
     [{{timeout, open}, Retry, open}]}.

reader_error({open_failed, Reason}) -> Reason;
reader_error({read_failed, Reason}) -> Reason;
reader_error(Other) -> Other.

-spec info(closed | open, map()) -> map().
info(State, #{path := Path, error := E, bytes := B, buttons := N, reopened := R}) ->
    #{device => Path, status => State, error => E, bytes => B, button_events => N,
      reopened => R}.

-spec terminate(term(), closed | open, map()) -> ok.
terminate(_Reason, _State, #{reader := Reader}) when is_pid(Reader) ->
    unlink(Reader),
    exit(Reader, kill),
    ok;
terminate(_Reason, _State, _Data) ->
    ok.

%%====================================================================
%% The reader
%%====================================================================

reader(Owner, Path, Chunk, Retry) ->
    case file:open(Path, [read, raw, binary]) of
        {ok, Fd} ->
            Owner ! {?MODULE, self(), opened},
            read_loop(Owner, Fd, Chunk, Retry);
        {error, Reason} ->
            exit({open_failed, Reason})
    end.

%% An event device blocks in read until there are events; a regular file
%% reaches its end, where we look again later, as `tail -f' does.
read_loop(Owner, Fd, Chunk, Retry) ->
    case file:read(Fd, Chunk) of
        {ok, Bytes} ->
            Owner ! {?MODULE, self(), Bytes},
            read_loop(Owner, Fd, Chunk, Retry);
        eof ->
            timer:sleep(Retry),
            read_loop(Owner, Fd, Chunk, Retry);
        {error, Reason} ->
            exit({read_failed, Reason})
    end.
