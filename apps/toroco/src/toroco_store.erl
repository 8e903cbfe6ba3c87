%% @doc The keeper of the runtime's tables: it owns them and does nothing
%% else, so they outlive a crash of the processes that write them.
%%
%% It is the first child of `toroco_sup'. Its tables:
%% <ul>
%% <li>`toroco_wiring': the wiring server's table (the configuration of each
%%     router and gate, the consumers of each emitter) and its own state, so
%%     that a crashed wiring server comes back with the wiring it had (its
%%     rows: `toroco_wiring_table'). It is
%%     `protected': every process may read it (a consumer reads its row when
%%     it starts), only its writer writes. The writer is the wiring server,
%%     lent the table by {@link claim/1} with this process as its heir: when
%%     the server dies the table comes back here, and the next incarnation
%%     claims it again;</li>
%% <li>`toroco_lives': per behavior or device, how often it was started in
%%     its current life and how often it was restarted (`toroco_restarts').</li>
%% </ul>
-module(toroco_store).
-behaviour(gen_server).

-export([start_link/0, claim/1]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).

-define(LENT, [toroco_wiring]).

%% Tables this process holds, and the claims waiting for a table to come
%% back from a writer that died.
-record(s, {held = ?LENT :: [atom()],
            waiting = #{} :: #{atom() => gen_server:from()}}).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], [{hibernate_after, 1000}]).

%% @doc Makes the caller the writer of `Table' (one of the tables lent to a
%% writer: `toroco_wiring') until it dies. If the last writer just died,
%% the answer waits for the table to come back from it (one claim at a
%% time: a second is refused).
-spec claim(atom()) -> ok | {error, {unknown_table | already_claimed, atom()}}.
claim(Table) ->
    gen_server:call(?MODULE, {claim, Table}, infinity).

-spec init([]) -> {ok, #s{}}.
init([]) ->
    %% Compressed: read when a consumer starts, never per event, and at ten
    %% thousand behaviors its rows are the largest part of the runtime's
    %% memory outside processes (about 560 bytes per behavior with its
    %% router, 320 compressed).
    _ = ets:new(toroco_wiring, [named_table, protected, set, compressed, {read_concurrency, true},
                                {heir, self(), lent}]),
    _ = ets:new(toroco_lives, [named_table, public, set, {write_concurrency, true}]),
    ok = toroco_wire:new_swallowed(),
    {ok, #s{}}.

-spec handle_call(term(), gen_server:from(), #s{}) -> {reply, term(), #s{}} | {noreply, #s{}}.
handle_call({claim, Table}, From, S = #s{held = Held, waiting = Waiting}) ->
    case {lists:member(Table, ?LENT), lists:member(Table, Held)} of
        {false, _} -> {reply, {error, {unknown_table, Table}}, S};
        {true, true} -> lend(Table, From, S#s{held = lists:delete(Table, Held)});
        {true, false} when is_map_key(Table, Waiting) -> {reply, {error, {already_claimed, Table}}, S};
        {true, false} -> {noreply, S#s{waiting = Waiting#{Table => From}}}
    end;
handle_call(_Req, _From, S) ->
    {reply, {error, unknown_request}, S}.

%% A writer died: its table is back here, for the claim waiting or the next.
-spec handle_info(term(), #s{}) -> {noreply, #s{}}.
handle_info({'ETS-TRANSFER', Table, _From, lent}, S = #s{held = Held, waiting = Waiting}) ->
    case Waiting of
        #{Table := Claim} ->
            {reply, ok, S1} = lend(Table, Claim, S#s{waiting = maps:remove(Table, Waiting)}),
            gen_server:reply(Claim, ok),
            {noreply, S1};
        #{} ->
            {noreply, S#s{held = lists:usort([Table | Held])}}
    end;
handle_info(_Msg, S) ->
    {noreply, S}.

-spec handle_cast(term(), #s{}) -> {noreply, #s{}}.
handle_cast(_Msg, S) ->
    {noreply, S}.

%% A claimer that died meanwhile leaves the table here.
lend(Table, {Pid, _}, S = #s{held = Held}) ->
    try ets:give_away(Table, Pid, lent) of
        true -> {reply, ok, S}
    catch error:badarg -> {reply, ok, S#s{held = lists:usort([Table | Held])}}
    end.
