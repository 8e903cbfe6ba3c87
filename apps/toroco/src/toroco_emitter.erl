%% @doc The emitter end of every wire a behavior or device feeds: per
%% output, the addresses of its consumers (routers or a gate) and its latch.
%% It runs inside the engine (`toroco_behavior'), which calls it when its
%% callback module emits, when consumers attach or detach, and when remote
%% consumers are due to hear from it.
%%
%% Consumers subscribe with a handshake (see `toroco_wire'), so the
%% subscriber lists change without a central server on the event path. On
%% start the emitter says `hello' to its consumers: nothing of the previous
%% incarnation survives. Open ports (a Lua behavior's): an output comes into
%% being when it is emitted on or subscribed to.
%%
%% Functions: {@link new/3}, {@link announce/1}; the event path: {@link
%% send/4}, {@link set/3}, {@link unset/3}, {@link emit/4}; the wiring:
%% {@link subscribed/3}, {@link unsubscribed/3}, {@link beat/1}; what the
%% engine shows: {@link latches/1}, {@link outputs/1}.
-module(toroco_emitter).

-include("toroco_wire.hrl").

-export([new/3, announce/1, tap/2]).
-export([send/4, set/3, unset/3, emit/4]).
-export([subscribed/3, unsubscribed/3, beat/1]).
-export([latches/1, outputs/1, has/2]).
-export_type([emitter/0]).
%% A step of every emission, inlined: the event path's calls are its cost.
-compile({inline, [relatch/3]}).

-record(em, {name :: atom(),
             %% declared output -> the addresses of its consumers
             outputs = #{} :: #{atom() => [toroco_wire:address()]},
             latches = #{} :: #{atom() => term()},
             open = false :: boolean(),
             %% the observer tap's emit sinks, if any
             sinks = [] :: list(),
             %% emissions on undeclared outputs: when last logged, how many since
             undeclared = {never, 0} :: {never | integer(), non_neg_integer()}}).

-opaque emitter() :: #em{}.

-define(LOG, #{domain => [toroco, engine]}).
-define(WARN_INTERVAL_MS, 1000).

%% @doc The emitter `Name', its outputs and their consumers' addresses.
-spec new(atom(), #{atom() => [toroco_wire:address()]}, boolean()) -> emitter().
new(Name, Outputs, Open) ->
    #em{name = Name, outputs = Outputs, open = Open}.

%% @doc Announces this incarnation to every consumer.
-spec announce(emitter()) -> ok.
announce(#em{name = Name, outputs = Outs}) ->
    maps:foreach(fun(Out, Consumers) ->
                         send_all(Consumers, ?WIRE_HELLO(emitter, {Name, Out}, self()))
                 end, Outs).

%% @doc Keeps the `emit' sinks of the observer tap's sinks `Tap'.
-spec tap(toroco_tap:sinks(), emitter()) -> emitter().
tap(Tap, Em) ->
    Em#em{sinks = maps:get(emit, Tap, [])}.

%%====================================================================
%% The event path
%%====================================================================

%% @doc `{send, Map}' (`Hold' is `default') or with a hold.
-spec send(map(), default | infinity | non_neg_integer(), emitter(), toroco_shell:shell()) ->
          {emitter(), toroco_shell:shell()}.
send(Map, Hold, Em, Sh) ->
    %% A list of the map's pairs, walked without a fun: an action's map has
    %% one or two outputs, where an iterator costs more than the walk.
    each(maps:to_list(Map), Hold, Em, Sh).

%% @doc `{set, Map}'.
-spec set(map(), emitter(), toroco_shell:shell()) -> {emitter(), toroco_shell:shell()}.
set(Map, Em, Sh) ->
    each(maps:to_list(Map), set, Em, Sh).

%% @doc `{unset, Outs}', or `all' of them.
-spec unset([atom()] | all, emitter(), toroco_shell:shell()) -> {emitter(), toroco_shell:shell()}.
unset(all, Em = #em{outputs = Outs}, Sh) ->
    unset(maps:keys(Outs), Em, Sh);
unset([], Em, Sh) ->
    {Em, Sh};
unset([Out | Outs], Em, Sh) ->
    {Em1, Sh1} = emit(Out, unset, Em, Sh),
    unset(Outs, Em1, Sh1).

each([], _How, Em, Sh) -> {Em, Sh};
each([{Out, V} | T], set, Em, Sh) ->
    {Em1, Sh1} = emit(Out, {set, V}, Em, Sh),
    each(T, set, Em1, Sh1);
each([{Out, V} | T], Hold, Em, Sh) ->
    {Em1, Sh1} = emit(Out, {send, V, Hold}, Em, Sh),
    each(T, Hold, Em1, Sh1).

%% @doc One emission on one output: to every consumer, in order; the latch
%% follows; the observer's event into the shell.
-spec emit(atom(), toroco_router_core:op(), emitter(), toroco_shell:shell()) ->
          {emitter(), toroco_shell:shell()}.
emit(Out, Op, Em = #em{outputs = Outs, name = Name}, Sh) ->
    case Outs of
        #{Out := Consumers} ->
            send_all(Consumers, ?WIRE_EVENT({Name, Out}, Op)),
            case Em#em.sinks of
                [] -> {relatch(Out, Op, Em), Sh};
                Sinks -> {relatch(Out, Op, Em), toroco_shell:tap(Sinks, event(Name, Out, Op), Sh)}
            end;
        #{} when Em#em.open, is_atom(Out) ->
            emit(Out, Op, Em#em{outputs = Outs#{Out => []}}, Sh);
        #{} ->
            {undeclared(Out, Em), Sh}
    end.

%% An emission on an undeclared output is dropped, and said at most once a
%% second per behavior, with how many were held back since.
undeclared(Out, Em = #em{name = Name, undeclared = {Last, Held}}) ->
    Now = erlang:monotonic_time(millisecond),
    case Last =:= never orelse Now - Last >= ?WARN_INTERVAL_MS of
        true ->
            logger:warning("toroco: ~p emitted on undeclared output ~p; dropped~ts",
                           [Name, Out, case Held of
                                           0 -> "";
                                           _ -> io_lib:format(" (~b more since the last warning)", [Held])
                                       end], ?LOG#{name => Name}),
            Em#em{undeclared = {Now, 0}};
        false ->
            Em#em{undeclared = {Last, Held + 1}}
    end.

%% The observer's event, stamped by the shell.
event(Name, Out, {send, V, _Hold}) -> {emit, stamp, {Name, Out}, send, V};
event(Name, Out, {set, V}) -> {emit, stamp, {Name, Out}, set, V};
event(Name, Out, unset) -> {emit, stamp, {Name, Out}, unset, none}.

relatch(Out, {set, V}, Em = #em{latches = L}) ->
    Em#em{latches = L#{Out => V}};
relatch(Out, _, Em = #em{latches = L}) ->
    case L of
        #{Out := _} -> Em#em{latches = maps:remove(Out, L)};
        #{} -> Em
    end.

send_all([], _Msg) -> ok;
send_all([C | Cs], Msg) ->
    toroco_wire:send(C, Msg),
    send_all(Cs, Msg).

%%====================================================================
%% The wiring
%%====================================================================

%% @doc A consumer attaches to `Src': it gets the output's latch, in the
%% same step as it joins the output's consumers; the first remote one
%% starts the keep-alive (the actions to add).
-spec subscribed({atom(), atom()}, toroco_wire:address(), emitter()) ->
          {emitter(), [gen_statem:action()]}.
subscribed({_, Out} = Src, Consumer, Em = #em{outputs = Outs, open = true})
  when not is_map_key(Out, Outs) ->
    subscribed(Src, Consumer, Em#em{outputs = Outs#{Out => []}});
subscribed({_, Out} = Src, Consumer, Em = #em{outputs = Outs}) ->
    case Outs of
        #{Out := Consumers} ->
            toroco_wire:send(Consumer, ?WIRE_STATE(emitter, Src, self(), latch(Out, Em))),
            Em1 = Em#em{outputs = Outs#{Out := lists:usort([Consumer | Consumers])}},
            case toroco_wire:remote(Consumer) andalso not has_remote(Em) of
                true -> {Em1, alive_timer()};
                false -> {Em1, []}
            end;
        #{} ->
            toroco_wire:send(Consumer, ?WIRE_STATE(emitter, Src, self(), none)),
            {Em, []}
    end.

%% @doc A consumer detaches from `Src'.
-spec unsubscribed({atom(), atom()}, toroco_wire:address(), emitter()) -> emitter().
unsubscribed({_, Out}, Consumer, Em = #em{outputs = Outs}) ->
    case Outs of
        #{Out := Consumers} -> Em#em{outputs = Outs#{Out := lists:delete(Consumer, Consumers)}};
        #{} -> Em
    end.

%% @doc Consumers on other nodes hear from each output now and then, with
%% its latch, so they can tell a silent node from a quiet output (SPEC
%% §13): the keep-alive's timeout again while there are some.
-spec beat(emitter()) -> [gen_statem:action()].
beat(Em = #em{outputs = Outs, name = Name}) ->
    maps:foreach(fun(Out, Consumers) ->
                         Msg = ?WIRE_ALIVE(emitter, {Name, Out}, latch(Out, Em)),
                         [toroco_wire:send(C, Msg) || C <- Consumers, toroco_wire:remote(C)]
                 end, Outs),
    case has_remote(Em) of
        true -> alive_timer();
        false -> []
    end.

has_remote(#em{outputs = Outs}) ->
    lists:any(fun toroco_wire:remote/1, lists:append(maps:values(Outs))).

%% In real time a named gen_statem timeout; in lockstep a timer of the
%% world's (toroco_clock:link_timer/3), in simulated time.
alive_timer() ->
    toroco_clock:link_timer({timeout, '$toroco_alive'}, toroco_wire:keepalive_ms(), beat).

latch(Out, #em{latches = L}) ->
    case L of
        #{Out := V} -> {value, V};
        #{} -> none
    end.

%%====================================================================
%% What the engine shows
%%====================================================================

-spec latches(emitter()) -> #{atom() => term()}.
latches(#em{latches = L}) -> L.

-spec outputs(emitter()) -> [atom()].
outputs(#em{outputs = Outs}) -> maps:keys(Outs).

%% @doc Whether `Out' is an output, or can become one (open ports).
-spec has(term(), emitter()) -> boolean().
has(Out, #em{outputs = Outs, open = Open}) ->
    is_map_key(Out, Outs) orelse (Open andalso is_atom(Out)).
