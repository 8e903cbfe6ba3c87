%% @doc Behaviors written in Lua 5.1 against the original Torocó API (SPEC
%% §16): a `toroco_behavior' callback module whose code is a Lua file, run in
%% a state of the `lua_port' program ({@link toroco_lua_port}).
%%
%% A Lua behavior is a behavior like any other: a gen_statem in its layer,
%% with suppression, inhibition, latches, holds, suspend/resume/reset/remove,
%% the tap and recordings. Each input it gets is one activation of its Lua
%% state, written to the program by this process; up to `window' are in
%% flight (one at a time, inside `handle_input/4', in lockstep: see
%% `toroco_lua_pipeline:activate/2'), and what the Lua code emitted comes back, in order, as the
%% actions of the message that brings the answer:
%% `set_output{motors_setvel = {20, 20}}' becomes
%% `{set, #{motors_setvel => {20, 20}}}'. Time is the runtime's: the state
%% reads `toroco_clock:now_ms()' and its timers (`wait_for_input' timeouts,
%% `sched.sleep') are this process's gen_statem timeouts, so Lua behaviors
%% run in lockstep too.
%%
%% The behavior ends with `{lua_error, File, Line, Message}' or `{lua_limit,
%% File, budget | memory}' and its layer restarts it. If the program dies
%% (or its owner, with it), every Lua behavior of the node starts its Lua
%% code again in the new program without a supervisor restart (see {@link reattach/2}: a program
%% crash is one fault, not one per behavior, so a layer of any number of Lua
%% behaviors outlives it), while Erlang behaviors go on.
%%
%% <b>Adding</b>: `toroco:add_behavior(Name, toroco_lua, #{file => Path,
%% params => P, layer => L})' as SPEC §16 writes it (its ports are open:
%% {@link interface/1}); {@link add_behavior/2} is the same with the name passed on for
%% the log; {@link load_main/2} for a whole program. <b>Looking</b>: {@link
%% waits/1}, {@link memory/1}.
%% <b>Changing</b>: {@link reload/1}.
%%
%% The app in parts: this module is the API and the behaviour callbacks
%% (the behavior's life: open, reload, the program or its owner dying);
%% `toroco_lua_pipeline' carries activations to the program and their
%% answers back; `toroco_lua_actions' turns an answer into the engine's
%% actions; `toroco_lua_main' turns a `main.lua' and a behavior's wiring
%% calls into the runtime's API calls; `toroco_lua_port' owns the program.
-module(toroco_lua).
-behaviour(toroco_behavior).

-include("toroco_lua_port.hrl").

-export([add_behavior/2, load_main/2, waits/1, memory/1, reload/1]).
-export([interface/1, init/1, handle_input/4, handle_event/4, info/2]).
-export([env/1, state_id/1, conn/1, reattach/2]).
-export_type([opts/0, main_opts/0]).

