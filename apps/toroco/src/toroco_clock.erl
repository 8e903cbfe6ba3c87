%% @doc The runtime's clock: the one place where the runtime reads time and
%% turns durations into timers (SPEC §14).
%%
%% Routers' and gates' hold deadlines, the pure cores' `Now', and the
%% engine's handling of a behavior's gen_statem timeouts (`state_timeout',
%% `{timeout, Name}', event timeouts) all count simulated milliseconds read
%% here. The real-time factor (`speed') is 1 unless set: the simulated lab
%% sets it (10 runs ten times faster), and then a hold of 500 ms lasts 50 ms
%% of real time, so a run at speed 10 behaves as the same run at speed 1.
%% Safety timers of real hardware (the servo watchdog of `pru_port') do not
%% use this clock: they stay in real time.
%%
%% At speed 1 {@link now_ms/0} is the monotonic clock and {@link real_ms/1}
%% the identity; the factor lives in a `persistent_term', read without a
%% copy, and changing it keeps simulated time continuous.
-module(toroco_clock).

-export([now_ms/0, speed/0, set_speed/1, real_ms/1, real_deadline/1]).
-export_type([speed/0]).

-type speed() :: number().

-define(KEY, toroco_clock).

%% @doc Simulated monotonic time in milliseconds.
-spec now_ms() -> integer().
now_ms() ->
    case persistent_term:get(?KEY, 1) of
        1 -> erlang:monotonic_time(millisecond);
        {Speed, RealBase, SimBase} -> SimBase + floor((real_now() - RealBase) * Speed)
    end.

%% @doc The real-time factor.
-spec speed() -> speed().
speed() ->
    case persistent_term:get(?KEY, 1) of
        1 -> 1;
        {Speed, _, _} -> Speed
    end.

%% @doc Sets the real-time factor; simulated time goes on from where it is.
-spec set_speed(speed()) -> ok | {error, {bad_speed, term()}}.
set_speed(Speed) when is_number(Speed), Speed > 0 ->
    Sim = now_ms(),
    Real = real_now(),
    case Speed == 1 andalso Sim =:= Real of
        true -> persistent_term:put(?KEY, 1);
        false -> persistent_term:put(?KEY, {Speed, Real, Sim})
    end;
set_speed(Speed) ->
    {error, {bad_speed, Speed}}.

%% @doc A duration of simulated milliseconds as real milliseconds (rounded
%% up, so a timer never fires early).
-spec real_ms(timeout()) -> timeout().
real_ms(infinity) -> infinity;
real_ms(Ms) ->
    case persistent_term:get(?KEY, 1) of
        1 -> Ms;
        {Speed, _, _} -> ceil(Ms / Speed)
    end.

%% @doc A simulated monotonic deadline as a real monotonic one, in ms (for
%% gen_statem's absolute timeouts).
-spec real_deadline(integer()) -> integer().
real_deadline(SimMs) ->
    case persistent_term:get(?KEY, 1) of
        1 -> SimMs;
        {Speed, RealBase, SimBase} -> RealBase + ceil((SimMs - SimBase) / Speed)
    end.

real_now() ->
    erlang:monotonic_time(millisecond).
