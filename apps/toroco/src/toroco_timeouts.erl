%% @doc Timeouts in simulated time (SPEC §14): what becomes of the gen_statem
%% timeouts a process of the event path sets (a callback module's
%% `state_timeout', `{timeout, Name}' and event timeouts, a consumer's hold
%% timer), as a pure function of the timeout, the clock and the timers
%% already set.
%%
%% In real time a timeout stays gen_statem's: a relative one counts
%% simulated milliseconds, turned into real ones by the clock's speed; a
%% hold deadline becomes an absolute real one. In lockstep gen_statem sees
%% none of them: each is an effect for `toroco_lockstep' (`{set, Kind,
%% Deadline, Msg}', `{cancel, Kind}'), which fires it as the step
%% `WIRE_TIMER(Kind, Msg)' at its simulated deadline, and the process keeps
%% its deadlines ({@link timers()}) to tell a timer still set from one
%% cancelled meanwhile ({@link fired/2}). Absolute timeouts (`{abs, true}')
%% stay gen_statem's, in real time: they are for real hardware.
%%
%% The shell (`toroco_shell') reads the clock (`toroco_clock:timebase/0')
%% and carries the effects out, in order, as it gets them.
%%
%% Functions: {@link action/3} (one gen_statem action), {@link hold/4} (a
%% consumer's earliest deadline), {@link cancel/2}, {@link fired/2}, and
%% {@link event_timeout/1}.
-module(toroco_timeouts).

-export([action/3, hold/4, cancel/2, fired/2, event_timeout/1]).
-export_type([timers/0, effect/0]).

%% In lockstep, the timeouts set and their simulated deadlines.
-type timers() :: #{term() => integer()}.
-type effect() :: {set, term(), integer(), term()} | {cancel, term()}.
-type clock() :: toroco_clock:timebase().

-define(IS_TIMEOUT(K), (K =:= state_timeout orelse K =:= timeout orelse
                        (is_tuple(K) andalso tuple_size(K) =:= 2 andalso element(1, K) =:= timeout))).
-define(HOLD, {timeout, hold}).

%% @doc One gen_statem action of a callback result: the actions gen_statem
%% is to see instead (none, or the action in real milliseconds), the timers
%% and the effects for `toroco_lockstep'. Actions other than timeouts pass.
-spec action(gen_statem:action() | term(), clock(), timers()) ->
          {[gen_statem:action() | term()], timers(), [effect()]}.
action(A, {realtime, Scale}, Timers) ->
    {[real(A, Scale)], Timers, []};
action(A, {lockstep, Now}, Timers) ->
    virtual(A, Now, Timers).

%% @doc A consumer's one hold timer (`{timeout, hold}'), moved only when its
%% earliest deadline (in `toroco_clock' time) changed from `Old' to `Next':
%% the deadline it now has, the actions and timers, the effects.
-spec hold(infinity | integer(), infinity | integer(), clock(), timers()) ->
          {infinity | integer(), [gen_statem:action()], timers(), [effect()]}.
hold(Same, Same, _Clock, Timers) -> {Same, [], Timers, []};
hold(infinity, _Old, {realtime, _}, Timers) ->
    {infinity, [{?HOLD, cancel}], Timers, []};
hold(Next, _Old, {realtime, Scale}, Timers) ->
    {Next, [{?HOLD, toroco_clock:real_deadline(Next, Scale), expire, [{abs, true}]}], Timers, []};
hold(infinity, _Old, {lockstep, _}, Timers) ->
    {infinity, [], maps:remove(?HOLD, Timers), [{cancel, ?HOLD}]};
hold(Next, _Old, {lockstep, _}, Timers) ->
    {Next, [], Timers#{?HOLD => Next}, [{set, ?HOLD, Next, expire}]}.

%% @doc Cancels simulated timeout `Kind' if it is set (leaving a state ends
%% its state timeout, any event ends an event timeout).
-spec cancel(term(), timers()) -> {timers(), [effect()]}.
cancel(Kind, Timers) ->
    case Timers of
        #{Kind := _} -> {maps:remove(Kind, Timers), [{cancel, Kind}]};
        #{} -> {Timers, []}
    end.

%% @doc A simulated timeout came as a step: `stale' if it was cancelled
%% since (the step was on its way), else the timers without it.
-spec fired(term(), timers()) -> {ok, timers()} | stale.
fired(Kind, Timers) ->
    case Timers of
        #{Kind := _} -> {ok, maps:remove(Kind, Timers)};
        #{} -> stale
    end.

%% @doc Whether a gen_statem action sets an event timeout (which any event
%% cancels).
-spec event_timeout(term()) -> boolean().
event_timeout(T) when is_integer(T) -> true;
event_timeout({timeout, _, _}) -> true;
event_timeout({timeout, _, _, _}) -> true;
event_timeout(_) -> false.

%%====================================================================
%% Internals
%%====================================================================

%% Relative times are turned into real ones; absolute ones and cancels pass.
real({Kind, T, Msg}, Scale) when ?IS_TIMEOUT(Kind), is_integer(T) ->
    {Kind, toroco_clock:real_ms(T, Scale), Msg};
real({Kind, T, Msg, Opts}, Scale) when ?IS_TIMEOUT(Kind), is_integer(T), is_list(Opts) ->
    case proplists:get_value(abs, Opts, false) of
        false -> {Kind, toroco_clock:real_ms(T, Scale), Msg, Opts};
        true -> {Kind, T, Msg, Opts}
    end;
real(T, Scale) when is_integer(T) -> toroco_clock:real_ms(T, Scale);
real(A, _Scale) -> A.

virtual({Kind, T, Msg}, Now, Timers) when ?IS_TIMEOUT(Kind), is_integer(T) ->
    set(Kind, Now + T, Msg, Timers);
virtual({Kind, infinity, _Msg}, _Now, Timers) when ?IS_TIMEOUT(Kind) ->
    none(cancel(Kind, Timers));
virtual({Kind, T, Msg, Opts} = A, Now, Timers) when ?IS_TIMEOUT(Kind), is_integer(T),
                                                    is_list(Opts) ->
    case proplists:get_value(abs, Opts, false) of
        false -> set(Kind, Now + T, Msg, Timers);
        true -> {[A], Timers, []}
    end;
virtual({Kind, cancel}, _Now, Timers) when ?IS_TIMEOUT(Kind) ->
    none(cancel(Kind, Timers));
virtual({Kind, update, Msg}, _Now, Timers) when ?IS_TIMEOUT(Kind) ->
    case Timers of
        #{Kind := Deadline} -> {[], Timers, [{set, Kind, Deadline, Msg}]};
        #{} -> {[], Timers, []}
    end;
virtual(T, Now, Timers) when is_integer(T) ->
    set(timeout, Now + T, T, Timers);
virtual(A, _Now, Timers) ->
    {[A], Timers, []}.

set(Kind, Deadline, Msg, Timers) ->
    {[], Timers#{Kind => Deadline}, [{set, Kind, Deadline, Msg}]}.

none({Timers, Effects}) -> {[], Timers, Effects}.
