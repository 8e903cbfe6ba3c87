%% @doc Registered names of the runtime's processes.
%%
%% Behaviors, devices, routers and gates are registered locally under quoted
%% atoms derived from their place in the wiring, so that a restarted process is
%% found again without telling anyone its new pid, and so that user names never
%% clash with other registered processes (a behavior may be called `logger').
%% `~w' quotes any atom that needs it, which keeps the names unambiguous.
-module(toroco_names).

-export([process/1, router/2, gate/1]).

%% @doc The registered name of a behavior or device.
-spec process(atom()) -> atom().
process(Name) -> list_to_atom("toroco:" ++ io_lib:write_atom(Name)).

%% @doc The registered name of the router of input `Input' of `Receiver'.
-spec router(atom(), atom()) -> atom().
router(Receiver, Input) -> name("toroco:~w/~w", [Receiver, Input]).

%% @doc The registered name of the gate whose smallest member is `{E, Out}'.
-spec gate({atom(), atom()}) -> atom().
gate({E, Out}) -> name("toroco:~w/~w!gate", [E, Out]).

name(Fmt, Args) -> list_to_atom(lists:flatten(io_lib:format(Fmt, Args))).
