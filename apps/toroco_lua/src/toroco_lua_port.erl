%% @doc The owner of the `lua_port' program (c_src/lua_port): one per node,
%% registered as `toroco_lua_port', under {@link toroco_lua_sup}.
%%
%% It spawns `priv/lua_port' as an Erlang port (`{packet, 4}', terms; the
%% frames are in c_src/lua_port/PROTOCOL.md), hands out state ids, and
%% matches the program's answers to the callers. It never waits in a
%% callback: a request goes to the program and its caller is answered when
%% the program replies. The program answers every frame, in order, so the
%% callers wait in a FIFO queue (a frame the program could not read, a
%% `bad_frame', answers the oldest).
%%
%% The budget of a Lua activation counts VM instructions, so one long C call
%% (a pathological string pattern) would hang the program with it. The
%% owner watches the request at the head of the queue: one unanswered after
%% `stuck_ms' (app env, default 2000) gets the program killed, and it is
%% handled as any death of the program.
%%
%% If the program dies, every caller waiting gets `{error, {lua_port_down,
%% Why}}', every Lua behavior that opened a state is told (below) and a new
%% program is started at once, where the behaviors open their states again.
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>call `{request, Req, Now}'</td><td>a Lua behavior → owner</td>
%%     <td>`open', `input', `timer', `waits', `memory', `close'</td>
%%     <td>the program's result for that request</td></tr>
%% <tr><td>`{toroco_lua_port, down, Ids, Why}'</td><td>owner → each behavior with a state</td>
%%     <td>the program died, with the behavior's states `Ids'</td><td>none: the
%%     behavior opens a new state (toroco_lua)</td></tr>
%% <tr><td>monitor `DOWN' of a behavior</td><td>runtime → owner</td>
%%     <td>a behavior with states stopped</td><td>the owner closes its states</td></tr>
%% </table>
%%
%% Functions: life `start_link/0', `os_pid/0', `states/0'; requests
%% `open/5', `input/4', `timer/4', `waits/1', `memory/1', `close/1',
%% `close_all/0', `ping/0'; tests `raw/1'.
-module(toroco_lua_port).
-behaviour(gen_statem).

-include("toroco_lua_port.hrl").

-export([start_link/0, os_pid/0, ping/0, raw/1, states/0,
         open/5, input/4, timer/4, waits/1, memory/1, close/1, close_all/0]).
-export([callback_mode/0, init/1, handle_event/4, terminate/3]).
-export_type([id/0, action/0, result/0, limits/0]).

-type id() :: pos_integer().
%% What a Lua activation asks for (PROTOCOL.md, "Actions").
-type action() :: {send, binary(), term(), default | non_neg_integer() | infinity}
                | {set, binary(), term()}
                | {unset, all | binary()}
                | {timer, pos_integer(), pos_integer(), non_neg_integer()}
                | {cancel, pos_integer()}
                | {print, binary()}
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
            next_ref = 1 :: pos_integer(),
            next_id = 1 :: pos_integer(),
            %% callers in the order their frames went out: {Ref, From | none, Op}
            pending = queue:new() :: queue:queue({pos_integer(), gen_statem:from() | none, term()}),
            %% behavior pid -> its monitor and state ids
            clients = #{} :: #{pid() => {reference(), [id()]}}}).

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
%% when it stops.
-spec open(file:filename_all(), file:filename_all(), term(), limits(), integer()) ->
          {ok, id(), [action()]} | {stopped, stop_reason(), [action()]} | {error, term()}.
open(File, Dir, Params, #{budget := B, memory := M}, Now) ->
    gen_statem:call(?MODULE, {open, self(), {unicode:characters_to_binary(File),
                                             unicode:characters_to_binary(Dir),
                                             Params, B, M}, Now}, ?CALL_TIMEOUT).

-spec input(id(), atom(), term(), integer()) -> result().
input(Id, Input, Value, Now) ->
    request({input, Id, Now, Input, Value}).

-spec timer(id(), pos_integer(), pos_integer(), integer()) -> result().
timer(Id, Task, Seq, Now) ->
    request({timer, Id, Now, Task, Seq}).

%% @doc What each task of the state waits for: `[[Task, Kind, Input | false, TimerPending]]'.
-spec waits(id()) -> {ok, list()} | {error, term()}.
waits(Id) ->
    request({waits, Id}).

-spec memory(id()) -> {ok, non_neg_integer()} | {error, term()}.
memory(Id) ->
    request({memory, Id}).

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

start_port() ->
    Exe = filename:join(code:priv_dir(toroco_lua), "lua_port"),
    case filelib:is_regular(Exe) of
        false -> {error, {lua_port_missing, Exe}};
        true ->
            Port = open_port({spawn_executable, Exe},
                             [{packet, 4}, binary, exit_status, use_stdio]),
            {os_pid, OsPid} = erlang:port_info(Port, os_pid),
            {ok, #d{port = Port, os_pid = OsPid}}
    end.

-spec handle_event(gen_statem:event_type(), term(), up, #d{}) ->
          gen_statem:event_handler_result(up).
handle_event({call, From}, {request, Req}, _S, D) ->
    keep(D, send(Req, From, D));
handle_event({call, From}, {open, Pid, {File, Dir, Params, B, M}, Now}, _S,
             D = #d{next_id = Id}) ->
    D1 = add_client(Pid, Id, D#d{next_id = Id + 1}),
    keep(D, send({open, Id, Now, File, Dir, Params, B, M}, From, D1));
handle_event({call, From}, {raw, Bin}, _S, D = #d{port = Port, pending = Q, next_ref = Ref}) ->
    true = port_command(Port, Bin),
    keep(D, D#d{pending = queue:in({Ref, From, raw}, Q), next_ref = Ref + 1});
handle_event({call, From}, os_pid, _S, #d{os_pid = OsPid}) ->
    {keep_state_and_data, [{reply, From, OsPid}]};
handle_event({call, From}, states, _S, #d{clients = Cs}) ->
    {keep_state_and_data, [{reply, From, lists:sum([length(Ids) || {_, Ids} <- maps:values(Cs)])}]};
handle_event({call, From}, {close_all, Pid}, _S, D = #d{clients = Cs}) ->
    case maps:take(Pid, Cs) of
        {{MRef, Ids}, Cs1} ->
            erlang:demonitor(MRef, [flush]),
            D1 = lists:foldl(fun(Id, Acc) -> send({close, Id}, none, Acc) end,
                             D#d{clients = Cs1}, Ids),
            {keep_state, D1, [{reply, From, ok} | watch(D, D1)]};
        error ->
            {keep_state_and_data, [{reply, From, ok}]}
    end;
handle_event(info, {Port, {data, Bin}}, _S, D = #d{port = Port}) ->
    keep(D, answer(decode(Bin), D));
handle_event(info, {Port, {exit_status, Status}}, _S, D = #d{port = Port}) ->
    restart({exit_status, Status}, D);
handle_event({timeout, stuck}, Ref, _S, #d{pending = Q, os_pid = OsPid}) ->
    case queue:peek(Q) of
        {value, {Ref, _, Req}} ->
            logger:error("toroco_lua_port: lua_port has not answered ~p in ~b ms; killing it",
                         [element(1, Req), stuck_ms()], ?LOG),
            %% kill(1) as a port of its own: nothing here waits for it
            _ = open_port({spawn_executable, os:find_executable("kill")},
                          [{args, ["-9", integer_to_list(OsPid)]}, exit_status]),
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
                             D#d{clients = Cs1}, Ids),
            {keep_state, D1};
        error -> keep_state_and_data
    end;
handle_event(Type, Content, _S, _D) ->
    logger:warning("toroco_lua_port: ignored ~p event ~p", [Type, Content], ?LOG),
    keep_state_and_data.

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

stuck_ms() ->
    application:get_env(toroco_lua, stuck_ms, ?STUCK_MS).

%% Sends {Op, Ref, Args...}; the caller waits in the queue.
send(Req, From, D = #d{port = Port, next_ref = Ref, pending = Q}) ->
    Frame = erlang:insert_element(2, Req, Ref),
    true = port_command(Port, term_to_binary(Frame)),
    D#d{next_ref = Ref + 1, pending = queue:in({Ref, From, Req}, Q)}.

%% The program's atoms are all known here, so nothing it sends makes atoms.
decode(Bin) ->
    try binary_to_term(Bin, [safe])
    catch error:badarg -> {undecodable, Bin}
    end.

answer(Answer, D = #d{pending = Q}) ->
    case queue:out(Q) of
        {{value, {Ref, From, Req}}, Q1} ->
            reply(From, result(Answer, Ref, Req)),
            forget(Answer, Req, D#d{pending = Q1});
        {empty, _} ->
            logger:error("toroco_lua_port: an answer nobody asked for: ~p", [Answer], ?LOG),
            D
    end.

result({reply, Ref, {ok, Actions}}, Ref, {open, Id, _, _, _, _, _, _}) -> {ok, Id, Actions};
result({reply, Ref, Result}, Ref, _Req) -> Result;
result({reply, _, Result}, _Ref, raw) -> Result;
result({bad_frame, Why}, _Ref, raw) -> {bad_frame, Why};
result({bad_frame, Why}, _Ref, _Req) -> {error, {bad_frame, Why}};
result(Other, _Ref, _Req) -> {error, {lua_port_answer, Other}}.

%% A state that stopped, was closed or could not open is no client's any more.
forget({reply, _, {stopped, _, _}}, Req, D) -> drop_id(element(2, Req), D);
forget(_, {close, Id}, D) -> drop_id(Id, D);
forget({reply, _, {error, _}}, {open, Id, _, _, _, _, _, _}, D) -> drop_id(Id, D);
forget({bad_frame, _}, {open, Id, _, _, _, _, _, _}, D) -> drop_id(Id, D);
forget(_, _, D) -> D.

reply(none, _) -> ok;
reply(From, Result) -> gen_statem:reply(From, Result).

add_client(Pid, Id, D = #d{clients = Cs}) ->
    case Cs of
        #{Pid := {MRef, Ids}} -> D#d{clients = Cs#{Pid := {MRef, [Id | Ids]}}};
        #{} -> D#d{clients = Cs#{Pid => {erlang:monitor(process, Pid), [Id]}}}
    end.

drop_id(Id, D = #d{clients = Cs}) ->
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
    maps:foreach(fun(Pid, {MRef, Ids}) ->
                         erlang:demonitor(MRef, [flush]),
                         Pid ! ?LUA_PORT_DOWN(Ids, Why)
                 end, Cs),
    case start_port() of
        {ok, D1} -> {keep_state, D1#d{next_id = D#d.next_id, next_ref = D#d.next_ref},
                     [{{timeout, stuck}, cancel}]};
        {error, Reason} -> {stop, Reason}
    end.
