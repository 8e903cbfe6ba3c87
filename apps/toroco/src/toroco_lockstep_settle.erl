%% @doc Exits as lockstep steps (SPEC §17), on the clock's state: the
%% processes of the path said `up', a death written down, the restarts
%% awaited and counted against their layer's (or the devices') intensity
%% in simulated time, a layer (the devices) taken out when it is spent,
%% the barrier, and what the settle held back queued in a fixed order.
-module(toroco_lockstep_settle).

-include("toroco_wire.hrl").
-include("toroco_lockstep.hrl").

-import(toroco_lockstep_trace, [note/2, reason/1, pname/1]).

-export([info/2, predecessor/2, up/5, group/2, intensity/3, exited/3, sup_down/2, settling/1, progress/1,
         flush/1, hold/3, watch/2]).

%% The messages of an exit's settle (`toroco_lockstep''s table): the
%% state they leave, `unchanged' for one that comes too late to matter.
-spec info(tuple(), #s{}) -> #s{} | unchanged.
info({?TAG, ready, _Pid, Name}, S = #s{settle = St = #settle{awaiting = Awaiting}})
  when is_map_key(Name, Awaiting) ->
    Sup = maps:get(Name, Awaiting),
    S1 = note(io_lib:format("~s restarted", [Name]),
              S#s{settle = St#settle{awaiting = maps:remove(Name, Awaiting)}}),
    Layer = case [L || #{name := N, layer := L} <- maps:values(S1#s.procs), N =:= Name] of
                [L | _] -> L;
                [] -> none
            end,
    progress(intensity(Sup, group(Sup, Layer), S1));
info({?TAG, devices_out, Sup}, S = #s{restarts = R}) ->
    S1 = S#s{restarts = maps:remove(Sup, R)},
    progress(case S1#s.settle of
                 none -> S1;
                 St = #settle{takeout = Out} ->
                     S1#s{settle = St#settle{takeout = maps:remove(Sup, Out)}}
             end);
info({?TAG, down, Pid, Down}, S = #s{cell = Cell, downs = Downs, arrival = A})
  when Cell =/= undefined ->
    S1 = settling(S#s{downs = [{A, Pid, Down} | Downs], arrival = A + 1}),
    St = #settle{expect = E} = S1#s.settle,
    progress(S1#s{settle = St#settle{expect = maps:remove({Pid, element(4, Down)}, E)}});
info({?TAG, synced, Ref, Pid}, S = #s{settle = St = #settle{barrier = {Ref, Waiting}}}) ->
    progress(S#s{settle = St#settle{barrier = {Ref, maps:remove(Pid, Waiting)}}});
info({?TAG, settle_guard, Guard}, S = #s{settle = #settle{guard = Guard} = St}) ->
    logger:warning("toroco_lockstep: an exit did not settle within ~b ms (restarts awaited: ~0p, "
                   "layers going out: ~0p); going on", [?SETTLE_GUARD_MS,
                                                        maps:keys(St#settle.awaiting),
                                                        maps:values(St#settle.takeout)], ?LOG),
    flush(S#s{unsettled = S#s.unsettled + 1});
info(_Msg, _S) ->
    unchanged.

%% A new incarnation of `Name' starts: its predecessor is dead (its
%% supervisor saw it go), and its exit is settled first, so that nothing
%% the new one sends comes before that exit's consequences.
-spec predecessor(atom(), #s{}) -> #s{}.
predecessor(Name, S = #s{procs = Procs}) ->
    case [{P, M} || {P, #{name := N, mon := M}} <- maps:to_list(Procs), N =:= Name] of
        [{Old, Mon} | _] ->
            receive
                {'DOWN', Mon, process, Old, Reason} -> exited(Old, Reason, S)
            after ?SETTLE_GUARD_MS ->
                    exited(Old, unknown, S)
            end;
        [] ->
            S
    end.

%% A process of the path starts: monitored, with its supervisor. Its
%% restart, if awaited, is done when it is ready (counted against its
%% layer's intensity in simulated time then).
-spec up(pid(), atom(), pid() | undefined, non_neg_integer() | none | consumer, #s{}) -> #s{}.
up(Pid, Name, Sup, Layer, S = #s{procs = Procs, sups = Sups}) ->
    Sups1 = case Sup of
                undefined -> Sups;
                _ when is_map_key(Sup, Sups) -> Sups;
                _ -> Sups#{Sup => {erlang:monitor(process, Sup), Layer}}
            end,
    S#s{procs = Procs#{Pid => #{name => Name, sup => Sup, layer => Layer,
                                mon => erlang:monitor(process, Pid)}},
        sups = Sups1, world = toroco_lockstep_nodes:remember(Pid, S#s.world)}.

%% What a restart counts against: its layer, or the devices (their
%% supervisor's intensity), or nothing (routers, consumers).
-spec group(pid() | undefined, non_neg_integer() | none | consumer) ->
          non_neg_integer() | devices | none | consumer.
group(Sup, none) ->
    case whereis(toroco_devices_sup) of
        Sup when is_pid(Sup) -> devices;
        _ -> none
    end;
group(_Sup, Layer) ->
    Layer.

%% A restart in a layer or of a device: more than the intensity allows
%% within its period of simulated time takes the layer (the devices) out,
%% as its supervisor would.
-spec intensity(pid() | undefined, non_neg_integer() | devices | none | consumer, #s{}) ->
          #s{}.
intensity(Sup, Group, S = #s{restarts = R, now = Now, settle = St = #settle{takeout = Out}})
  when is_pid(Sup), is_integer(Group); is_pid(Sup), Group =:= devices ->
    {Max, Period} = case Group of
                        devices -> S#s.device_intensity;
                        _ -> S#s.intensity
                    end,
    %% as OTP's supervisor counts: restarts at or after Now - Period
    Recent = [T || T <- [Now | maps:get(Sup, R, [])], T >= Now - Period * 1000],
    S1 = S#s{restarts = R#{Sup => Recent}},
    case length(Recent) > Max andalso not is_map_key(Sup, Out) of
        true ->
            S2 = lists:foldl(fun watch/2, S1, [P || {P, #{sup := PS}} <- maps:to_list(S1#s.procs),
                                                   PS =:= Sup]),
            take_out(Sup, Group),
            note(case Group of
                     devices -> "devices out";
                     _ -> io_lib:format("layer ~b out", [Group])
                 end, S2#s{settle = St#settle{takeout = Out#{Sup => Group}}});
        false ->
            S1
    end;
intensity(_Sup, _Group, S) ->
    S.

%% A layer goes with its supervisor (seen as that one's DOWN); the devices
%% leave theirs running, and say when they are gone.
take_out(Sup, devices) ->
    Self = self(),
    _ = spawn(fun() -> ok = toroco_devices_sup:take_out(), Self ! {?TAG, devices_out, Sup} end),
    ok;
take_out(_Sup, Layer) ->
    _ = spawn(fun() -> toroco_layers_sup:take_out(Layer) end),
    ok.

%% A process of the path died: the exit is written down, its restart is
%% awaited unless it ended for good (normal, shutdown) or its supervisor
%% is going, and the node settles.
-spec exited(pid(), term(), #s{}) -> #s{}.
exited(Pid, Reason, S = #s{procs = Procs, inflight = Inflight}) ->
    #{Pid := #{name := Name, sup := Sup}} = Procs,
    S1 = case Inflight of
             {_, Mon, Pid} -> erlang:demonitor(Mon, [flush]), S#s{inflight = none};
             _ -> S
         end,
    S2 = settling(note(io_lib:format("~s exit ~ts", [Name, reason(Reason)]),
                       S1#s{procs = maps:remove(Pid, Procs)})),
    #settle{awaiting = Awaiting, takeout = Out, barrier = Barrier} = S2#s.settle,
    Restarts = not final(Reason) andalso is_pid(Sup) andalso is_map_key(Sup, S2#s.sups)
        andalso not is_map_key(Sup, Out),
    Barrier1 = case Barrier of
                   {Ref, Waiting} -> {Ref, maps:remove(Pid, Waiting)};
                   none -> none
               end,
    %% the consumers that monitored it hand its DOWN over (those already
    %% gone or that already did are not waited for), and it will hand none
    Handed = [C || {_, C, {'DOWN', _, process, D, _}} <- S2#s.downs, D =:= Pid],
    Expect0 = maps:filter(fun({C, _}, _) -> C =/= Pid end, (S2#s.settle)#settle.expect),
    Expect = lists:foldl(fun(C, E) -> E#{{C, Pid} => true} end, Expect0,
                         [C || C <- maps:get(Pid, S2#s.watch, []), is_map_key(C, S2#s.procs),
                               not lists:member(C, Handed)]),
    S2#s{watch = maps:remove(Pid, S2#s.watch),
         settle = (S2#s.settle)#settle{barrier = Barrier1, expect = Expect,
                            awaiting = case Restarts of
                                           true -> Awaiting#{Name => Sup};
                                           false -> Awaiting
                                       end}}.

final(normal) -> true;
final(shutdown) -> true;
final({shutdown, _}) -> true;
final(_) -> false.

%% A supervisor of the path died (a layer taken out): the restarts it
%% would have made are not awaited.
-spec sup_down(pid(), #s{}) -> #s{}.
sup_down(Sup, S = #s{sups = Sups}) ->
    case maps:take(Sup, Sups) of
        {{_, Layer}, Sups1} ->
            S1 = S#s{sups = Sups1, restarts = maps:remove(Sup, S#s.restarts)},
            case S1#s.settle of
                St = #settle{awaiting = Awaiting, takeout = Out} ->
                    S2 = case is_map_key(Sup, Out) orelse not is_integer(Layer) of
                             true -> S1;
                             false -> note(io_lib:format("layer ~b out", [Layer]), S1)
                         end,
                    S2#s{settle = St#settle{awaiting = maps:filter(fun(_, P) -> P =/= Sup end,
                                                                    Awaiting),
                                            takeout = maps:remove(Sup, Out)}};
                none ->
                    settling(S1)
            end;
        error ->
            S
    end.

-spec settling(#s{}) -> #s{}.
settling(S = #s{settle = none}) ->
    Guard = make_ref(),
    erlang:send_after(?SETTLE_GUARD_MS, self(), {?TAG, settle_guard, Guard}),
    S#s{settle = #settle{guard = Guard}};
settling(S) ->
    S.

%% The settle moves on: once no restart nor layer is awaited, the barrier
%% goes to every process of the path; once all have answered, what the
%% settle gathered is queued.
-spec progress(#s{}) -> #s{}.
progress(S = #s{settle = none}) ->
    S;
progress(S = #s{settle = #settle{awaiting = A, takeout = O, expect = E}})
  when map_size(A) > 0; map_size(O) > 0; map_size(E) > 0 ->
    S;
progress(S = #s{settle = St = #settle{barrier = none}, procs = Procs}) ->
    Ref = make_ref(),
    _ = [Pid ! ?WIRE_BARRIER(Ref) || Pid <- maps:keys(Procs)],
    progress_barrier(S#s{settle = St#settle{barrier = {Ref, maps:map(fun(_, _) -> true end,
                                                                     Procs)}}});
progress(S) ->
    progress_barrier(S).

progress_barrier(S = #s{settle = #settle{barrier = {_, Waiting}}}) when map_size(Waiting) > 0 ->
    S;
progress_barrier(S) ->
    flush(S).

%% The settle's end: the DOWNs by receiver's name, then the sends, timers
%% and cancels by sender's name (each sender's in the order it made them).
-spec flush(#s{}) -> #s{}.
flush(S = #s{downs = Downs, held = Held, queue = Q}) ->
    Q1 = lists:foldl(fun({_, _, Pid, Down}, Acc) -> queue:in({Pid, Pid, Down}, Acc) end,
                     Q, lists:sort([{pname(Pid), A, Pid, Down} || {A, Pid, Down} <- Downs])),
    lists:foldl(fun({_, _, H}, Acc) -> apply_held(H, Acc) end,
                S#s{queue = Q1, downs = [], held = [], settle = none},
                lists:sort([{pname(From), A, H} || {A, From, H} <- Held])).

apply_held({send, To, Pid, Msg}, S = #s{queue = Q}) ->
    S#s{queue = queue:in({To, Pid, Msg}, Q)};
apply_held({timer, Pid, Kind, Deadline, Msg}, S) ->
    toroco_lockstep_timers:set(Pid, Kind, Deadline, Msg, S);
apply_held({cancel, Pid, Kind}, S) ->
    toroco_lockstep_timers:drop(Pid, Kind, S).

-spec hold(pid(), held(), #s{}) -> #s{}.
hold(From, H, S = #s{held = Held, arrival = A}) ->
    S#s{held = [{A, From, H} | Held], arrival = A + 1}.

%% Who will hand over `Pid''s DOWN should it die now: the consumers that
%% monitor it (read as its step goes, when only it works, or before it is
%% killed). Only processes of the path are looked at.
-spec watch(pid(), #s{}) -> #s{}.
watch(Pid, S = #s{procs = Procs, watch = W}) when is_map_key(Pid, Procs), node(Pid) =:= node() ->
    case erlang:process_info(Pid, monitored_by) of
        {monitored_by, By} ->
            S#s{watch = W#{Pid => [C || C <- By, is_pid(C),
                                        case Procs of
                                            #{C := #{layer := consumer}} -> true;
                                            #{} -> false
                                        end]}};
        undefined ->
            S
    end;
watch(_Pid, S) ->
    S.
