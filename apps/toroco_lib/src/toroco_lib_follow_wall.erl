%% @doc Follow a wall on one side at a set distance: Matarić's wall
%% following, the wall follower's one behavior.
%%
%% Inputs (range readings in metres, see `toroco_lib_range'): `side', the
%% sensor square to the followed side; `diagonal', the sensor 45 degrees
%% forward on that side (optional: it sees inner corners early and tells
%% whether the robot points to or away from the wall); `front'.
%% Outputs: `motors', latched, emitted when the command changes.
%%
%% Each reading recomputes the command:
%% <ul>
%% <li>something at or below `front_near' ahead: spin away from the wall;</li>
%% <li>no wall within `lost' on the side: arc towards the
%%     side (`search_turn'), which takes the robot round an outer corner;
%%     lost for `search_ms', the robot is in the open and goes straight
%%     ahead until it meets a wall;</li>
%% <li>else steer `speed' ahead with a turn towards the wall of
%%     `gain' x (side - `distance') + `heading_gain' x (how much the
%%     diagonal says the robot points away from the wall), clamped to
%%     `max_turn'.</li>
%% </ul>
%%
%% Parameters: `side' [right] (`left' | `right'), `distance' [0.25] m,
%% `speed' [70], `gain' [120], `heading_gain' [150], `max_turn' [35],
%% `lost' [0.45] m, `search_turn' [25], `search_ms' [2500], `front_near'
%% [0.3] m, `spin' [50].
%%
%% Usual layer: 0 (it never lets go), with `escape' above it.
-module(toroco_lib_follow_wall).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, handle_event/4]).

-type state() :: following | lost | searching.

%% On a straight wall the diagonal, projected square to the wall, reads
%% this much more than the side sensor: both start on the rim of a robot
%% of the default 0.12 m radius, the diagonal's start 45 degrees forward.
-define(PARALLEL, 0.035).
-define(FAR, 10.0).

-spec params() -> [toroco_lib_params:spec()].
params() ->
    [{side, {one_of, [left, right]}, right}, {distance, metres, 0.25}, {speed, speed, 70},
     {gain, non_neg_number, 120}, {heading_gain, non_neg_number, 150},
     {max_turn, pos_speed, 35}, {lost, metres, 0.45}, {search_turn, speed, 25},
     {search_ms, ms, 2500},
     {front_near, metres, 0.3}, {spin, pos_speed, 50}].

-spec interface() -> #{inputs := [side | diagonal | front], outputs := [motors]}.
interface() -> #{inputs => [side, diagonal, front], outputs => [motors]}.

-spec init(map()) -> {ok, lost, map(), toroco_behavior:actions()}
                         | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, P} -> {ok, lost, P#{readings => #{}, last => none},
                     [{state_timeout, maps:get(search_ms, P), search}]};
        {error, _} = Error -> Error
    end.

-spec handle_input(side | diagonal | front, term(), state(), map()) ->
          toroco_behavior:result().
handle_input(Input, Reading, State, #{readings := Rs} = P) ->
    P1 = P#{readings := Rs#{Input => toroco_lib_range:metres(Reading, ?FAR)}},
    case {command(P1), State} of
        {{follow, Command}, _} -> drive(following, Command, [], P1);
        {{lost, Command}, following} ->
            drive(lost, Command, [{state_timeout, maps:get(search_ms, P), search}], P1);
        {{lost, Command}, lost} -> drive(lost, Command, [], P1);
        {{lost, _}, searching} -> {keep_state, P1}
    end.

-spec handle_event(gen_statem:event_type(), term(), state(), map()) -> toroco_behavior:result().
handle_event(state_timeout, search, lost, #{speed := S} = P) ->
    drive(searching, toroco_lib_drive:wheels(S, S), [], P);
handle_event(_Type, _Content, _State, _P) ->
    keep_state_and_data.

drive(State, Command, Timers, #{last := Last} = P) ->
    {Actions, Last1} = toroco_lib_drive:set(Command, Last),
    {next_state, State, P#{last := Last1}, Actions ++ Timers}.

command(#{readings := Rs} = P) ->
    command(Rs, P).

command(Rs, #{side := Side, distance := Distance, speed := Speed, gain := Gain,
              heading_gain := HGain, max_turn := MaxTurn, lost := Lost,
              search_turn := Search, front_near := FrontNear, spin := Spin}) ->
    Away = case Side of left -> right; right -> left end,
    Towards = case Side of left -> -1; right -> 1 end,
    SideR = maps:get(side, Rs, ?FAR),
    Diag = maps:get(diagonal, Rs, none),
    %% A diagonal that sees nothing near (past an outer corner, it sees the
    %% next wall away) says nothing of the heading.
    DiagSquare = case Diag of
                     D when is_number(D), D =< Lost -> D * math:sqrt(0.5);
                     _ -> SideR + ?PARALLEL
                 end,
    Front = maps:get(front, Rs, ?FAR),
    if
        Front =< FrontNear ->
            {follow, toroco_lib_drive:spin(Away, Spin)};
        SideR > Lost ->
            {lost, toroco_lib_drive:steer(Speed, Towards * Search)};
        true ->
            Near = min(SideR, DiagSquare - ?PARALLEL),
            Turn = Gain * (Near - Distance) + HGain * (DiagSquare - ?PARALLEL - SideR),
            Clamped = max(-MaxTurn, min(MaxTurn, Turn)),
            {follow, toroco_lib_drive:steer(Speed, Towards * Clamped)}
    end.
