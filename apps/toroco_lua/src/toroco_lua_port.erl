%% @doc The owner of the `lua_port' program (c_src/lua_port): one per node,
%% registered as `toroco_lua_port', under {@link toroco_lua_sup}.
%%
%% It spawns `priv/lua_port' as an Erlang port (in stream mode, frames of
%% `{packet, 4}''s layout cut here, terms; the frames are in
%% c_src/lua_port/PROTOCOL.md), hands out state ids, and
%% passes the program's answers on. It never waits in a callback.
%%
%% <b>The event path skips it one way.</b> A Lua behavior writes its
%% activations (`input/4', `timer/4') and its `waits/1', `memory/1' to the
%% port itself (any process may write to a port), with its state's id as
%% the frame's `Ref', and waits for the answer in its own process. Answers
%% can only come to the port's owner: it reads the `Ref' from the answer's
%% first bytes (no decoding) and forwards the bytes to the state's process,
%% which decodes them. This saves the hop through this process on the way
%% in and the decoding in it on the way out; what the program answers is
%% what the behavior reads, in order, so nothing else is matched. The
%% answers to a state's pipelined requests (`Seq' > 0) that one read brought
%% go to its process in one message, `{toroco_lua_port, replies, [{Ref,
%% Bytes}]}', one event for the behavior instead of one each; a `Seq' 0
%% answer (`call/2''s, awaited alone) goes alone.
%%
%% Its own requests (`open', `close', `ping', `raw') carry negative refs and
%% wait in a FIFO queue (a frame the program could not read, a `bad_frame',
%% answers the oldest: a behavior checks that its values can cross before it
%% writes, so a bad frame is only ever one of `raw/1''s).
%%
%% The budget of a Lua activation counts VM instructions, so one long C call
%% (a pathological string pattern) would hang the program with it. A
%% behavior waits `stuck_ms' (app env, default 2000) for its answer and then
%% asks this process to kill the program (`stuck/1'), which is handled as any
%% death of the program; the owner watches the head of its own queue the
%% same way.
%%
%% If the program dies, every caller waiting gets `{error, {lua_port_down,
%% Why}}', every Lua behavior that opened a state is told (below) and a new
%% program is started at once, where the behaviors open their states again.
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>call `{request, Req}', `{open, ...}', `{attach, ...}'</td>
%%     <td>a Lua behavior → owner</td>
%%     <td>`open', `attach', `close', `ping'</td>
%%     <td>the program's result for that request</td></tr>
%% <tr><td>frame `{Op, Id, Id, ...}'</td><td>a Lua behavior → the program</td>
%%     <td>`input', `timer', `waits', `memory'</td>
%%     <td>`{toroco_lua_port, reply, Ref, Bytes}' (`Seq' 0) or
%%     `{toroco_lua_port, replies, [{Ref, Bytes}]}' forwarded by the owner</td></tr>
%% <tr><td>cast `{stuck, Port, Op}'</td><td>a Lua behavior → owner</td>
%%     <td>no answer in `stuck_ms'</td><td>none: the program is killed</td></tr>
%% <tr><td>`{toroco_lua_port, down, Ids, Why}'</td><td>owner → each behavior with a state</td>
%%     <td>the program died, with the behavior's states `Ids'</td><td>none: the
%%     behavior opens a new state (toroco_lua)</td></tr>
%% <tr><td>monitor `DOWN' of a behavior</td><td>runtime → owner</td>
%%     <td>a behavior with states stopped</td><td>the owner closes its states</td></tr>
%% </table>
%%
%% Functions: life `start_link/0', `os_pid/0', `states/0'; through the owner
%% `open/5', `attach/3', `close/1', `close_all/0', `ping/0'; straight to the program,
%% from the state's process, `input/4', `timer/4', `waits/1', `memory/1';
%% tests `raw/1'.
-module(toroco_lua_port).
-behaviour(gen_statem).

-include("toroco_lua_port.hrl").

-export([start_link/0, os_pid/0, ping/0, raw/1, states/0,
         open/5, attach/3, input/4, timer/4, waits/1, waits/2, memory/1, memory/2, close/1,
         close_all/0, crossable/1,
         request/3, encode/3, write/2, answer/2, await/2, await_replies/2, stuck/1, stuck_ms/0]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).
-export_type([id/0, conn/0, ref/0, request/0, action/0, result/0, limits/0]).

-type id() :: pos_integer().
%% A state as its process reaches it: its id, the port it lives in, and
%% that process's monitor of the owner.
-type conn() :: {id(), port(), reference()}.
%% A state's request's ref: its id, shifted, and its sequence number.
-type ref() :: pos_integer().
-type request() :: {input, integer(), atom(), term()} | {timer, integer(), pos_integer(), pos_integer()}
                 | waits | memory.
%% What a Lua activation asks for (PROTOCOL.md, "Actions").
-type action() :: {send, binary(), term(), default | non_neg_integer() | infinity}
                | {set, binary(), term()}
                | {unset, all | binary()}
                | {timer, pos_integer(), pos_integer(), non_neg_integer()}
                | {cancel, pos_integer()}
                | {print, binary()}
                | {warning, binary()}
                | {main, binary(), non_neg_integer(), term()}.
-type stop_reason() :: {lua_error, binary(), non_neg_integer(), binary()}
                     | {lua_limit, binary(), budget | memory}.
-type result() :: {ok, [action()]} | {stopped, stop_reason(), [action()]} | {error, term()}.
-type limits() :: #{budget := pos_integer(), memory := pos_integer()}.

-define(CALL_TIMEOUT, 5000).
-define(STUCK_MS, 2000).
-define(LOG, #{domain => [toroco, lua]}).

-record(d, {port :: port(),
            os_pid :: integer() | undefined,
            %% the owner's own refs count down from -1; a state's id is its ref
            next_ref = -1 :: neg_integer(),
            next_id = 1 :: pos_integer(),
            %% callers in the order their frames went out: {Ref, From | none, Op}
            pending = queue:new() :: queue:queue({neg_integer(), gen_statem:from() | none, term()}),
            %% behavior pid -> its monitor and state ids
            clients = #{} :: #{pid() => {reference(), [id()]}},
            %% state id -> the process its answers go to
            routes = #{} :: #{id() => pid()},
            %% the bytes of a frame not read whole yet
            rest = <<>> :: binary()}).

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> gen_statem:start_ret().
start_link() ->
    gen_statem:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc The OS pid of the running program (tests kill it).
-spec os_pid() -> integer() | undefined.
os_pid() ->
    gen_statem:call(?MODULE, os_pid, ?CALL_TIMEOUT).

-spec ping() -> {pong, pos_integer()} | {error, term()}.
ping() ->
    request({ping}).

%% @doc Sends bytes as one frame, whatever they are, and returns the
%% program's answer: how the tests show a bad frame is answered.
-spec raw(binary()) -> term().
raw(Bin) when is_binary(Bin) ->
    gen_statem:call(?MODULE, {raw, Bin}, ?CALL_TIMEOUT).

%% @doc A new state running `File' (relative to `Dir') for the calling
%% process, which is then told if the program dies; its states are closed
%% when it stops. `{ok, Id, Port, Actions}': the port the state lives in,
%% which the process writes its requests to.
-spec open(file:filename_all(), file:filename_all(), term(), limits(), integer()) ->
          {ok, id(), port(), [action()]} | {stopped, stop_reason(), [action()]} | {error, term()}.
open(File, Dir, Params, #{budget := B, memory := M}, Now) ->
    gen_statem:call(?MODULE, {open, self(), {unicode:characters_to_binary(File),
                                             unicode:characters_to_binary(Dir),
                                             Params, B, M}, Now}, ?CALL_TIMEOUT).

%% @doc A new id for the calling process in the Lua state opened as `Host',
%% running that state's slot `Slot' (a behavior its code added with inline
%% functions, or a converter): its tasks start, and the answer is as
%% `open/5''s. `{error, {unknown_state, Host}}' when that state is gone,
%% `{error, {unknown_slot, Slot}}' when it made no such slot.
-spec attach(id(), pos_integer(), integer()) ->
          {ok, id(), port(), [action()]} | {stopped, stop_reason(), [action()]} | {error, term()}.
attach(Host, Slot, Now) ->
    gen_statem:call(?MODULE, {attach, self(), Host, Slot, Now}, ?CALL_TIMEOUT).

%% @doc An activation: `Input' arrived with `Value'. In the state's process,
%% which waits for the answer.
-spec input(conn(), atom(), term(), integer()) -> result().
input(C, Input, Value, Now) ->
    call(C, {input, Now, Input, Value}).

