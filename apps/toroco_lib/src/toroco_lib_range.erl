%% @doc Near or far from a range reading, with hysteresis: what `avoid' and
%% `follow_wall' make of their sensors. A reading is a distance in metres
%% (the simulated world's range sensors), or already a level: `near' | `1'
%% | `true' and `far' | `0' | `false' (the Torobot's IR devices).
-module(toroco_lib_range).

-export([level/4, metres/2]).

%% @doc The level after `Reading', given the previous one: near at or
%% below `Near' metres, far again above `Far'.
-spec level(term(), near | far, number(), number()) -> near | far.
level(R, _Prev, Near, _Far) when is_number(R), R =< Near -> near;
level(R, _Prev, _Near, Far) when is_number(R), R > Far -> far;
level(R, Prev, _Near, _Far) when is_number(R) -> Prev;
level(R, _Prev, _Near, _Far) when R =:= near; R =:= 1; R =:= true -> near;
level(R, _Prev, _Near, _Far) when R =:= far; R =:= 0; R =:= false -> far;
level(_Other, Prev, _Near, _Far) -> Prev.

%% @doc A reading as metres: `Default' for what is not a number (nothing
%% in range).
-spec metres(term(), number()) -> number().
metres(R, _Default) when is_number(R) -> R;
metres(_R, Default) -> Default.
