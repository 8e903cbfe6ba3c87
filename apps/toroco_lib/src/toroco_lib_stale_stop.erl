%% @doc Stale stop: pass motor commands through, and put the motors at the
%% idle value when the last command is older than `max_age_ms': the safety
%% behavior twist_mux users ask for, so a commander that goes quiet (a
%% remote link, a crashed planner) cannot leave the robot driving.
%%
%% Inputs: `command', any motor command (`{Left, Right}'). Outputs:
%% `motors', latched: each command as it comes, then `idle' once no command
%% came for `max_age_ms'; a new command takes over again.
%%
%% Parameters: `max_age_ms' [500], `idle' [{0, 0}].
%%
%% Usual layer: between a remote commander and the motors, at the
%% commander's layer or just above it.
-module(toroco_lib_stale_stop).
-behaviour(toroco_behavior).

-export([params/0, interface/0, init/1, handle_input/4, handle_event/4]).

-spec params() -> [toroco_lib_params:spec()].
params() -> [{max_age_ms, ms, 500}, {idle, term, {0, 0}}].

-spec interface() -> #{inputs := [command], outputs := [motors]}.
interface() -> #{inputs => [command], outputs => [motors]}.

-spec init(map()) -> {ok, quiet, map()} | {error, toroco_lib_params:error()}.
init(Params) ->
    case toroco_lib_params:check(Params, params()) of
        {ok, P} -> {ok, quiet, P};
        {error, _} = Error -> Error
    end.

-spec handle_input(command, term(), quiet | fresh | stale, map()) -> toroco_behavior:result().
handle_input(command, Command, _State, #{max_age_ms := Age} = P) ->
    {next_state, fresh, P, [{set, #{motors => Command}}, {state_timeout, Age, stale}]}.

-spec handle_event(gen_statem:event_type(), term(), quiet | fresh | stale, map()) ->
          toroco_behavior:result().
handle_event(state_timeout, stale, fresh, #{idle := Idle} = P) ->
    {next_state, stale, P, [{set, #{motors => Idle}}]};
handle_event(_Type, _Content, _State, _P) ->
    keep_state_and_data.