%% @doc An activation: the state's timer `{Task, Seq}' fired.
-spec timer(conn(), pos_integer(), pos_integer(), integer()) -> result().
timer(C, Task, Seq, Now) ->
    call(C, {timer, Now, Task, Seq}).

%% @doc What each task of the state waits for: `[[Task, Kind, Input | false, TimerPending]]'.
-spec waits(conn()) -> {ok, list()} | {error, term()}.
waits(C) ->
    call(C, waits).

-spec memory(conn()) -> {ok, non_neg_integer()} | {error, term()}.
memory(C) ->
    call(C, memory).

%% @doc As `waits/1', giving up after `Ms' (the program is busy with other
%% states' work, or hung): `{error, {lua_port_timeout, Ref}}', and the late
%% answer comes to the caller as a `{toroco_lua_port, reply, Ref, Bytes}'
%% to drop. For `toroco:inspect/1', which must answer at once.
-spec waits(conn(), non_neg_integer()) -> {ok, list()} | {error, term()}.
waits(C, Ms) ->
    call(C, waits, Ms).

%% @doc As `memory/1', giving up after `Ms' (see `waits/2').
-spec memory(conn(), non_neg_integer()) -> {ok, non_neg_integer()} | {error, term()}.
memory(C, Ms) ->
    call(C, memory, Ms).

