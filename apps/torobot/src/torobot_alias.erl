%% @doc A device's ports under another name: the names the original
%% Torocó's Toribio configuration gave the Torobot's devices, for programs
%% written for it (SPEC §16, `config/torobot_lua.wiring').
%%
%% A behavior that relays each input to an output, converting the value:
%% `servo_motors' and `trc_motor' take `setvel2mtr' (left, right) and set
%% the motors' `setvel' (latched, as a servo keeps its velocity); `camera.update'
%% passes the camera's `update_red' on as `update', the blob's `{X, Y}', or
%% no values (`{}') when none is seen. A Lua program's `device.D.E' is the
%% behavior named `D.E' when there is one (toroco_lua), so
%% `device.camera.update' reads this one.
%%
%% Options: `relay' `#{Input => Output}'; `how' `set' (latched) or `send'
%% (default); `none' `empty' turns the camera's `none' into no values.
-module(torobot_alias).
-behaviour(toroco_behavior).

-export([interface/1, init/1, handle_input/4]).

-type opts() :: #{relay := #{atom() => atom()}, how => set | send, none => empty | keep}.

-spec interface(opts()) -> #{inputs := [atom()], outputs := [atom()]}.
interface(#{relay := Relay}) ->
    #{inputs => lists:sort(maps:keys(Relay)), outputs => lists:usort(maps:values(Relay))}.

-spec init(opts()) -> {ok, relaying, opts()}.
init(Opts = #{relay := _}) ->
    {ok, relaying, Opts}.

-spec handle_input(atom(), term(), relaying, opts()) -> toroco_behavior:result().
handle_input(Input, Value, relaying, Opts = #{relay := Relay}) ->
    Out = map_get(Input, Relay),
    V = case {Value, maps:get(none, Opts, keep)} of
            {none, empty} -> {};
            _ -> Value
        end,
    {keep_state_and_data, [{maps:get(how, Opts, send), #{Out => V}}]}.
