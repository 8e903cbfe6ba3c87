%% @doc The activation pipeline of a Lua behavior (SPEC §16): how its
%% inputs and timers reach its Lua state in the `lua_port' program and how
%% the answers come back as the engine's actions, without the callback ever
%% waiting: up to `window' requests in flight, the rest queued here and
%% written as answers come, the answers of one read handled as one event,
%% a request unanswered for `stuck_ms' getting the program killed, and in
%% lockstep the step held (`step_pending') until every answer is in.
%% The callbacks are `toroco_lua''s; this module keeps their data's
%% `out', `batch', `seq' and `watched'.
-module(toroco_lua_pipeline).

-export([activate/2, settle/2, replies/2, flushed/1, drain/1]).

-define(LOG, #{domain => [toroco, lua]}).

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
-spec activate(tuple(), map()) -> toroco_behavior:result().
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
    case toroco_lua_port:encode(toroco_lua:conn(D), Seq, Req) of
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
                            self() ! {toroco_lua, flush, Id},
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
            case toroco_lua_port:write(toroco_lua:conn(D2), [Frame || {_, Frame} <- Items]) of
                ok -> {ok, D2};
                Error -> {Error, D2}
            end
    end.

-spec flushed(map()) -> toroco_behavior:result().
flushed(D) ->
    case flush(D) of
        {ok, D1} -> {keep_state, D1, []};
        {Error, D1} -> activation(Error, D1)
    end.

%% In lockstep, the step is over once no request is out any more.
-spec settle(atom(), toroco_behavior:result()) -> toroco_behavior:result().
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
-spec replies([{integer(), binary()}], map()) -> toroco_behavior:result().
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
-spec drain(map()) -> toroco_behavior:result().
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
            case toroco_lua_port:await_replies(toroco_lua:conn(D), Ref) of
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
    {keep_state, D, toroco_lua_actions:actions(Actions, D)};
activation({stopped, Reason, Actions}, D = #{name := Name}) ->
    _ = toroco_lua_actions:actions(Actions, D),                  % its prints; emissions die with it
    Why = toroco_lua_main:reason(Reason, D),
    logger:error("toroco_lua: ~p stopped: ~p", [Name, Why], ?LOG#{name => Name}),
    {stop, Why};
activation({error, {Bad, Why}}, D = #{name := Name}) when Bad =:= bad_frame; Bad =:= bad_value ->
    %% a value the port cannot take (a pid, a fun, too many values): this
    %% event only
    logger:warning("toroco_lua: ~p got a value that cannot cross to Lua (~p); dropped",
                   [Name, {Bad, Why}], ?LOG#{name => Name}),
    {keep_state, D, []};
activation({error, {lua_port_down, Why}}, D) ->
    toroco_lua:reattach(Why, D);
activation({error, Why}, _D) ->
    {stop, {lua_port, Why}}.
