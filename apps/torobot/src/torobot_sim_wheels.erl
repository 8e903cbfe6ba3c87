%% @doc The simulated robot's wheels: an actuator device that hands each
%% velocity pair it receives to the robot's side of the simulator.
%%
%% `torobot_sim_robot' adds it (as `wheels') and wires its `applied' input to the
%% servo device's `applied' output, so the world moves with what the servos
%% really do (nothing while disabled, neutral after a watchdog stop), not
%% with what the behaviors ask for. Each delivery is sent to the `sim'
%% process as `{torobot_sim_wheels, {Left, Right}}'.
%%
%% Options: `sim', the pid to tell (required).
-module(torobot_sim_wheels).
-behaviour(toroco_device).

-export([interface/1, init/2, handle_input/4]).

-spec interface(map()) -> #{inputs := [applied], outputs := []}.
interface(_Opts) ->
    #{inputs => [applied], outputs => []}.

-spec init(atom(), map()) -> {ok, turning, pid()} | {error, term()}.
init(_Name, #{sim := Sim}) when is_pid(Sim) ->
    {ok, turning, Sim};
init(Name, _Opts) ->
    {error, {bad_option, {Name, sim}}}.

-spec handle_input(applied, term(), turning, pid()) -> keep_state_and_data.
handle_input(applied, {L, R} = V, _State, Sim) when is_number(L), is_number(R) ->
    Sim ! {?MODULE, V},
    keep_state_and_data;
handle_input(_Input, _Value, _State, _Sim) ->
    keep_state_and_data.
