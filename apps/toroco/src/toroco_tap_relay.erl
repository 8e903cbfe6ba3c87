%% @doc The observer tap of a robot on several nodes (SPEC §10, §13): a
%% subscriber on one node also gets the events of every other connected node.
%%
%% `toroco:subscribe_events/1' subscribes the caller to its own node's tap
%% and starts one relay on each other node whose wiring server this node
%% knows. A relay is a subscriber of its node's tap with the same options;
%% it hands what it gets, in batches, to the subscription's feeder on the
%% subscriber's node (`toroco_tap:relayed/4'), which bounds them as it
%% bounds the local producers: past `buffer' pending, events are dropped and
%% counted into the subscriber's one `{dropped, N}', with those the relay's
%% own tap dropped and those a congested connection would not take (the
%% relay never waits for the other node). Per source, events keep their
%% order. A relay goes when the subscription's feeder goes (the subscriber
%% died or unsubscribed: it monitors it) or when
%% `toroco:unsubscribe_events/1' stops it; relays find each other in the
%% `pg' scope `toroco', group `{tap_relay, Ref}'. A node that connects after
%% the subscription is not covered: subscribe again.
-module(toroco_tap_relay).

-export([start/3, stop/1]).

-define(SCOPE, toroco).
-define(BATCH_MAX, 64).
%% How soon a relay tries again to report drops the connection refused.
-define(RETRY_MS, 50).

%% @doc Starts a relay on this node for subscription `Ref', whose feeder
%% (on another node) is `Feeder'.
-spec start(pid(), reference(), toroco_tap:opts()) -> ok | {error, term()}.
start(Feeder, Ref, Opts) ->
    Caller = self(),
    {Pid, Mon} = spawn_monitor(fun() -> init(Caller, Feeder, Ref, Opts) end),
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

init(Caller, Feeder, Ref, Opts) ->
    %% Whatever the subscriber asked for, the relay takes its node's events
    %% in batches: they leave as batches too.
    case toroco_tap:subscribe(Opts#{delivery => batch}) of
        {ok, Local} ->
            ok = pg:join(?SCOPE, {tap_relay, Ref}, self()),
            Mon = erlang:monitor(process, Feeder),
            Caller ! {self(), ok},
            relay({Feeder, Ref, Local, Mon}, 0);
        Err ->
            Caller ! {self(), Err}
    end.

%% `Dropped': events lost on this side not reported yet.
relay(R = {_, Ref, Local, Mon}, Dropped) ->
    receive
        {toroco_events, Local, Events} ->
            relay(R, pass(R, take(Local, Events, Dropped)));
        {'DOWN', Mon, process, _, _} ->
            toroco_tap:unsubscribe(Local);
        {stop, Ref} ->
            toroco_tap:unsubscribe(Local)
    after case Dropped of 0 -> infinity; _ -> ?RETRY_MS end ->
            relay(R, pass(R, {[], Dropped}))
    end.

%% The events of a batch, and what else is already here up to ?BATCH_MAX,
%% with the drops they report counted apart.
take(Local, Events, Dropped) ->
    take(Local, Events, [], 0, Dropped).

take(Local, [], Acc, N, Dropped) when N < ?BATCH_MAX ->
    receive
        {toroco_events, Local, Events} -> take(Local, Events, Acc, N, Dropped)
    after 0 ->
            {lists:reverse(Acc), Dropped}
    end;
take(_Local, [], Acc, _N, Dropped) ->
    {lists:reverse(Acc), Dropped};
take(Local, [{dropped, K} | Events], Acc, N, Dropped) ->
    take(Local, Events, Acc, N, Dropped + K);
take(Local, [Event | Events], Acc, N, Dropped) ->
    take(Local, Events, [Event | Acc], N + 1, Dropped).

pass({Feeder, Ref, _, _}, {Events, Dropped}) ->
    case toroco_tap:relayed(Feeder, Ref, Events, Dropped) of
        ok -> 0;
        busy -> Dropped + length(Events)
    end.
