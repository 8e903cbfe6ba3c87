%% @doc A turning behavior of the line follower (thesis §4.1.6): while its
%% grey sensor reads `black' it holds the motors at the turn of param
%% `velocity' (for turning left towards a line seen on the left, e.g.
%% `{0, 50}'); when the sensor reads `white' again it lets go.
%%
%% Input `grey' (a grey-level sensor reading `black' or `white'), output
%% `velocity'. Holding is a `set' (it suppresses the lower `forward' for as
%% long as it stands) and letting go an `unset' (so `forward''s latch is
%% re-delivered). Only changes of the reading act: a repeated `black' sets
%% nothing new.
-module(torobot_ex_turn).
-behaviour(toroco_behavior).

-export([interface/0, init/1, handle_input/4]).

-spec interface() -> #{inputs := [atom()], outputs := [atom()]}.
interface() -> #{inputs => [grey], outputs => [velocity]}.

-spec init(map()) -> {ok, white, #{velocity := term()}}.
init(#{velocity := V}) -> {ok, white, #{velocity => V}}.

-spec handle_input(grey, term(), white | black, map()) -> toroco_behavior:result().
handle_input(grey, black, white, D = #{velocity := V}) ->
    {next_state, black, D, [{set, #{velocity => V}}]};
handle_input(grey, white, black, D) ->
    {next_state, white, D, [{unset, [velocity]}]};
handle_input(grey, _Reading, _State, _Data) ->
    keep_state_and_data.
