%% @doc Behaviors written in Lua 5.1 against the original Torocó API (SPEC
%% §16): a `toroco_behavior' callback module whose code is a Lua file, run in
%% a state of the `lua_port' program ({@link toroco_lua_port}).
%%
%% A Lua behavior is a behavior like any other: a gen_statem in its layer,
%% with suppression, inhibition, latches, holds, suspend/resume/reset/remove,
%% the tap and recordings. Each input it gets is one activation of its Lua
%% state, written to the program by this process; up to `window' are in
%% flight (one at a time, inside `handle_input/4', in lockstep: see
%% `activate/2'), and what the Lua code emitted comes back, in order, as the
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
-module(toroco_lua).
-behaviour(toroco_behavior).

-include("toroco_lua_port.hrl").

-export([add_behavior/2, load_main/2, waits/1, memory/1, reload/1]).
-export([interface/1, init/1, handle_input/4, handle_event/4, info/2]).
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
%% call refused stops there, with the main file's line.
-spec load_main(file:filename_all(), main_opts()) ->
          {ok, #{behaviors := [atom()]}} | {error, {file:filename_all(), non_neg_integer(), term()}}.
load_main(Path, Opts) ->
    Abs = filename:absname(Path),
    Limits = #{budget => maps:get(budget, Opts, env(budget)),
               memory => maps:get(memory, Opts, env(memory))},
    D = #{name => main, file => Path, args => #{}, id => none},
    case toroco_lua_port:open(filename:basename(Abs), filename:dirname(Abs),
                              maps:get(params, Opts, #{}), Limits, toroco_clock:now_ms()) of
        {ok, Id, _Port, Actions} ->
            _ = [print(Text, D) || {print, Text} <- Actions],
            Ctx = #{root => filename:dirname(Path), opts => Opts, host => Id, file => Path},
            Calls = [{Op, Line, Args} || {main, Op, Line, Args} <- Actions],
            %% converters first, so that the wiring names what they emit
            {Polling, Others} = lists:partition(
                                  fun({Op, _, _}) -> Op =:= <<"configure_polling">> end, Calls),
            Result = apply_main(Polling ++ Others, Path, Ctx, []),
            %% the state lives on while a behavior it hosts does
            _ = toroco_lua_port:close(Id),
            Result;
        {stopped, {lua_error, _, Line, Msg} = R, _} ->
            {error, {path(element(2, R), D), Line, Msg}};
        {stopped, {lua_limit, Src, What}, _} ->
            {error, {path(Src, D), 0, {lua_limit, What}}};
        {error, Why} ->
            {error, {Path, 0, Why}}
    end.

apply_main([], _Path, _Ctx, Loaded) ->
    {ok, #{behaviors => lists:reverse(Loaded)}};
apply_main([{Op, Line, Args} | Rest], Path, Ctx, Loaded) ->
    case main_call(Op, Args, Ctx) of
        ok -> apply_main(Rest, Path, Ctx, Loaded);
        {loaded, Name} -> apply_main(Rest, Path, Ctx, [Name | Loaded]);
        {error, Why} -> {error, {Path, Line, Why}}
    end.

%% One wiring call of Lua code (main.lua, or a behavior changing the
%% network); paths start at the program's folder `root'.
main_call(<<"load_behavior">>, [Name, File, Params], #{root := Root, opts := Opts}) ->
    B = binary_to_atom(Name),
    Layer = maps:get(B, maps:get(layers, Opts, #{}), 0),
    Limits = maps:with([budget, memory, layers], Opts),
    case toroco_lua:add_behavior(B, Limits#{file => lua_file(Root, File), root => Root,
                                            layer => Layer, params => table(Params)}) of
        ok -> {loaded, B};
        Error -> Error
    end;
main_call(<<"add_behavior">>, [Name, Slot], Ctx = #{root := Root, opts := Opts, host := Host}) ->
    B = binary_to_atom(Name),
    Layer = maps:get(B, maps:get(layers, Opts, #{}), 0),
    Limits = maps:with([budget, memory, layers], Opts),
    case toroco_lua:add_behavior(B, Limits#{file => maps:get(file, Ctx), root => Root,
                                            layer => Layer, host => {Host, Slot}}) of
        ok -> {loaded, B};
        Error -> Error
    end;
main_call(<<"set_inputs">>, [R, Inputs], _Ctx) ->
    toroco:set_inputs(binary_to_atom(R),
                      maps:from_list([{binary_to_atom(I), lists:reverse(sources(Ss))}
                                      || {I, Ss} <- maps:to_list(table(Inputs))]));
main_call(<<"set_inhibitors">>, [E, Outputs], _Ctx) ->
    toroco:set_inhibitors(binary_to_atom(E),
                          maps:from_list([{binary_to_atom(O), sources(Ss)}
                                          || {O, Ss} <- maps:to_list(table(Outputs))]));
main_call(<<"suspend_behavior">>, [B], _Ctx) -> toroco:suspend_behavior(binary_to_atom(B));
main_call(<<"resume_behavior">>, [B], _Ctx) -> toroco:resume_behavior(binary_to_atom(B));
main_call(<<"remove_behavior">>, [B], _Ctx) -> toroco:remove_behavior(binary_to_atom(B));
main_call(<<"configure_polling">>, [D, E, Ms, false], _Ctx) ->
    configure_polling(D, E, Ms);
main_call(<<"configure_polling">>, [D, E, Ms, Slot], Ctx) ->
    case configure_polling(D, E, Ms) of
        ok -> converter(binary_to_atom(D), binary_to_atom(E), Slot, Ctx);
        Error -> Error
    end;
main_call(<<"run">>, _, _Ctx) -> ok;
main_call(Op, Args, _Ctx) -> {error, {bad_main_call, {Op, Args}}}.

sources(Ss) -> [converted({binary_to_atom(E), binary_to_atom(O)}) || [E, O] <- Ss].

%% The behavior named `'D.E'', when there is one, stands for source `{D,
%% E}': a converter (below), or a device's output under the name the
%% original gave it (torobot's `camera.update').
converted({D, E} = Src) ->
    Conv = converter_name(D, E),
    case toroco:inspect(Conv) of
        #{kind := behavior} -> {Conv, E};
        _ -> Src
    end.

%% The behavior that runs the converter of source `{D, E}': `'D.E'', in the
%% Lua state of the code that configured it, between the device and those
%% wired to `device.D.E' by Lua code, in layer 0.
converter_name(D, E) ->
    binary_to_atom(<<(atom_to_binary(D))/binary, ".", (atom_to_binary(E))/binary>>).

converter(D, E, Slot, Ctx = #{root := Root, opts := Opts, host := Host}) ->
    Conv = converter_name(D, E),
    _ = case toroco:inspect(Conv) of
            #{kind := behavior, module := ?MODULE} -> toroco:remove_behavior(Conv);
            _ -> ok
        end,
    Limits = maps:with([budget, memory], Opts),
    case toroco_lua:add_behavior(Conv, Limits#{file => maps:get(file, Ctx), root => Root,
                                               layer => 0, host => {Host, Slot},
                                               inputs => [E], outputs => [E]}) of
        ok -> toroco:set_inputs(Conv, #{E => [{D, E}]});
        Error -> Error
    end.

%% configure_polling(device.D.E, seconds): D must be a device on the node
%% with output E; one that can be polled (toroco_poll_sensor) is asked to
%% poll every Ms, one that emits by itself answers unknown_call and is left
%% as it is.
configure_polling(D, E, Ms) ->
    Dev = binary_to_atom(D),
    Out = binary_to_atom(E),
    case toroco:inspect(Dev) of
        #{kind := device, outputs := #{Out := _}} ->
            try toroco_device:call(Dev, {toroco_poll, every_ms, Ms}, 5000) of
                ok -> ok;
                {error, {unknown_call, _}} -> ok;
                {error, _} = Error -> Error
            catch exit:Why -> {error, {Dev, Why}}
            end;
        #{kind := device} -> {error, {unknown_output, {Dev, Out}}};
        #{} -> {error, {not_a_device, Dev}};
        {error, _} = Error -> Error
    end.

%% An empty Lua table crosses as [] (SPEC §16); as a set of keys it is #{}.
table([]) -> #{};
table(M) when is_map(M) -> M.

%% `path' or `path.lua', relative to `Dir'.
lua_file(Dir, File) ->
    P = filename:join(Dir, unicode:characters_to_list(File)),
    case filename:extension(P) =:= ".lua" orelse filelib:is_regular(P) of
        true -> P;
        false -> P ++ ".lua"
    end.

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
                {ok, D1, Actions} -> {ok, running, D1, actions(Actions, D1)};
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
    activate({input, toroco_clock:now_ms(), Input, Value}, D).

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
    activate({timer, toroco_clock:now_ms(), Task, Seq}, D);
handle_event({timeout, {lua, _}}, {lua_timer, _OldGen, _, _}, _S, _D) ->
    keep_state_and_data;                      % a timer of the state before a reload
handle_event(info, {toroco_lua_port, replies, Replies}, S, D) ->
    settle(S, replies(Replies, D));
handle_event(info, {toroco_lua_port, reply, _Ref, _Bin}, _S, _D) ->
    keep_state_and_data;                      % a call's, after its caller gave up
handle_event(info, {?MODULE, flush, Id}, S, D = #{id := Id}) ->
    settle(S, flushed(D));
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
    settle(S, owner_down(Why, D));
handle_event(info, {timeout, _, {lua_owner, Why, Tries}}, S, D) ->
    settle(S, owner_back(Why, Tries, D));
handle_event(info, ?LUA_PORT_DOWN(Ids, Why), S, D = #{id := Id}) ->
    case lists:member(Id, Ids) of
        true -> settle(S, reattach(Why, D));
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
    settle(S, reload(From, D0));
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
    case drain(D0) of
        {keep_state, D = #{id := Old, name := Name}, Drained} ->
            case open(D) of
                {ok, D1, Actions} ->
                    _ = toroco_lua_port:close(Old),
                    logger:notice("toroco_lua: ~p reloaded ~ts", [Name, maps:get(file, D)],
                                  ?LOG#{name => Name}),
                    {keep_state, D1, Drained ++ [{reply, From, ok} | actions(Actions, D1)]};
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
    {Root, Rel} = root(File, Args),
    Limits = #{budget => maps:get(budget, Args, env(budget)),
               memory => maps:get(memory, Args, env(memory))},
    opened(toroco_lua_port:open(Rel, Root, maps:get(params, Args, #{}), Limits,
                                toroco_clock:now_ms()), D).

%% The behavior's code is in the program now (opened or attached), or not.
opened({ok, Id, Port, Actions}, D) ->
    {ok, D#{id := Id, port := Port, gen := maps:get(gen, D) + 1}, Actions};
opened({stopped, Reason, Actions}, D) ->
    _ = actions(Actions, D),
    {error, reason(Reason, D)};
opened({error, _} = Error, _D) ->
    Error.

env(Key) ->
    {ok, V} = application:get_env(toroco_lua, Key),
    V.

%% An activation. Up to `window' (app env, default 32) of a behavior's
%% activations are in flight: the request is written to the program and the
%% callback returns, the answer comes as a message and its emissions are
%% the actions of that event, in the order the inputs came (the program
%% answers in order). The program then reads the requests that queued up in
%% one go and the answers come back in one go, instead of one round trip
%% through the pipe each: an event stream is not paced by the round trip.
%% Past the window, requests wait here and go out as answers come: the
%% callback never waits, so inspect, suspend and the tap are answered at
%% once whatever the program is doing.
%%
%% In lockstep the behavior enters state `step_pending' until every answer
%% is in: the engine holds the lockstep step until it leaves that state
%% (toroco_behavior), so that a step still holds its emissions.
activate(Req, D) ->
    case toroco_clock:lockstep_server() of
        none -> pipeline(Req, D);
        _ ->
            case queue(Req, D) of
                {ok, D1} ->
                    case flush(D1) of
                        {ok, D2} -> {next_state, step_pending, D2, []};
                        {Error, D2} -> settle(step_pending, activation(Error, D2))
                    end;
                Error -> activation(Error, D)
            end
    end.

%% A request kept, to be written by flush/1.
queue(Req, D = #{seq := Seq, batch := Batch}) ->
    case toroco_lua_port:encode(conn(D), Seq, Req) of
        {ok, Ref, Frame} ->
            {ok, D#{seq := Seq rem 65535 + 1, batch := queue:in({Ref, Frame}, Batch)}};
        Error -> Error
    end.

%% While more messages wait in the mailbox, the requests are kept and
%% written together when the `flush' this sends itself comes, after them:
%% one write for a burst of inputs.
pipeline(Req, D0 = #{id := Id, out := Out, batch := Batch}) ->
    case queue(Req, D0) of
        {ok, D1} ->
            case queue:is_empty(Batch) andalso queue:is_empty(Out) of
                false ->
                    %% its flush is on its way, or requests written are in
                    %% flight: this one is written, with whatever else
                    %% comes meanwhile, when their answers come (the
                    %% program would take it after them anyway): one write
                    %% instead of one per input
                    {keep_state, D1, []};
                true ->
                    case process_info(self(), message_queue_len) of
                        {message_queue_len, 0} -> flushed(D1);
                        _ ->
                            self() ! {?MODULE, flush, Id},
                            {keep_state, D1, []}
                    end
            end;
        Error ->
            activation(Error, D0)
    end.

%% The requests kept, written, as many as the window has room for; the
%% watchdog counts from now for them.
flush(D = #{batch := Batch, out := Out, window := Window}) ->
    case min(Window - queue:len(Out), queue:len(Batch)) of
        N when N =< 0 -> {ok, D};
        N ->
            {Now, Later} = queue:split(N, Batch),
            Items = queue:to_list(Now),
            D1 = watchdog(D),
            Due = erlang:monotonic_time(millisecond) + maps:get(stuck_ms, D1),
            D2 = D1#{batch := Later,
                     out := queue:join(Out, queue:from_list([{Ref, Due} || {Ref, _} <- Items]))},
            case toroco_lua_port:write(conn(D2), [Frame || {_, Frame} <- Items]) of
                ok -> {ok, D2};
                Error -> {Error, D2}
            end
    end.

flushed(D) ->
    case flush(D) of
        {ok, D1} -> {keep_state, D1, []};
        {Error, D1} -> activation(Error, D1)
    end.

%% In lockstep, the step is over once no request is out any more.
settle(step_pending, {keep_state, D = #{out := Out, batch := Batch}, Actions}) ->
    case queue:is_empty(Out) andalso queue:is_empty(Batch) of
        true -> {next_state, running, D, Actions};
        false -> {keep_state, D, Actions}
    end;
settle(_S, Result) ->
    Result.

%% The answers to pipelined activations that came together, in order: the
%% actions of all of them, one event. One that ends the behavior (or fails)
%% after others is left for the next event, inserted before anything else
%% (`next_event'), so that the emissions before it go out first.
replies(Replies, D0) ->
    case replies(Replies, D0, []) of
        {keep_state, D, Actions} ->
            case flush(D) of
                {ok, D1} -> {keep_state, D1, Actions};
                {Error, D1} -> then(Actions, activation(Error, D1))
            end;
        Stop ->
            Stop
    end.

replies([], D, Acc) ->
    {keep_state, D, lists:append(lists:reverse(Acc))};
replies([{Ref, Bin} | More] = Replies, D = #{out := Out}, Acc) ->
    case queue:peek(Out) of
        {value, {Ref, _}} ->
            case toroco_lua_port:answer(Ref, Bin) of
                {ok, _} = Ok ->
                    {keep_state, D1, Actions} = activation(Ok, D#{out := queue:drop(Out)}),
                    replies(More, D1, [Actions | Acc]);
                _Other when Acc =/= [] ->
                    Next = {next_event, info, {toroco_lua_port, replies, Replies}},
                    {keep_state, D, lists:append(lists:reverse(Acc)) ++ [Next]};
                Other ->
                    case activation(Other, D#{out := queue:drop(Out)}) of
                        {keep_state, D1, Actions} -> replies(More, D1, [Actions]);
                        Stop -> Stop
                    end
            end;
        _ ->
            replies(More, D, Acc)             % of a state it no longer has
    end.

%% The answers to every request kept or in flight, awaited in order (a
%% reload's: the events sent to the old code are answered by it first).
drain(D) ->
    drain(D, []).

drain(D = #{out := Out, batch := Batch}, Acc) ->
    case queue:peek(Out) of
        empty ->
            case queue:is_empty(Batch) of
                true -> {keep_state, D, lists:append(lists:reverse(Acc))};
                false ->
                    case flush(D) of
                        {ok, D1} -> drain(D1, Acc);
                        {Error, D1} -> then(lists:append(lists:reverse(Acc)), activation(Error, D1))
                    end
            end;
        {value, {Ref, _}} ->
            case toroco_lua_port:await_replies(conn(D), Ref) of
                {replies, Replies} -> drained(Replies, D, Acc);
                Error ->
                    case activation(Error, D#{out := queue:drop(Out)}) of
                        {keep_state, D1, Actions} -> drain(D1, [Actions | Acc]);
                        Stop -> Stop
                    end
            end
    end.

%% The answers awaited while draining, each in turn.
drained([], D, Acc) ->
    drain(D, Acc);
drained([{Ref, Bin} | More], D = #{out := Out}, Acc) ->
    case queue:peek(Out) of
        {value, {Ref, _}} ->
            case activation(toroco_lua_port:answer(Ref, Bin), D#{out := queue:drop(Out)}) of
                {keep_state, D1, Actions} -> drained(More, D1, [Actions | Acc]);
                Stop -> Stop
            end;
        _ -> drained(More, D, Acc)
    end.

then(Actions, {keep_state, D, More}) -> {keep_state, D, Actions ++ More};
then(_Actions, Stop) -> Stop.

%% A request unanswered for stuck_ms gets the program killed (the owner
%% checks it is still the one running). Each request in flight carries the
%% time it is due by; one timer at a time checks the oldest and is set again
%% for the next one's due time, rather than one timer (and its message, two
%% seconds later) for every activation.
watchdog(D = #{watched := true}) ->
    D;
watchdog(D = #{stuck_ms := Ms}) ->
    _ = erlang:start_timer(Ms, self(), lua_stuck),
    D#{watched := true}.

activation({ok, Actions}, D) ->
    {keep_state, D, actions(Actions, D)};
activation({stopped, Reason, Actions}, D = #{name := Name}) ->
    _ = actions(Actions, D),                  % its prints; emissions die with it
    Why = reason(Reason, D),
    logger:error("toroco_lua: ~p stopped: ~p", [Name, Why], ?LOG#{name => Name}),
    {stop, Why};
activation({error, {Bad, Why}}, D = #{name := Name}) when Bad =:= bad_frame; Bad =:= bad_value ->
    %% a value the port cannot take (a pid, a fun, too many values): this
    %% event only
    logger:warning("toroco_lua: ~p got a value that cannot cross to Lua (~p); dropped",
                   [Name, {Bad, Why}], ?LOG#{name => Name}),
    {keep_state, D, []};
activation({error, {lua_port_down, Why}}, D) ->
    reattach(Why, D);
activation({error, Why}, _D) ->
    {stop, {lua_port, Why}}.

%% The program died (killed, crashed, or hung and killed by its owner, who
%% has started a new one by now): the behavior's process stays and its Lua
%% code starts again in a new state, as a Brooks reset does: its outputs are
%% unset (latches and holds end), the new state's emissions follow, and the
%% old state's timers, named with the old id, do nothing. No supervisor sees
%% it, so one program death is not one restart per Lua behavior of a layer.
%% A program that dies more than ?REATTACH_MAX times in ?REATTACH_WINDOW_MS
%% (of the runtime's clock: simulated time in lockstep) stops the behavior with `{lua_port_down, Why}'.
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
                    {keep_state, D2, [unset | actions(Actions, D2)]};
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

%% The Lua state a behavior's code runs in, as its slots' behaviors name it
%% (`host'): the one it opened, or the one it was made in.
state_id(#{host := {Host, _}}) -> Host;
state_id(#{id := Id}) -> Id.

%% {lua_error, File, Line, Message}: File as the user named it for the
%% behavior's own file, else the module's path in the program's folder.
reason({lua_error, Src, Line, Msg}, D) -> {lua_error, path(Src, D), Line, Msg};
reason({lua_limit, Src, What}, D) -> {lua_limit, path(Src, D), What}.

path(Src, #{file := File, args := Args}) ->
    {Root, Rel} = root(File, Args),
    case unicode:characters_to_list(Src) of
        Rel -> File;
        Other -> filename:join(Root, Other)
    end.

%% The program's folder and the file's path inside it; a file outside the
%% folder given is its own folder's.
root(File, Args) ->
    Abs = unicode:characters_to_list(filename:absname(File)),
    Root = unicode:characters_to_list(filename:absname(maps:get(root, Args, filename:dirname(Abs)))),
    case string:prefix(Abs, Root ++ "/") of
        nomatch -> {filename:dirname(Abs), filename:basename(Abs)};
        Rel ->
            case filelib:safe_relative_path(Rel, Root) of
                unsafe -> {filename:dirname(Abs), filename:basename(Abs)};
                Safe -> {Root, Safe}
            end
    end.

%% The behavior's state as its process reaches it (toroco_lua_port:conn()).
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

%% The port's actions as the engine's: emissions and timers. A behavior
%% removing, suspending or resuming itself would wait on itself from its
%% own callback: that is done once the callback is over, after the calls
%% it made next (the thesis' level2 removes itself, then adds level3).
actions(Actions, D) ->
    case lists:keymember(main, 1, Actions) of
        false -> lists:filtermap(fun(A) -> action(A, D) end, Actions);
        true -> wiring_actions(Actions, D)
    end.

wiring_actions(Actions, D = #{name := Name}) ->
    Self = atom_to_binary(Name),
    {Later, Now} = lists:partition(
                     fun({main, Op, _, [B]}) ->
                             B =:= Self andalso lists:member(Op, [<<"remove_behavior">>,
                                                                  <<"suspend_behavior">>,
                                                                  <<"resume_behavior">>]);
                        (_) -> false
                     end, Actions),
    Result = lists:filtermap(fun(A) -> action(A, D) end, Now),
    _ = case Later of
            [] -> ok;
            _ ->
                Ctx = main_ctx(D),
                spawn(fun() -> [main_call_logged(Op, Args, Ctx, Name)
                                || {main, Op, _, Args} <- Later] end)
        end,
    Result.

main_ctx(D = #{file := File, args := Args0}) ->
    #{root => element(1, root(File, Args0)), file => File, host => state_id(D),
      opts => maps:with([budget, memory, layers], Args0)}.

action({send, Out, V, Hold}, D) ->
    with_output(Out, D, fun(O) -> case Hold of
                                      default -> {send, #{O => V}};
                                      _ -> {send, #{O => V}, #{hold => Hold}}
                                  end
                        end);
action({set, Out, V}, D) ->
    with_output(Out, D, fun(O) -> {set, #{O => V}} end);
action({unset, all}, _D) ->
    {true, unset};
action({unset, Out}, D) ->
    with_output(Out, D, fun(O) -> {unset, [O]} end);
action({timer, Task, Seq, Ms}, #{gen := Gen}) ->
    {true, {{timeout, {lua, Task}}, Ms, {lua_timer, Gen, Task, Seq}}};
action({cancel, Task}, _D) ->
    {true, {{timeout, {lua, Task}}, cancel}};
action({print, Text}, D) ->
    print(Text, D),
    false;
action({warning, Text}, #{name := Name}) ->
    logger:warning("toroco_lua: ~p: ~ts", [Name, Text], ?LOG#{name => Name}),
    false;
action({main, Op, _Line, Args}, D = #{name := Name}) ->
    %% a behavior changing the network (the thesis' suspender, add/remove)
    _ = main_call_logged(Op, Args, main_ctx(D), Name),
    false.

main_call_logged(Op, Args, Ctx, Name) ->
    case main_call(Op, Args, Ctx) of
        {error, Why} ->
            logger:warning("toroco_lua: ~p: ~ts refused: ~p", [Name, Op, Why], ?LOG#{name => Name});
        _ -> ok
    end.

print(Text, #{name := Name}) ->
    logger:notice("~p: ~ts", [Name, Text], ?LOG#{name => Name}).

%% Ports are open: an output exists once the code emits on it. Names are
%% atoms, so a name that no atom has yet is made one while the atom table
%% is less than 90 % full (a program that makes names without end would
%% fill it and take the node down); past that such emissions are dropped
%% with a warning.
with_output(Out, #{name := Name}, Fun) ->
    try binary_to_existing_atom(Out) of
        O -> {true, Fun(O)}
    catch error:badarg ->
            case erlang:system_info(atom_count) < erlang:system_info(atom_limit) * 9 div 10
                andalso byte_size(Out) =< 255 of
                true -> {true, Fun(binary_to_atom(Out))};
                false ->
                    logger:warning("toroco_lua: ~p emitted on new output ~ts with the atom "
                                   "table nearly full; dropped", [Name, Out], ?LOG#{name => Name}),
                    false
            end
    end.