%% @doc Writes a request of the state to the program without waiting:
%% `{ok, Ref}', and its answer comes to the calling process: for `Seq' 0
%% (`call/2''s) as `{toroco_lua_port, reply, Ref, Bytes}' (read it with
%% `answer/2', or wait for it with `await/2'); for `Seq' 1..65535, which
%% tells apart the requests of one state in flight together, in a
%% `{toroco_lua_port, replies, [{Ref, Bytes}]}' with the answers after it
%% that came in the same read (wait for it with `await_replies/2').
-spec request(conn(), 0..65535, request()) -> {ok, ref()} | {error, term()}.
request(C, Seq, Req) ->
    case encode(C, Seq, Req) of
        {ok, Ref, Frame} ->
            case write(C, Frame) of
                ok -> {ok, Ref};
                Error -> Error
            end;
        {error, _} = Error -> Error
    end.

%% @doc `request/3' in two steps, so that a process can write several
%% requests at once: the frame (with its length) and its ref...
-spec encode(conn(), 0..65535, request()) -> {ok, ref(), iodata()} | {error, term()}.
encode({Id, _, _}, Seq, Req) ->
    Ref = Id bsl 16 bor Seq,
    case toroco_lua_frame:frame(Req, Ref, Id) of
        {ok, Frame} -> {ok, Ref, [<<(byte_size(Frame)):32>>, Frame]};
        {error, _} = Error -> Error
    end.

%% @doc ...and frames written to the program in one go.
-spec write(conn(), iodata()) -> ok | {error, {lua_port_down, closed}}.
write({_, Port, _}, Frames) ->
    try port_command(Port, Frames) of
        true -> ok
    catch error:badarg -> {error, {lua_port_down, closed}}
    end.

%% @doc The result in an answer `request/3''s caller got: an activation's
%% `result()', or `waits''s and `memory''s.
-spec answer(ref(), binary()) -> term().
answer(Ref, Bin) ->
    case toroco_lua_frame:decode(Bin) of
        {reply, Ref, Result} -> Result;
        Other -> {error, {lua_port_answer, Other}}
    end.

%% @doc Waits for the answer to request `Ref' of state `C', skipping any
%% other in the mailbox. While it waits: the program's death (the owner's
%% word, naming the state), the owner's, or no answer in stuck_ms, when the
%% owner is asked to kill the program and its word is awaited.
-spec await(conn(), ref()) -> term().
await({Id, Port, OwnerMon}, Ref) ->
    await(Id, Ref, one, Port, OwnerMon, stuck_ms()).