%% `file' (required) the behavior's Lua file; `root' the program's folder,
%% where its `require' and `load_behavior' paths start (default: the file's
%% folder; `load_main/2' gives the main file's, as the original ran from
%% there); `params' its `toroco.params';
%% `layer'; `budget' VM instructions per activation and `memory' bytes per
%% state (defaults: the application's env); `window' its activations in
%% flight at most (env `window', default 32; 1: one at a time);
%% `inputs'/`outputs' ports added to those found in the file (for names
%% built at run time).
%% `host' (set by a Lua behavior's `add_behavior' with inline functions,
%% or its `configure_polling' with a converter): the behavior's code is slot
%% `Slot' of the Lua state opened as `Id', and `file' and `root' are its
%% creator's; `layers' the layer of each behavior a program adds, by name.
-type opts() :: #{file := file:filename_all(), root => file:filename_all(), name => atom(),
                  params => map(), layer => non_neg_integer(),
                  budget => pos_integer(), memory => pos_integer(), window => pos_integer(),
                  inputs => [atom()], outputs => [atom()],
                  host => {toroco_lua_port:id(), pos_integer()},
                  layers => #{atom() => non_neg_integer()}}.

%% `layers' the layer of each behavior main.lua loads (default 0: the
%% original has no layers, only priorities); `params' the main file's
%% `toroco.params'; `budget' and `memory' for the
%% main file's own state and every behavior it loads.
-type main_opts() :: #{layers => #{atom() => non_neg_integer()}, params => map(),
                       budget => pos_integer(), memory => pos_integer()}.

-define(LOG, #{domain => [toroco, lua]}).
%% A behavior re-attaches to a new program at most this often in this
%% window; one more program death in it stops the behavior, so a program that
%% dies again and again is left to the layers' supervision.
-define(REATTACH_MAX, 3).
-define(REATTACH_WINDOW_MS, 10000).
%% How long inspect waits for the program to say what the state waits for.
-define(INFO_MS, 100).
%% After its owner died, how long a behavior looks for the new one.
-define(OWNER_POLL_MS, 10).
-define(OWNER_WAIT_MS, 5000).

%%====================================================================
%% API
%%====================================================================

%% @doc Starts Lua behavior `Name' running `file': `toroco:add_behavior(Name,
%% toroco_lua, Opts)' with the name among the options, so that the log and
%% `print' name the behavior.
-spec add_behavior(toroco:name(), opts()) -> ok | {error, term()}.
add_behavior(Name, Opts = #{file := _}) when is_atom(Name) ->
    toroco:add_behavior(Name, ?MODULE, Opts#{name => Name});
add_behavior(Name, Opts) ->
    {error, {bad_options, {Name, Opts}}}.

%% @doc Runs a `main.lua' of the original and turns its `load_behavior',
%% `set_inputs', `set_inhibitors' (and `suspend_behavior',
%% `resume_behavior', `remove_behavior') calls into the node's behaviors and
%% wiring, in the order it made them; `run()' is where it ends. Behavior
%% paths are relative to the main file, `.lua' optional. Devices it names
%% must be on the node already (`device.mouse.left' is the source `{mouse,
%% left}'). Its source lists are the original's, lowest priority first;
%% the runtime's are highest first, so each is turned round. The first
%% call refused stops there, with the main file's line (`toroco_lua_main').
-spec load_main(file:filename_all(), main_opts()) ->
          {ok, #{behaviors := [atom()]}} | {error, {file:filename_all(), non_neg_integer(), term()}}.
load_main(Path, Opts) ->
    toroco_lua_main:load(Path, Opts).

%% @doc The ports of a Lua behavior (the `toroco_behavior' callback, given
%% the options of `add_behavior' but the layer): open, as in the original
%% Torocó. Its inputs are every input its wiring names, read or not, and its
%% outputs every output its code emits on or its wiring names; nothing is
%% read from the file. The options `inputs' / `outputs' declare some
%% beforehand (they show in `toroco:inspect/1' before any wiring).
-spec interface(map()) -> #{inputs := [atom()], outputs := [atom()], open := true}.
interface(Args) when is_map(Args) ->
    #{inputs => lists:usort(maps:get(inputs, Args, [])),
      outputs => lists:usort(maps:get(outputs, Args, [])),
      open => true}.

%% @doc What the tasks of Lua behavior `Name' wait for: `[#{task => T, kind =>
%% file | coroutine | trigger, input => I | none, timer => boolean()}]'.
-spec waits(toroco:name()) -> {ok, [map()]} | {error, term()}.
waits(Name) ->
    behavior_call(Name, waits).

%% @doc The bytes of Lua behavior `Name''s state.
-spec memory(toroco:name()) -> {ok, non_neg_integer()} | {error, term()}.
memory(Name) ->
    behavior_call(Name, memory).

%% @doc Re-reads the file of Lua behavior `Name' into a new state, all or
%% nothing: a file that fails to load leaves the old state running and the
%% reason is returned. The new state starts from scratch (its coroutines
%% and triggers start again); the behavior's latches and holds stay. The
%% interface is the one the behavior was added with.
-spec reload(toroco:name()) -> ok | {error, term()}.
reload(Name) ->
    behavior_call(Name, reload).

behavior_call(Name, Req) ->
    try toroco_device:call(Name, {?MODULE, Req}, 10000)
    catch exit:{noproc, _} -> {error, {not_running, Name}};
          exit:{timeout, _} -> {error, {timeout, Name}}
    end.

%%====================================================================
%% toroco_behavior
%%====================================================================

-spec init(map()) -> {ok, running, map(), [toroco_behavior:action()]} | {error, term()}.
init(Args = #{file := File}) ->
    Name = maps:get(name, Args, registered_name()),
    case whereis(toroco_lua_port) of
        undefined ->
            {error, {lua_port_not_running, Name}};
        Owner ->
            %% a reset runs init/1 again in this process: its last state
            %% goes (a slot's behavior attaches again instead, which takes
            %% its place: closing it could end the state it lives in)
            ok = case Args of
                     #{host := _} -> ok;
                     #{} -> toroco_lua_port:close_all()
                 end,
            D = #{name => Name, file => File, args => Args,
                  owner => erlang:monitor(process, Owner), id => none, port => none,
                  host => maps:get(host, Args, none),
                  %% which of this process's states it is (1, 2, ...): its
                  %% timers carry it, so the old state's do nothing, and a
                  %% run's trace does not depend on the program's ids
                  gen => 0,
                  reattached => [], out => queue:new(), seq => 1, batch => queue:new(),
                  watched => false, stuck_ms => toroco_lua_port:stuck_ms(),
                  window => window(maps:get(window, Args, env(window)))},
            case open(D) of
                {ok, D1, Actions} -> {ok, running, D1, toroco_lua_actions:actions(Actions, D1)};
                {error, {unknown_state, _}} -> {ok, running, orphan(host_gone, D)};
                {error, _} = Error -> Error
            end
    end.

%% At least one in flight, and fewer than the 65,535 sequence numbers a
%% state's requests are told apart by.
window(W) when is_integer(W) -> min(max(W, 1), 1024);
window(_) -> 32.

%% The name the log gives a behavior added without `name' in its options.
registered_name() ->
    case process_info(self(), registered_name) of
        {registered_name, R} -> R;
        _ -> self()
    end.

%% `step_pending': in lockstep, an activation is out (see activate/2).
-type state() :: running | step_pending.

-spec handle_input(atom(), term(), state(), map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _S, #{id := none}) ->
    keep_state_and_data;                      % an orphan, leaving (orphan/2)
handle_input(Input, Value, _S, D) ->
    toroco_lua_pipeline:activate({input, toroco_clock:now_ms(), Input, Value}, D).

%% @doc What `toroco:inspect(Name)' shows under `behavior': `waits' as
%% {@link waits/1} gives them, `memory' the bytes of the Lua state.
%% While activations are out, the program would answer after them: then
%% `waits' is `{busy, N}' (N requests out) and nothing is asked, so that
%% inspect is answered at once.
-spec info(state(), map()) -> #{waits := [map()] | {busy, pos_integer()} | {error, term()},
                                memory := non_neg_integer() | unknown | {error, term()}}.
info(_S, #{id := none}) ->
    #{waits => [], memory => 0};
info(_S, D = #{out := Out, batch := Batch}) ->
    case queue:len(Out) + queue:len(Batch) of
        0 ->
            %% bounded: a program busy with other behaviors' work (or
            %% hung) does not hold inspect up
            #{waits => case waits_of(D, ?INFO_MS) of {ok, Ws} -> Ws; Error -> Error end,
              memory => case toroco_lua_port:memory(conn(D), ?INFO_MS) of
                            {ok, M} -> M;
                            Error -> Error
                        end};
        Busy ->
            #{waits => {busy, Busy}, memory => unknown}
    end.

-spec handle_event(gen_statem:event_type(), term(), state(), map()) -> toroco_behavior:result().
handle_event({timeout, {lua, _}}, _, _S, #{id := none}) ->
    keep_state_and_data;                      % no state now: see owner_down/2
handle_event({timeout, {lua, Task}}, {lua_timer, Gen, Task, Seq}, _S, D = #{gen := Gen}) ->
    toroco_lua_pipeline:activate({timer, toroco_clock:now_ms(), Task, Seq}, D);
handle_event({timeout, {lua, _}}, {lua_timer, _OldGen, _, _}, _S, _D) ->
    keep_state_and_data;                      % a timer of the state before a reload
handle_event(info, {toroco_lua_port, replies, Replies}, S, D) ->
    toroco_lua_pipeline:settle(S, toroco_lua_pipeline:replies(Replies, D));
handle_event(info, {toroco_lua_port, reply, _Ref, _Bin}, _S, _D) ->
    keep_state_and_data;                      % a call's, after its caller gave up
handle_event(info, {?MODULE, flush, Id}, S, D = #{id := Id}) ->
    toroco_lua_pipeline:settle(S, toroco_lua_pipeline:flushed(D));
handle_event(info, {?MODULE, flush, _OldId}, _S, _D) ->
    keep_state_and_data;
handle_event(info, {timeout, _, lua_stuck}, _S, D = #{out := Out, port := Port}) ->
    case queue:peek(Out) of
        {value, {_, Due}} ->
            case Due - erlang:monotonic_time(millisecond) of
                Left when Left =< 0 ->
                    ok = toroco_lua_port:stuck(Port),
                    {keep_state, D#{watched := false}};
                Left ->
                    _ = erlang:start_timer(Left, self(), lua_stuck),
                    keep_state_and_data
            end;
        empty ->
            {keep_state, D#{watched := false}}
    end;
handle_event(info, {'DOWN', MRef, process, _, Why}, S, D = #{owner := MRef}) ->
    toroco_lua_pipeline:settle(S, owner_down(Why, D));
handle_event(info, {timeout, _, {lua_owner, Why, Tries}}, S, D) ->
    toroco_lua_pipeline:settle(S, owner_back(Why, Tries, D));
handle_event(info, ?LUA_PORT_DOWN(Ids, Why), S, D = #{id := Id}) ->
    case lists:member(Id, Ids) of
        true -> toroco_lua_pipeline:settle(S, reattach(Why, D));
        false -> keep_state_and_data          % a state it already re-opened
    end;
handle_event({call, From}, {?MODULE, _}, _S, #{id := none, name := Name}) ->
    %% no Lua state now (its owner is being restarted, or it is leaving)
    {keep_state_and_data, [{reply, From, {error, {no_lua_state, Name}}}]};
handle_event({call, From}, {?MODULE, waits}, _S, D) ->
    {keep_state_and_data, [{reply, From, waits_of(D)}]};
handle_event({call, From}, {?MODULE, memory}, _S, D) ->
    {keep_state_and_data, [{reply, From, toroco_lua_port:memory(conn(D))}]};
handle_event({call, From}, {?MODULE, reload}, S, D0) ->
    %% the events sent to the old code are answered by it first
    toroco_lua_pipeline:settle(S, reload(From, D0));
%% The engine's default for what nobody handles: this module's handle_event
%% is called through each behavior's own callback module, so it cannot fall
%% through to the engine by a function_clause.
handle_event({call, From}, Request, _S, #{name := Name}) ->
    {keep_state_and_data, [{reply, From, {error, {unknown_call, {Name, Request}}}}]};
handle_event(Type, Content, _S, #{name := Name}) ->
    logger:warning("toroco_lua: ~p ignored ~p event ~p", [Name, Type, Content],
                   ?LOG#{name => Name}),
    keep_state_and_data.

reload(From, D0) ->
    case toroco_lua_pipeline:drain(D0) of
        {keep_state, D = #{id := Old, name := Name}, Drained} ->
            case open(D) of
                {ok, D1, Actions} ->
                    _ = toroco_lua_port:close(Old),
                    logger:notice("toroco_lua: ~p reloaded ~ts", [Name, maps:get(file, D)],
                                  ?LOG#{name => Name}),
                    {keep_state, D1, Drained ++ [{reply, From, ok} | toroco_lua_actions:actions(Actions, D1)]};
                {error, _} = Error ->
                    {keep_state, D, Drained ++ [{reply, From, Error}]}
            end;
        Stop ->
            Stop
    end.

%%====================================================================
%% Activations
%%====================================================================

open(D = #{host := {Host, Slot}}) ->
    opened(toroco_lua_port:attach(Host, Slot, toroco_clock:now_ms()), D);
open(D = #{file := File, args := Args}) ->
    {Root, Rel} = toroco_lua_main:root(File, Args),
    Limits = #{budget => maps:get(budget, Args, env(budget)),
               memory => maps:get(memory, Args, env(memory))},
    opened(toroco_lua_port:open(Rel, Root, maps:get(params, Args, #{}), Limits,
                                toroco_clock:now_ms()), D).

%% The behavior's code is in the program now (opened or attached), or not.
opened({ok, Id, Port, Actions}, D) ->
    {ok, D#{id := Id, port := Port, gen := maps:get(gen, D) + 1}, Actions};
opened({stopped, Reason, Actions}, D) ->
    _ = toroco_lua_actions:actions(Actions, D),
    {error, toroco_lua_main:reason(Reason, D)};
opened({error, _} = Error, _D) ->
    Error.

%% @private The application's setting `Key' (`budget', `memory', `window').
-spec env(atom()) -> term().
env(Key) ->
    {ok, V} = application:get_env(toroco_lua, Key),
    V.

%% The program died (killed, crashed, or hung and killed by its owner, who
%% has started a new one by now): the behavior's process stays and its Lua
%% code starts again in a new state, as a Brooks reset does: its outputs are
%% unset (latches and holds end), the new state's emissions follow, and the
%% old state's timers, named with the old id, do nothing. No supervisor sees
%% it, so one program death is not one restart per Lua behavior of a layer.
%% A program that dies more than ?REATTACH_MAX times in ?REATTACH_WINDOW_MS
%% (of the runtime's clock: simulated time in lockstep) stops the behavior with `{lua_port_down, Why}'.
-spec reattach(term(), map()) -> toroco_behavior:result().
reattach(Why, D = #{host := {_, _}}) ->
    {keep_state, orphan({lua_port_down, Why}, D), [unset]};
reattach(Why, D = #{name := Name, reattached := Times}) ->
    Now = toroco_clock:now_ms(),
    Recent = [T || T <- Times, Now - T < ?REATTACH_WINDOW_MS],
    case length(Recent) >= ?REATTACH_MAX of
        true ->
            logger:error("toroco_lua: ~p: lua_port died again (~p), ~b times in ~b ms; stopping",
                         [Name, Why, length(Recent) + 1, ?REATTACH_WINDOW_MS], ?LOG#{name => Name}),
            {stop, {lua_port_down, Why}};
        false ->
            case open(D) of
                {ok, D1, Actions} ->
                    logger:warning("toroco_lua: ~p: lua_port died (~p); its Lua code starts "
                                   "again in the new program", [Name, Why], ?LOG#{name => Name}),
                    D2 = D1#{reattached := [Now | Recent], out := queue:new(),
                             batch := queue:new()},
                    {keep_state, D2, [unset | toroco_lua_actions:actions(Actions, D2)]};
                {error, Reason} ->
                    {stop, Reason}
            end
    end.

%% The owner died, and the program with it: its supervisor starts another.
%% The behavior drops its inputs until then (real time: the world does not
%% wait) and starts its Lua code again in the new program, as when the
%% program alone dies, so that a layer of any number of Lua behaviors
%% outlives this too. No owner within ?OWNER_WAIT_MS: it stops.
owner_down(Why, D = #{host := {_, _}}) ->
    {keep_state, orphan({lua_port_owner_down, Why}, D#{owner := none}), [unset]};
owner_down(Why, D) ->
    Tries = ?OWNER_WAIT_MS div ?OWNER_POLL_MS,
    _ = erlang:start_timer(?OWNER_POLL_MS, self(), {lua_owner, Why, Tries}),
    {keep_state, D#{owner := none, id := none, out := queue:new(), batch := queue:new()}, [unset]}.

owner_back(Why, Tries, D) ->
    case whereis(toroco_lua_port) of
        Owner when is_pid(Owner) ->
            reattach({lua_port_owner_down, Why}, D#{owner := erlang:monitor(process, Owner)});
        undefined when Tries > 0 ->
            _ = erlang:start_timer(?OWNER_POLL_MS, self(), {lua_owner, Why, Tries - 1}),
            keep_state_and_data;
        undefined ->
            {stop, {lua_port_down, Why}}
    end.

%% A behavior whose code was made in a Lua state that is gone (with the
%% program that held it): nothing can run it again, so it leaves the
%% network (a call its own callback cannot make: done once it returns) and
%% meanwhile answers inspect with no state.
orphan(Why, D = #{name := Name}) ->
    logger:error("toroco_lua: ~p: the Lua state its code was made in is gone (~p); "
                 "removing it", [Name, Why], ?LOG#{name => Name}),
    _ = spawn(fun() -> toroco:remove_behavior(Name) end),
    D#{id := none, out := queue:new(), batch := queue:new()}.

%% @private The Lua state a behavior's code runs in, as its slots' behaviors
%% name it (`host'): the one it opened, or the one it was made in.
-spec state_id(map()) -> toroco_lua_port:id() | none.
state_id(#{host := {Host, _}}) -> Host;
state_id(#{id := Id}) -> Id.

%% @private The behavior's state as its process reaches it
%% (toroco_lua_port:conn()).
-spec conn(map()) -> toroco_lua_port:conn().
conn(#{id := Id, port := Port, owner := Owner}) ->
    {Id, Port, Owner}.

waits_of(D) ->
    waits_of(D, toroco_lua_port:stuck_ms()).

waits_of(D, Ms) ->
    case toroco_lua_port:waits(conn(D), Ms) of
        {ok, Ws} -> {ok, [#{task => T, kind => binary_to_atom(K), input => waited(I), timer => Timer}
                          || [T, K, I, Timer] <- Ws]};
        Error -> Error
    end.

waited(false) -> none;
waited(I) -> binary_to_atom(I).
