%% @doc The behavior library (SPEC §14): reusable behaviors with declared
%% ports and checked parameters, so that a robot is a wiring file of
%% library behaviors (the robots of `config/robots/').
%%
%% This module is the catalogue: {@link catalogue/0} lists each behavior
%% with its module, ports, parameters (kind and default) and usual layer,
%% read from the modules themselves, so the table in the README and the
%% tests cannot drift from the code. The behaviors are the `toroco_lib_*'
%% callback modules; `toroco_lib_params' checks parameters,
%% `toroco_lib_drive' builds wheel commands, `toroco_lib_range' reads
%% range sensors and `toroco_lib_braitenberg' runs the two vehicles.
%%
%% The application has no processes: behaviors run under the runtime's
%% layer supervisors like any other, so there is nothing to supervise.
-module(toroco_lib).

-export([catalogue/0, behaviors/0]).
-export_type([entry/0]).

-type entry() :: #{name := atom(), module := module(), inputs := [atom()],
                   outputs := [atom()], params := [toroco_lib_params:spec()],
                   layer := string()}.

-define(BEHAVIORS,
        [{cruise, toroco_lib_cruise, "0"},
         {wander, toroco_lib_wander, "0"},
         {avoid, toroco_lib_avoid, "1"},
         {follow_wall, toroco_lib_follow_wall, "0"},
         {escape, toroco_lib_escape, "top of motion"},
         {seek_colour, toroco_lib_seek_colour, "above avoid"},
         {dock, toroco_lib_dock, "above wander, below avoid"},
         {stale_stop, toroco_lib_stale_stop, "with its commander"},
         {teleop, toroco_lib_teleop, "top"},
         {fear, toroco_lib_fear, "above wander, below avoid"},
         {love, toroco_lib_love, "above wander, below avoid"}]).

%% @doc The library's behaviors as `{Name, Module}'.
-spec behaviors() -> [{atom(), module()}].
behaviors() ->
    [{Name, Module} || {Name, Module, _} <- ?BEHAVIORS].

%% @doc Every behavior of the library with its ports, parameters and usual
%% layer.
-spec catalogue() -> [entry()].
catalogue() ->
    [begin
         #{inputs := Ins, outputs := Outs} = Module:interface(),
         #{name => Name, module => Module, inputs => Ins, outputs => Outs,
           params => Module:params(), layer => Layer}
     end || {Name, Module, Layer} <- ?BEHAVIORS].
