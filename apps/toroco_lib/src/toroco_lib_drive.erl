%% @doc Wheel commands as the library's behaviors emit them: `{Left,
%% Right}' servo velocities, rounded to integers and clamped to -100..100,
%% latched, and emitted only when they change, so a steady command costs
%% nothing downstream.
-module(toroco_lib_drive).

-export([wheels/2, steer/2, spin/2, set/2, release/1]).
-export_type([wheels/0, last/0]).

-type wheels() :: {integer(), integer()}.
-type last() :: wheels() | none.

%% @doc The command for these wheel velocities.
-spec wheels(number(), number()) -> wheels().
wheels(L, R) -> {clamp(L), clamp(R)}.

%% @doc Forward at `Speed' turning by `Turn' (positive: to the right, the
%% left wheel faster).
-spec steer(number(), number()) -> wheels().
steer(Speed, Turn) -> wheels(Speed + Turn, Speed - Turn).

%% @doc A spin in place at `Speed' to the `left' or `right'.
-spec spin(left | right, number()) -> wheels().
spin(left, Speed) -> wheels(-Speed, Speed);
spin(right, Speed) -> wheels(Speed, -Speed).

%% @doc The actions that latch `Command' on `motors' if it differs from
%% `Last', and the new last command.
-spec set(wheels(), last()) -> {[toroco_behavior:action()], wheels()}.
set(Command, Command) -> {[], Command};
set(Command, _Last) -> {[{set, #{motors => Command}}], Command}.

%% @doc The actions that hand the motors back to lower layers.
-spec release(last()) -> {[toroco_behavior:action()], none}.
release(none) -> {[], none};
release(_Last) -> {[{unset, [motors]}], none}.

-spec clamp(number()) -> integer().
clamp(V) -> max(-100, min(100, round(V))).