%% @doc As `await/2', for a pipelined request: `{replies, [{Ref, Bytes} |
%% Later]}', its answer and those to the state's later requests that came
%% with it, or an error.
-spec await_replies(conn(), ref()) -> {replies, [{ref(), binary()}, ...]} | {error, term()}.
await_replies({Id, Port, OwnerMon}, Ref) ->
    await(Id, Ref, many, Port, OwnerMon, stuck_ms()).

%% One request, its answer awaited.
call(C, Req) ->
    case request(C, 0, Req) of
        {ok, Ref} -> await(C, Ref);
        {error, _} = Error -> Error
    end.

call(C = {Id, Port, OwnerMon}, Req, Ms) ->
    case request(C, 0, Req) of
        {ok, Ref} -> await(Id, Ref, one, Port, OwnerMon, {bounded, Ms});
        {error, _} = Error -> Error
    end.

%% @doc Whether the program can read `Value' (PROTOCOL.md): numbers (whole
%% ones of up to 64 bits), atoms, binaries, proper lists, tuples and maps,
%% nested at most 31 deep inside a frame (`toroco_lua_frame:crossable/1').
-spec crossable(term()) -> boolean().
crossable(Value) ->
    toroco_lua_frame:crossable(Value).

await(Id, Ref, Kind, Port, OwnerMon, Wait) ->
    receive
        {?MODULE, reply, Ref, Bin} when Kind =:= one ->
            answer(Ref, Bin);
        {?MODULE, replies, [{Ref, _} | _] = Replies} when Kind =:= many ->
            {replies, Replies};
        ?LUA_PORT_DOWN(Ids, Why) ->
            case lists:member(Id, Ids) of
                true -> {error, {lua_port_down, Why}};
                false -> await(Id, Ref, Kind, Port, OwnerMon, Wait)  % about a state it had before
            end;
        {'DOWN', OwnerMon, process, _, Why} ->
            {error, {lua_port_owner_down, Why}}
    after wait_ms(Wait) ->
            case Wait of
                {bounded, _} -> {error, {lua_port_timeout, Ref}};
                ?CALL_TIMEOUT -> {error, {lua_port_timeout, Ref}};
                _ ->
                    stuck(Port),
                    await(Id, Ref, Kind, Port, OwnerMon, ?CALL_TIMEOUT)
            end
    end.

wait_ms({bounded, Ms}) -> Ms;
wait_ms(Ms) -> Ms.

%% @doc A state's request written to `Port' had no answer in stuck_ms: the
%% owner kills the program if it is still the one running.
-spec stuck(port()) -> ok.
stuck(Port) ->
    gen_statem:cast(?MODULE, {stuck, Port}).

