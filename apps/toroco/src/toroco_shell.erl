%% @doc The part of a process of the event path that every such process
%% does the same way, whatever it runs: the behavior engine
%% (`toroco_behavior', behaviors and devices) and the consumer shell
%% (`toroco_consumer', routers and gates) are gen_statems whose
%% `handle_event/4' goes through here.
%%
%% What lives here, once:
%% <ul>
%% <li>lockstep (`toroco_lockstep'): a barrier answered at once; a step
%%     (`WIRE_STEP(Token, Msg)') handled as the message or timer it carries
%%     would be in real time, then said done once the events it inserted are
%%     handled; a simulated timer that was cancelled while its step was on
%%     the way is dropped, and any other step ends a simulated event
%%     timeout, as gen_statem's own would end;</li>
%% <li>the idle tick (`toroco_wire:idle_arm/0'): a quiet process
%%     hibernates, its next event arms the tick again;</li>
%% <li>the observer tap's batch (`toroco_tap:after_event/3'): the events a
%%     process tapped while handling an event go when it has handled it, as
%%     the named timeout `'$toroco_tap'' or at once. Every event one
%%     activation (the handling of one event) taps carries one time stamp,
%%     read once, at its first tapped event (`toroco_clock:timestamp_ns/0'):
%%     with no observer no clock is read; their order is their order in the
%%     batch, which the tap keeps (SPEC §10);</li>
%% <li>timeouts in simulated time: the gen_statem timeouts a host is asked
%%     for go through `toroco_timeouts', and what lockstep must keep is told
%%     to it here.</li>
%% </ul>
%%
%% A host keeps a {@link shell()} in its data and hands {@link
%% handle_event/5} a {@link host()}: how to get the shell out of its data
%% and put it back, and its own event handler, which gets every event the
%% shell does not handle itself. The event path's own messages (a router's
%% event in, a behavior's input) may take a short way: when {@link
%% awake/1} says the shell has nothing to do first, straight to the
%% host's handler, and its result to {@link done/3}, which is what {@link
%% handle_event/5} would do with them, a few calls fewer (the engine and
%% the consumer shell do; the event path's cost is its calls).
-module(toroco_shell).

-include("toroco_wire.hrl").

-export([new/0, handle_event/5, awake/1, done/3, tap/3, lifecycle/4, flush/1]).
-export([timeout/2, left/1, hold/3]).
-export_type([shell/0, host/1]).
%% After every event: inlined, the event path's calls are its cost.
-compile({inline, [tap_after/3, own/5, result/4]}).

-record(shell, {idle = off :: toroco_wire:idle(),
                %% the observer tap's events not sent yet
                batch = [] :: toroco_tap:batch(),
                %% the time stamp of this activation's tapped events, once read
                stamp = none :: none | integer(),
                %% in lockstep, the timeouts set and their simulated deadlines
                timers = #{} :: toroco_timeouts:timers()}).

-opaque shell() :: #shell{}.
%% How the shell reaches a host's data `D': gets its shell, puts it back,
%% and hands an event on to the host's own handler.
-type host(D) :: {fun((D) -> shell()), fun((shell(), D) -> D),
                  fun((gen_statem:event_type(), term(), term(), D) ->
                             gen_statem:event_handler_result(term()))}.

%%====================================================================
%% Events
%%====================================================================

%% @doc A new process's shell, its idle tick armed.
-spec new() -> shell().
new() ->
    #shell{idle = toroco_wire:idle_arm()}.

%% @doc Every event of a host: what the shell does itself, or the host's
%% handler; then what becomes of the tap's batch.
-spec handle_event(gen_statem:event_type(), term(), term(), D, host(D)) ->
          gen_statem:event_handler_result(term()).
handle_event(info, ?WIRE_BARRIER(Ref), _St, _D, _Host) ->
    toroco_lockstep:synced(Ref),
    keep_state_and_data;
handle_event(Type, Content, St, D, Host) ->
    tap_after(event(Type, Content, St, D, Host), D, Host).

%% @doc Whether the shell has nothing to do before a host's event: the
%% idle tick is armed (or never used). A host may then hand an event of
%% its event path straight to its handler, and the result to {@link
%% done/3}: the same as {@link handle_event/5} would do with it.
-spec awake(shell()) -> boolean().
awake(#shell{idle = off}) -> false;
awake(#shell{}) -> true.

%% @doc What becomes of the tap's batch after a host's handler returned
%% `R' for data `D0' (as after every event {@link handle_event/5} hands
%% on).
-spec done(gen_statem:event_handler_result(term()), D, host(D)) ->
          gen_statem:event_handler_result(term()).
done(R, D0, Host) ->
    tap_after(R, D0, Host).

event(info, ?WIRE_STEP(Token, Msg), St, D, Host) ->
    toroco_wire:step_done(Token, step(Msg, St, D, Host));
%% A step whose work is still out of the process (a Lua behavior's
%% activation, answered by a message): done once the host leaves state
%% `step_pending' (gen_statem retries a postponed event then).
event(internal, ?WIRE_STEP_DONE(_), step_pending, _D, _Host) ->
    {keep_state_and_data, [postpone]};
event(internal, ?WIRE_STEP_DONE(Token), _St, _D, _Host) ->
    toroco_lockstep:done(Token),
    keep_state_and_data;
event(info, ?WIRE_IDLE, _St, D, {Get, Put, _}) ->
    Sh = Get(D),
    {Idle, Actions} = toroco_wire:idle_tick(Sh#shell.idle),
    {keep_state, Put(Sh#shell{idle = Idle}, D), Actions};
event(Type, Content, St, D, Host = {Get, Put, _}) ->
    case Get(D) of
        Sh = #shell{idle = off} ->
            own(Type, Content, St, Put(Sh#shell{idle = toroco_wire:idle_arm()}, D), Host);
        #shell{} -> own(Type, Content, St, D, Host)
    end.

%% The tap's batch is due (toroco_tap:after_event/3), or a subscriber wants
%% everything tapped so far (toroco_tap:sync/1); else the host's event.
own({timeout, '$toroco_tap'}, flush, _St, D, {Get, Put, _}) ->
    {keep_state, Put(flush(Get(D)), D)};
own(info, ?WIRE_TAP_FLUSH(Feeder, Tag), _St, D, {Get, Put, _}) ->
    Sh = Get(D),
    {keep_state, Put(Sh#shell{batch = toroco_tap:flushed(Feeder, Tag, Sh#shell.batch)}, D)};
own(Type, Content, St, D, {_, _, Handle}) ->
    Handle(Type, Content, St, D).

%% A step of lockstep: a simulated timer that is still set fires; any other
%% message ends a simulated event timeout.
step(?WIRE_TIMER(Kind, {'$toroco_link', Msg}), St, D, Host) ->
    %% a link timer (toroco_clock:link_timer/3): the world keeps it, not the shell
    event(Kind, Msg, St, D, Host);
step(?WIRE_TIMER(Kind, Msg), St, D, Host = {Get, Put, _}) ->
    Sh = Get(D),
    case toroco_timeouts:fired(Kind, Sh#shell.timers) of
        {ok, Timers} -> event(Kind, Msg, St, Put(Sh#shell{timers = Timers}, D), Host);
        stale -> keep_state_and_data
    end;
step(Msg, St, D, Host = {Get, Put, _}) ->
    case Get(D) of
        Sh = #shell{timers = #{timeout := _}} ->
            event(info, Msg, St, Put(cancel(timeout, Sh), D), Host);
        #shell{} ->
            event(info, Msg, St, D, Host)
    end.

%%====================================================================
%% The observer tap's batch
%%====================================================================

%% @doc Keeps `Event' for the tap's `Sinks' in the shell's batch, stamped
%% (its second element, the time, is set) with the activation's time.
-spec tap([term()], tuple(), shell()) -> shell().
tap(Sinks, Event, Sh = #shell{batch = B, stamp = none}) ->
    T = toroco_clock:timestamp_ns(),
    Sh#shell{batch = toroco_tap:tap(Sinks, setelement(2, Event, T), B), stamp = T};
tap(Sinks, Event, Sh = #shell{batch = B, stamp = T}) ->
    Sh#shell{batch = toroco_tap:tap(Sinks, setelement(2, Event, T), B)}.

%% @doc A lifecycle event about `Name' to the `lifecycle' sinks of `Tap'.
-spec lifecycle(toroco_tap:sinks(), atom(), term(), shell()) -> shell().
lifecycle(#{lifecycle := Sinks}, Name, What, Sh) ->
    tap(Sinks, {lifecycle, stamp, Name, What}, Sh);
lifecycle(#{}, _Name, _What, Sh) ->
    Sh.

%% @doc Sends the batch now (at the end of `init', in `terminate').
-spec flush(shell()) -> shell().
flush(Sh = #shell{batch = B}) ->
    Sh#shell{batch = toroco_tap:flush(B)}.

%% After an event, with the data the result carries (or the data before
%% the event if it carries none): the batch goes now, or later with the
%% timeout `'$toroco_tap'' (toroco_tap:after_event/3).
tap_after(R, D0, Host) ->
    case R of
        {keep_state, D} -> tapped(keep_state, none, D, [], D0, Host, R);
        {keep_state, D, A} -> tapped(keep_state, none, D, A, D0, Host, R);
        {next_state, S, D} -> tapped(next_state, S, D, [], D0, Host, R);
        {next_state, S, D, A} -> tapped(next_state, S, D, A, D0, Host, R);
        {repeat_state, D} -> tapped(repeat_state, none, D, [], D0, Host, R);
        {repeat_state, D, A} -> tapped(repeat_state, none, D, A, D0, Host, R);
        keep_state_and_data -> tapped(keep_state, none, D0, [], D0, Host, R);
        {keep_state_and_data, A} -> tapped(keep_state, none, D0, A, D0, Host, R);
        repeat_state_and_data -> tapped(repeat_state, none, D0, [], D0, Host, R);
        {repeat_state_and_data, A} -> tapped(repeat_state, none, D0, A, D0, Host, R);
        _ -> R                                  % stopping: terminate/3 sends it
    end.

%% The activation is over: its stamp goes.
tapped(How, S, D, A0, D0, {Get, Put, _}, R) ->
    case Get(D) of
        #shell{batch = [], stamp = none} ->
            R;
        Sh = #shell{batch = B} ->
            A = case is_list(A0) of true -> A0; false -> [A0] end,
            Was = (Get(D0))#shell.batch =/= [],
            Hurry = A =/= [] andalso lists:any(fun toroco_timeouts:event_timeout/1, A),
            case toroco_tap:after_event(Was, B, Hurry) of
                keep -> result(How, S, Put(Sh#shell{stamp = none}, D), A);
                {B1, More} -> result(How, S, Put(Sh#shell{batch = B1, stamp = none}, D), More ++ A)
            end
    end.

result(next_state, S, D, A) -> {next_state, S, D, A};
result(How, _S, D, A) -> {How, D, A}.

%%====================================================================
%% Timeouts
%%====================================================================

%% @doc One gen_statem action of a host's result through
%% `toroco_timeouts': the actions gen_statem is to see instead, and the
%% shell; lockstep is told what it keeps.
-spec timeout(term(), shell()) -> {[term()], shell()}.
timeout(A, Sh = #shell{timers = Timers}) ->
    {Actions, Timers1, Effects} = toroco_timeouts:action(A, toroco_clock:timebase(), Timers),
    effects(Effects),
    {Actions, Sh#shell{timers = Timers1}}.

%% @doc Leaving a state ends its state timeout: gen_statem does it for its
%% own, the shell for a simulated one.
-spec left(shell()) -> shell().
left(Sh) ->
    cancel(state_timeout, Sh).

%% @doc A consumer's hold timer, from deadline `Old' to `Next'
%% (`toroco_timeouts:hold/4').
-spec hold(infinity | integer(), infinity | integer(), shell()) ->
          {infinity | integer(), [gen_statem:action()], shell()}.
hold(Same, Same, Sh) ->
    {Same, [], Sh};
hold(Next, Old, Sh = #shell{timers = Timers}) ->
    {Next, Actions, Timers1, Effects} = toroco_timeouts:hold(Next, Old, toroco_clock:timebase(),
                                                             Timers),
    effects(Effects),
    {Next, Actions, Sh#shell{timers = Timers1}}.

cancel(Kind, Sh = #shell{timers = Timers}) ->
    {Timers1, Effects} = toroco_timeouts:cancel(Kind, Timers),
    effects(Effects),
    Sh#shell{timers = Timers1}.

effects([]) -> ok;
effects([{set, Kind, Deadline, Msg} | T]) ->
    toroco_clock:set_timer(Kind, Deadline, Msg),
    effects(T);
effects([{cancel, Kind} | T]) ->
    toroco_clock:cancel_timer(Kind),
    effects(T).
