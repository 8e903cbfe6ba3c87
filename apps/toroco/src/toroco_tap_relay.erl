%% @doc The observer tap of a robot on several nodes (SPEC §10, §13): a
%% subscriber on one node also gets the events of every other connected node.
%%
%% `toroco:subscribe_events/1' subscribes the caller to its own node's tap
%% and starts one relay on each other node whose wiring server this node
%% knows. A relay is a subscriber of its node's tap with the same options
%% and sends what it gets on, under the caller's reference (a `{dropped, N}'
%% of its own included); per source, events keep their order. The bound
%% of SPEC §10 holds at the relay, which keeps up unless the connection
%% is congested: a subscriber slower than the other nodes' events lets its
%% own mailbox grow. It goes when the subscriber goes (it
%% monitors it) or when `toroco:unsubscribe_events/1' stops it; relays find
%% each other in the `pg' scope `toroco', group `{tap_relay, Ref}'. A node
%% that connects after the subscription is not covered: subscribe again.
-module(toroco_tap_relay).

-export([start/3, stop/1]).

-define(SCOPE, toroco).

%% @doc Starts a relay on this node for subscriber `Sub' (on another node)
%% of subscription `Ref'.
-spec start(pid(), reference(), toroco_tap:opts()) -> ok | {error, term()}.
start(Sub, Ref, Opts) ->
    Caller = self(),
    {Pid, Mon} = spawn_monitor(fun() -> init(Caller, Sub, Ref, Opts) end),
    receive
        {Pid, Answer} -> erlang:demonitor(Mon, [flush]), Answer;
        {'DOWN', Mon, process, Pid, Why} -> {error, {relay_failed, Why}}
    after 5000 ->
            exit(Pid, kill),
            {error, {timeout, tap_relay}}
    end.

%% @doc Stops the relays of subscription `Ref', on every node.
-spec stop(reference()) -> ok.
stop(Ref) ->
    Relays = try pg:get_members(?SCOPE, {tap_relay, Ref})
             catch error:badarg -> []            % toroco is not running here
             end,
    _ = [Pid ! {stop, Ref} || Pid <- Relays],
    ok.

init(Caller, Sub, Ref, Opts) ->
    case toroco_tap:subscribe(Opts) of
        {ok, Local} ->
            ok = pg:join(?SCOPE, {tap_relay, Ref}, self()),
            Mon = erlang:monitor(process, Sub),
            Caller ! {self(), ok},
            relay(Sub, Ref, Local, Mon);
        Err ->
            Caller ! {self(), Err}
    end.

relay(Sub, Ref, Local, Mon) ->
    receive
        {toroco_event, Local, Event} ->
            Sub ! {toroco_event, Ref, Event},
            relay(Sub, Ref, Local, Mon);
        {'DOWN', Mon, process, Sub, _} ->
            toroco_tap:unsubscribe(Local);
        {stop, Ref} ->
            toroco_tap:unsubscribe(Local)
    end.