%% @doc How long a state's request may wait for its answer (app env
%% `stuck_ms').
-spec stuck_ms() -> pos_integer().
stuck_ms() ->
    application:get_env(toroco_lua, stuck_ms, ?STUCK_MS).

-spec close(id()) -> ok | {error, term()}.
close(Id) ->
    request({close, Id}).

%% @doc Closes every state the calling process has: a behavior that starts
%% again in the same process (Brooks' reset runs init/1 anew) leaves none
%% of its last life behind.
-spec close_all() -> ok.
close_all() ->
    gen_statem:call(?MODULE, {close_all, self()}, ?CALL_TIMEOUT).

%% @doc How many states are open, all processes together.
-spec states() -> non_neg_integer().
states() ->
    gen_statem:call(?MODULE, states, ?CALL_TIMEOUT).

request(Req) ->
    try gen_statem:call(?MODULE, {request, Req}, ?CALL_TIMEOUT)
    catch
        exit:{noproc, _} -> {error, lua_port_not_running};
        exit:{timeout, _} -> {error, {lua_port_timeout, element(1, Req)}}
    end.

%%====================================================================
%% gen_statem
%%====================================================================

-spec callback_mode() -> gen_statem:callback_mode_result().
callback_mode() -> handle_event_function.

-spec init([]) -> gen_statem:init_result(up).
init([]) ->
    process_flag(trap_exit, true),
    case start_port() of
        {ok, D} -> {ok, up, D};
        {error, Reason} -> {stop, Reason}
    end.

%% The program: priv/lua_port, or app env `executable' (the release suite
%% runs the board's armhf build through qemu).
start_port() ->
    Exe = application:get_env(toroco_lua, executable,
                              filename:join(code:priv_dir(toroco_lua), "lua_port")),
    case filelib:is_regular(Exe) of
        false -> {error, {lua_port_missing, Exe}};
        true ->
            %% spin_us: how long the program polls for the next request
            %% before it sleeps in read(2) (0: it sleeps at once)
            Spin = application:get_env(toroco_lua, spin_us, 0),
            %% frames of {packet, 4}'s layout, cut here: a process writes
            %% several at once (one port_command is one packet in packet mode)
            Port = open_port({spawn_executable, Exe},
                             [stream, binary, exit_status, use_stdio,
                              {args, [integer_to_list(Spin)]}]),
            {os_pid, OsPid} = erlang:port_info(Port, os_pid),
            {ok, #d{port = Port, os_pid = OsPid}}
    end.

-spec handle_event(gen_statem:event_type(), term(), up, #d{}) ->
          gen_statem:event_handler_result(up).
handle_event({call, From}, Call, _S, D) ->
    handle_call(Call, From, D);
handle_event(info, {Port, {data, Bytes}}, _S, D = #d{port = Port, rest = Rest}) ->
    {Frames, Rest1} = toroco_lua_frame:cut(case Rest of <<>> -> Bytes; _ -> <<Rest/binary, Bytes/binary>> end),
    keep(D, frames_in(Frames, none, D#d{rest = Rest1}));
handle_event(cast, {stuck, Port}, _S, #d{port = Port, os_pid = OsPid}) ->
    logger:error("toroco_lua_port: lua_port has not answered a Lua behavior in ~b ms; "
                 "killing it", [stuck_ms()], ?LOG),
    kill(OsPid),
    keep_state_and_data;
handle_event(cast, {stuck, _OldPort}, _S, _D) ->
    keep_state_and_data;                      % that program is gone already
handle_event(info, {Port, {exit_status, Status}}, _S, D = #d{port = Port}) ->
    restart({exit_status, Status}, D);
handle_event({timeout, stuck}, Ref, _S, #d{pending = Q, os_pid = OsPid}) ->
    case queue:peek(Q) of
        {value, {Ref, _, Req}} ->
            logger:error("toroco_lua_port: lua_port has not answered ~p in ~b ms; killing it",
                         [element(1, Req), stuck_ms()], ?LOG),
            kill(OsPid),
            keep_state_and_data;
        _ -> keep_state_and_data
    end;
handle_event(info, {_OtherPort, {exit_status, _}}, _S, _D) ->
    keep_state_and_data;                      % the kill(1) above
handle_event(info, {'EXIT', Port, Why}, _S, D = #d{port = Port}) ->
    restart(Why, D);
handle_event(info, {'DOWN', _MRef, process, Pid, _Why}, _S, D = #d{clients = Cs}) ->
    case maps:take(Pid, Cs) of
        {{_, Ids}, Cs1} ->
            D1 = lists:foldl(fun(Id, Acc) -> send({close, Id}, none, Acc) end,
                             D#d{clients = Cs1, routes = maps:without(Ids, D#d.routes)}, Ids),
            {keep_state, D1};
        error -> keep_state_and_data
    end;
handle_event(Type, Content, _S, _D) ->
    logger:warning("toroco_lua_port: ignored ~p event ~p", [Type, Content], ?LOG),
    keep_state_and_data.

%% The calls, the same in the one state.
-spec handle_call(term(), gen_statem:from(), #d{}) -> gen_statem:event_handler_result(up).
handle_call({request, Req}, From, D) ->
    keep(D, send(Req, From, D));
handle_call({open, Pid, {File, Dir, Params, B, M}, Now}, From, D = #d{next_id = Id}) ->
    D1 = add_client(Pid, Id, D#d{next_id = Id + 1}),
    keep(D, send({open, Id, Now, File, Dir, Params, B, M}, From, D1));
handle_call({attach, Pid, Host, Slot, Now}, From, D = #d{next_id = Id}) ->
    D1 = add_client(Pid, Id, D#d{next_id = Id + 1}),
    keep(D, send({attach, Id, Host, Slot, Now}, From, D1));
handle_call({raw, Bin}, From, D = #d{port = Port, pending = Q, next_ref = Ref}) ->
    true = port_command(Port, [<<(byte_size(Bin)):32>>, Bin]),
    keep(D, D#d{pending = queue:in({Ref, From, raw}, Q), next_ref = Ref - 1});
handle_call(os_pid, From, #d{os_pid = OsPid}) ->
    {keep_state_and_data, [{reply, From, OsPid}]};
handle_call(states, From, #d{clients = Cs}) ->
    {keep_state_and_data, [{reply, From, lists:sum([length(Ids) || {_, Ids} <- maps:values(Cs)])}]};
handle_call({close_all, Pid}, From, D = #d{clients = Cs}) ->
    case maps:take(Pid, Cs) of
        {{MRef, Ids}, Cs1} ->
            erlang:demonitor(MRef, [flush]),
            D1 = lists:foldl(fun(Id, Acc) -> send({close, Id}, none, Acc) end,
                             D#d{clients = Cs1, routes = maps:without(Ids, D#d.routes)}, Ids),
            {keep_state, D1, [{reply, From, ok} | watch(D, D1)]};
        error ->
            {keep_state_and_data, [{reply, From, ok}]}
    end.

-spec terminate(term(), up, #d{}) -> ok.
terminate(_Reason, _S, #d{port = Port}) ->
    catch port_close(Port),
    ok.

%%====================================================================
%% Frames
%%====================================================================

%% The new data, and the watchdog moved to the new head of the queue if the
%% head changed.
keep(D0, D) ->
    {keep_state, D, watch(D0, D)}.

watch(#d{pending = Q0}, #d{pending = Q}) ->
    case {queue:peek(Q0), queue:peek(Q)} of
        {Same, Same} -> [];
        {_, empty} -> [{{timeout, stuck}, cancel}];
        {_, {value, {Ref, _, _}}} -> [{{timeout, stuck}, stuck_ms(), Ref}]
    end.

%% The answers one read brought, in order. A state's answers to pipelined
%% requests are gathered while they follow each other (`Run': the state's
%% id, its process and the answers so far, last first) and go to its
%% process in one message.
frames_in([], Run, D) ->
    replies(Run),
    D;
frames_in([Bin | Bins], Run, D = #d{routes = Routes}) ->
    case toroco_lua_frame:ref(Bin) of
        Ref when is_integer(Ref), Ref band 16#ffff =/= 0, is_map_key(Ref bsr 16, Routes) ->
            Id = Ref bsr 16,
            case Run of
                {Id, Pid, Rs} -> frames_in(Bins, {Id, Pid, [{Ref, Bin} | Rs]}, D);
                _ ->
                    replies(Run),
                    frames_in(Bins, {Id, map_get(Id, Routes), [{Ref, Bin}]}, D)
            end;
        _ ->
            replies(Run),
            frames_in(Bins, none, frame_in(Bin, D))
    end.

replies(none) -> ok;
replies({_Id, Pid, Rs}) -> Pid ! {?MODULE, replies, lists:reverse(Rs)}, ok.

frame_in(Bin, D = #d{routes = Routes}) ->
    case toroco_lua_frame:ref(Bin) of
        Ref when is_integer(Ref), is_map_key(Ref bsr 16, Routes) ->
            %% a state's answer to call/2, to its process as it came
            map_get(Ref bsr 16, Routes) ! {?MODULE, reply, Ref, Bin},
            D;
        Ref when is_integer(Ref), Ref > 0 ->
            %% a closed state's (its process died with a request out), or raw/1's
            case queue:peek(D#d.pending) of
                {value, {_, _, raw}} -> answered(toroco_lua_frame:decode(Bin), D);
                _ -> D
            end;
        _ ->
            answered(toroco_lua_frame:decode(Bin), D)
    end.

%% kill(1) as a port of its own: nothing here waits for it.
kill(OsPid) ->
    _ = open_port({spawn_executable, os:find_executable("kill")},
                  [{args, ["-9", integer_to_list(OsPid)]}, exit_status]),
    ok.

%% Sends {Op, Ref, Args...}; the caller waits in the queue.
send(Req, From, D = #d{port = Port, next_ref = Ref, pending = Q}) ->
    Frame = term_to_binary(erlang:insert_element(2, Req, Ref)),
    true = port_command(Port, [<<(byte_size(Frame)):32>>, Frame]),
    D#d{next_ref = Ref - 1, pending = queue:in({Ref, From, Req}, Q)}.

answered(Answer, D = #d{pending = Q}) ->
    case queue:out(Q) of
        {{value, {Ref, From, Req}}, Q1} ->
            reply(From, toroco_lua_frame:result(Answer, Ref, Req, D#d.port)),
            forget(Answer, Req, D#d{pending = Q1});
        {empty, _} ->
            logger:error("toroco_lua_port: an answer nobody asked for: ~p", [Answer], ?LOG),
            D
    end.

%% A state that stopped, was closed or could not open is no client's any more.
forget({reply, _, {stopped, _, _}}, Req, D) -> drop_id(element(2, Req), D);
forget(_, {close, Id}, D) -> drop_id(Id, D);
forget({reply, _, {error, _}}, {open, Id, _, _, _, _, _, _}, D) -> drop_id(Id, D);
forget({bad_frame, _}, {open, Id, _, _, _, _, _, _}, D) -> drop_id(Id, D);
forget({reply, _, {error, _}}, {attach, Id, _, _, _}, D) -> drop_id(Id, D);
forget({bad_frame, _}, {attach, Id, _, _, _}, D) -> drop_id(Id, D);
forget(_, _, D) -> D.

reply(none, _) -> ok;
reply(From, Result) -> gen_statem:reply(From, Result).

add_client(Pid, Id, D = #d{clients = Cs, routes = Rs}) ->
    case Cs of
        #{Pid := {MRef, Ids}} -> D#d{clients = Cs#{Pid := {MRef, [Id | Ids]}}, routes = Rs#{Id => Pid}};
        #{} -> D#d{clients = Cs#{Pid => {erlang:monitor(process, Pid), [Id]}}, routes = Rs#{Id => Pid}}
    end.

drop_id(Id, D0 = #d{routes = Rs}) ->
    D = D0#d{routes = maps:remove(Id, Rs)},
    Cs = D#d.clients,
    Cs1 = maps:filtermap(fun(_Pid, {MRef, Ids}) ->
                                 case lists:delete(Id, Ids) of
                                     [] -> erlang:demonitor(MRef, [flush]), false;
                                     Ids1 -> {true, {MRef, Ids1}}
                                 end
                         end, Cs),
    D#d{clients = Cs1}.

%% The program died: everyone waiting is answered, every behavior with a
%% state is told, and a new program starts.
restart(Why, D = #d{pending = Q, clients = Cs}) ->
    logger:error("toroco_lua_port: lua_port died (~p); ~b Lua behaviors restart",
                 [Why, map_size(Cs)], ?LOG),
    [reply(From, {error, {lua_port_down, Why}}) || {_, From, _} <- queue:to_list(Q)],
    %% told in the order their states were opened, each as a notice: in
    %% lockstep every behavior opens its new state as a step, in that order
    _ = [begin
             erlang:demonitor(MRef, [flush]),
             toroco_clock:notify(Pid, ?LUA_PORT_DOWN(Ids, Why), {toroco_lua_port, down, Why})
         end || {_, Pid, MRef, Ids} <- lists:sort([{lists:min(Ids), Pid, MRef, Ids}
                                                 || {Pid, {MRef, Ids}} <- maps:to_list(Cs)])],
    case start_port() of
        {ok, D1} -> {keep_state, D1#d{next_id = D#d.next_id, next_ref = D#d.next_ref},
                     [{{timeout, stuck}, cancel}]};
        {error, Reason} -> {stop, Reason}
    end.
