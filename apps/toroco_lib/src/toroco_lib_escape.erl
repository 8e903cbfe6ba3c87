%% @doc Escape: after a bump, or when the wheels are commanded but do not
%% turn (a stall), back up and turn away, as a timed sequence. The
%% bump-and-go of Roomba-like robots and of leJOS' subsumption examples.
%%
%% Inputs:
%% <ul>
%% <li>`bump': the bumper, `none' (or `false') when free, else the side
%%     hit: `left', `right', `front', `rear' (or `true', taken as front);</li>
%% <li>`command': the wheel velocities being applied (the servos'
%%     `applied' output) and `odometry': the wheel velocities measured, both
%%     `{Left, Right}' in servo units. Stalled means the command is at
%%     least `min_command' while the wheels turn at less than
%%     `stall_ratio' of it, for `stall_ms' on end. Leave both unwired to
%%     escape from bumps only.</li>
%% </ul>
%% Outputs: `motors': latched `{-back_speed, -back_speed}' for `back_ms'
%% (skipped after a rear bump), then a spin away from the side hit for
%% `turn_ms' plus a seeded random share of `turn_spread_ms' (so a robot
%% that only bumps does not settle into the same bounce for ever; after a
%% front bump or a stall, to each side in turn, `prefer' first), then
%% unset. Bumps and stalls during the sequence are
%% ignored, except a rear bump while backing, which starts the turn at once.
%%
%% Parameters: `back_ms' [700], `turn_ms' [600], `back_speed' [50],
%% `spin' [50], `turn_spread_ms' [0] (0..), `seed' [1], `stall_ms' [800],
%% `stall_ratio' [0.25], `min_command' [20], `prefer' [left].
%%
%% Usual layer: the top of the robot's motion layers (an escape must win).
-module(toroco_lib_escape).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, handle_event/4]).

-type state() :: idle | {backing, left | right} | {turning, left | right}.

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{back_ms, ms, 700}, {turn_ms, ms, 600}, {back_speed, pos_speed, 50}, {spin, pos_speed, 50},
     {turn_spread_ms, non_neg_number, 0}, {seed, integer, 1},
     {stall_ms, ms, 800}, {stall_ratio, non_neg_number, 0.25}, {min_command, pos_speed, 20},
     {prefer, {one_of, [left, right]}, left}].

-spec interface() -> #{inputs := [bump | command | odometry], outputs := [motors]}.
interface() -> #{inputs => [bump, command, odometry], outputs => [motors]}.

-spec init(map()) -> {ok, idle, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, #{prefer := Prefer, seed := Seed} = P} ->
            {ok, idle, P#{next => Prefer, rand => rand:seed_s(exsss, Seed), command => {0, 0}, odometry => {0, 0},
                          stalled => false}};
        {error, _} = Error ->
            Error
    end.

-spec handle_input(bump | command | odometry, term(), state(), map()) ->
          toroco_behavior:result().
handle_input(bump, Hit, idle, P) when Hit =/= none, Hit =/= false ->
    start(side(Hit), P);
handle_input(bump, rear, {backing, Dir}, P) ->
    turn(Dir, P);
handle_input(bump, _Hit, _State, _P) ->
    keep_state_and_data;
handle_input(Input, {L, R} = V, State, P) when (Input =:= command orelse Input =:= odometry),
                                                is_number(L), is_number(R) ->
    watch(State, P#{Input := V});
handle_input(_Input, _Other, _State, _P) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), state(), map()) ->
          toroco_behavior:result().
handle_event({timeout, stall}, stall, idle, P) ->
    start(front, P#{stalled := false});
handle_event(state_timeout, turn, {backing, Dir}, P) ->
    turn(Dir, P);
handle_event(state_timeout, done, {turning, _}, P) ->
    {next_state, idle, P#{stalled := false}, [{unset, [motors]}]};
handle_event(_Type, _Content, _State, _P) ->
    keep_state_and_data.

side(Hit) when Hit =:= left; Hit =:= right; Hit =:= rear -> Hit;
side(_Front) -> front.

%% Where to turn: away from a side hit; after a front hit or a stall, to
%% each side in turn.
start(rear, #{next := Next} = P) ->
    turn(Next, P#{next := other(Next)});
start(Hit, #{next := Next, back_ms := Back, back_speed := B} = P) ->
    {Dir, P1} = case Hit of
                    left -> {right, P};
                    right -> {left, P};
                    front -> {Next, P#{next := other(Next)}}
                end,
    {next_state, {backing, Dir}, P1,
     [{set, #{motors => toroco_lib_drive:wheels(-B, -B)}}, {state_timeout, Back, turn},
      {{timeout, stall}, cancel}]}.

turn(Dir, #{turn_ms := Turn, turn_spread_ms := Spread, spin := Spin, rand := R0} = P) ->
    {U, R1} = rand:uniform_s(R0),
    {next_state, {turning, Dir}, P#{rand := R1},
     [{set, #{motors => toroco_lib_drive:spin(Dir, Spin)}},
      {state_timeout, Turn + round(U * Spread), done},
      {{timeout, stall}, cancel}]}.

other(left) -> right;
other(right) -> left.

%% The stall timer runs while idle and stalled; the sequence's own
%% commands never count.
watch(idle, #{command := C, odometry := O, stalled := Was, stall_ms := Ms} = P) ->
    case {stalled(C, O, P), Was} of
        {true, false} -> {keep_state, P#{stalled := true}, [{{timeout, stall}, Ms, stall}]};
        {false, true} -> {keep_state, P#{stalled := false}, [{{timeout, stall}, cancel}]};
        _ -> {keep_state, P}
    end;
watch(_Escaping, P) ->
    {keep_state, P}.

stalled({Cl, Cr}, {Ol, Or}, #{min_command := Min, stall_ratio := Ratio}) ->
    Commanded = (abs(Cl) + abs(Cr)) / 2,
    Commanded >= Min andalso (abs(Ol) + abs(Or)) / 2 < Ratio * Commanded.
