%% @doc (API) The simulated world as the dashboard and the bridges see it:
%% a registered process (`toroco_live_world') that keeps the latest
%% snapshot of the world running in this node and each robot's trajectory
%% for whoever draws them. It is the source of `toroco_rec_world' (the
%% flight recorder's and the taps' world): it sets itself there as it starts.
%%
%% A simulator does not know this process, nor does this process know the
%% simulator: the world publishes each step through the runtime
%% (`toroco:publish_world/1', SPEC §10), and this process subscribes to
%% those snapshots (`toroco:subscribe_world/0') when it starts, and again
%% (every 200 ms until the runtime is back) when the runtime restarts under
%% it and takes the subscription with it. Without
%% `toroco_live' (a board release, or the application stopped) nobody
%% subscribes and the world makes no snapshot. The messages:
%%
%% <table>
%% <tr><th>message</th><th>from → to</th><th>when</th><th>answer</th></tr>
%% <tr><td>`{toroco_world, Snapshot}'</td>
%%     <td>the runtime (`toroco:publish_world/1', called by `torobot_sim')
%%     → each subscriber, this process among them</td>
%%     <td>after each step of the world</td><td>none</td></tr>
%% <tr><td>`{toroco_live_world, changed}'</td>
%%     <td>`toroco_live_world' → each subscriber</td>
%%     <td>a new snapshot came, and the subscriber has read
%%         ({@link latest/0}) since the last such message: at most one is
%%         ever waiting in a subscriber's mailbox</td><td>none</td></tr>
%% <tr><td>`{toroco_live_world, at, Snapshot}'</td>
%%     <td>`toroco_live_world' → each subscriber of {@link subscribe_all/0}</td>
%%     <td>a snapshot of a world in lockstep (`lockstep => true'): every
%%         one, since the world sends one a tick and goes as fast as the CPU
%%         allows (a recording then has the pose at every tick, stamped with
%%         its simulated time)</td><td>none</td></tr>
%% </table>
%%
%% `Snapshot' is a map (metres, degrees counter-clockwise from +x,
%% milliseconds of world time):
%%
%% <table>
%% <tr><th>key</th><th>value</th></tr>
%% <tr><td>`run'</td><td>any term naming this run; a new one starts new trajectories</td></tr>
%% <tr><td>`lockstep'</td><td>optional, `true' when the world is the clock</td></tr>
%% <tr><td>`timeline'</td><td>optional, `#{duration_ms => D, marks => [#{t_ms,
%%   kind, text}]}': what the page marks on the run's timeline (a fault of
%%   the robustness lab, a violation of its property)</td></tr>
%% <tr><td>`t_ms'</td><td>world time of the step</td></tr>
%% <tr><td>`arena'</td><td>`{Width, Height}'; walls all around, origin bottom-left</td></tr>
%% <tr><td>`walls'</td><td>`[{{X1, Y1}, {X2, Y2}}]', inside the arena</td></tr>
%% <tr><td>`objects'</td><td>`[{red | blue, {X, Y}, Radius}]'</td></tr>
%% <tr><td>`robots'</td><td>a list of maps, one per robot:
%%   `name' (atom), `pose' `{X, Y, Heading}', `radius',
%%   `winner' (the behavior winning the motors, or `none'),
%%   `ir' `[#{side => left | right, from => {X, Y}, to => {X, Y}, adc => 0..1023}]'
%%   (each ray from the sensor to what it hits, or to its range),
%%   `camera' `#{fov_deg => F, range => R}' (looking along the heading)</td></tr>
%% </table>
%%
%% The trajectory is not in the message: this process appends each
%% robot's pose, with its winner, to that robot's trajectory (the last
%% 4000 points), so a simulator sends a constant-size message per
%% step. {@link latest/0} returns the last snapshot with `trajectories =>
%% #{Name => [{X, Y, Winner}]}' (oldest first) added.
-module(toroco_live_world).
-behaviour(gen_server).
-behaviour(toroco_rec_world).

-export([start_link/0, latest/0, subscribe/0, subscribe_all/0, unsubscribe/0]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).

-export_type([snapshot/0]).

-type snapshot() :: #{run := term(), t_ms := non_neg_integer(),
                      arena := {number(), number()}, walls := list(), objects := list(),
                      robots := [map()], trajectories => map(), lockstep => boolean(),
                      timeline => #{duration_ms := pos_integer(), marks := [map()]}}.

%% Points kept per robot's trajectory.
-define(TRAIL, 4000).

%% How soon to subscribe again to the world's snapshots after the runtime
%% took the subscription away, or refused it.
-define(RESUBSCRIBE_MS, 200).

-record(w, {latest = none :: snapshot() | none,
            %% the runtime's side of the subscription to the world's snapshots
            world = none :: reference() | none,
            trails = #{} :: #{atom() => {non_neg_integer(), [tuple()]}},
            subscribers = #{} :: #{pid() => {reference(), Notified :: boolean()}},
            %% the subscribers that take every snapshot of a world in lockstep
            all = #{} :: #{pid() => true}}).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc The last snapshot, with the trajectories; `none' before any.
%% Re-arms the caller's `changed' notification.
-spec latest() -> snapshot() | none.
latest() ->
    gen_server:call(?MODULE, latest).

%% @doc The caller gets `{toroco_live_world, changed}' when a snapshot comes.
-spec subscribe() -> ok.
subscribe() ->
    gen_server:call(?MODULE, subscribe).

%% @doc As {@link subscribe/0}, and the caller also gets every snapshot of
%% a world in lockstep as `{toroco_live_world, at, Snapshot}' (instead of
%% `changed' for those).
-spec subscribe_all() -> ok.
subscribe_all() ->
    gen_server:call(?MODULE, subscribe_all).

-spec unsubscribe() -> ok.
unsubscribe() ->
    gen_server:call(?MODULE, unsubscribe).

-spec init([]) -> {ok, #w{}}.
init([]) ->
    %% The flight recorder and the taps that ask for the world read it here.
    ok = toroco_rec_world:set(?MODULE),
    {ok, subscribe_world(#w{})}.

%% Snapshots come while the runtime runs; when it is not running (yet, or
%% again) this process asks again a little later.
subscribe_world(W) ->
    case toroco:subscribe_world() of
        {ok, Ref} ->
            W#w{world = Ref};
        {error, _} ->
            erlang:send_after(?RESUBSCRIBE_MS, self(), {?MODULE, subscribe_world}),
            W#w{world = none}
    end.

-spec handle_call(term(), gen_server:from(), #w{}) -> {reply, term(), #w{}}.
handle_call(latest, {Pid, _}, W = #w{latest = Latest, trails = Trails, subscribers = Subs}) ->
    Subs1 = case Subs of
                #{Pid := {Ref, _}} -> Subs#{Pid := {Ref, false}};
                #{} -> Subs
            end,
    Reply = case Latest of
                none -> none;
                _ -> Latest#{trajectories => maps:map(fun(_, {_, Ps}) -> lists:reverse(Ps) end,
                                                      Trails)}
            end,
    {reply, Reply, W#w{subscribers = Subs1}};
handle_call(subscribe, {Pid, _}, W = #w{subscribers = Subs}) ->
    case Subs of
        #{Pid := _} -> {reply, ok, W};
        #{} -> {reply, ok, W#w{subscribers = Subs#{Pid => {monitor(process, Pid), false}}}}
    end;
handle_call(subscribe_all, From = {Pid, _}, W) ->
    {reply, ok, W1} = handle_call(subscribe, From, W),
    {reply, ok, W1#w{all = (W1#w.all)#{Pid => true}}};
handle_call(unsubscribe, {Pid, _}, W = #w{subscribers = Subs}) ->
    case Subs of
        #{Pid := {Ref, _}} -> demonitor(Ref, [flush]);
        #{} -> ok
    end,
    {reply, ok, W#w{subscribers = maps:remove(Pid, Subs), all = maps:remove(Pid, W#w.all)}};
handle_call(_Request, _From, W) ->
    {reply, {error, unknown_call}, W}.

-spec handle_cast(term(), #w{}) -> {noreply, #w{}}.
handle_cast(_Msg, W) ->
    {noreply, W}.

-spec handle_info(term(), #w{}) -> {noreply, #w{}}.
handle_info({toroco_world, #{run := Run, robots := Robots} = Snap}, W) when is_list(Robots) ->
    Trails = case W#w.latest of
                 #{run := Run} -> W#w.trails;
                 _ -> #{}
             end,
    Trails1 = lists:foldl(fun trail/2, Trails, Robots),
    {noreply, notify(W#w{latest = Snap, trails = Trails1})};
handle_info({'DOWN', Ref, process, _, _}, W = #w{world = Ref}) ->
    %% the runtime restarted, and its subscribers with it
    erlang:send_after(?RESUBSCRIBE_MS, self(), {?MODULE, subscribe_world}),
    {noreply, W#w{world = none}};
handle_info({?MODULE, subscribe_world}, W = #w{world = none}) ->
    {noreply, subscribe_world(W)};
handle_info({'DOWN', Ref, process, Pid, _}, W = #w{subscribers = Subs}) ->
    case Subs of
        #{Pid := {Ref, _}} -> {noreply, W#w{subscribers = maps:remove(Pid, Subs),
                                            all = maps:remove(Pid, W#w.all)}};
        #{} -> {noreply, W}
    end;
handle_info(_Info, W) ->
    {noreply, W}.

trail(#{name := Name, pose := {X, Y, _}} = Robot, Trails) ->
    Point = {X, Y, maps:get(winner, Robot, none)},
    case maps:get(Name, Trails, {0, []}) of
        {N, Ps} when N >= ?TRAIL -> Trails#{Name => {?TRAIL div 2 + 1,
                                                     [Point | lists:sublist(Ps, ?TRAIL div 2)]}};
        {N, Ps} -> Trails#{Name => {N + 1, [Point | Ps]}}
    end;
trail(_, Trails) ->
    Trails.

notify(W = #w{subscribers = Subs, all = All, latest = Latest}) ->
    Every = case Latest of
                #{lockstep := true} -> All;
                _ -> #{}
            end,
    maps:foreach(fun(Pid, _) -> Pid ! {?MODULE, at, Latest} end, Every),
    Subs1 = maps:map(fun(Pid, Sub) when is_map_key(Pid, Every) ->
                             Sub;
                        (Pid, {Ref, false}) ->
                             Pid ! {?MODULE, changed},
                             {Ref, true};
                        (_, Sub) ->
                             Sub
                     end, Subs),
    W#w{subscribers = Subs1}.
