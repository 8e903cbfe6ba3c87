%% @doc The slots of a listener that strangers can connect to: who is
%% admitted, who is shed to make room, who has been too slow or too quiet.
%% A pure core, no process and no clock of its own: the caller passes the
%% time (`Now', milliseconds of one monotonic clock) and does the closing.
%% Its shells are `toroco_tcp_link' (toroco_hw) and `toroco_live_listener'
%% (the dashboard's and the Foxglove bridge's ports); both use it through
%% these functions only.
%%
%% A connection is in one of three phases:
%% <ul>
%% <li>`request': connected (or started a line, a request) and not
%%     finished it yet; closed `request_timeout' after it began;</li>
%% <li>`idle': between requests (lines); closed `idle_timeout' after the
%%     last one ended;</li>
%% <li>`busy': serving a request, or upgraded to a WebSocket whose own
%%     process bounds it; never timed out, never shed.</li>
%% </ul>
%% Admission ({@link admit/4}), the model being ranch's `max_connections'
%% with Cowboy's timeouts: a peer address that already holds
%% `max_per_peer' connections, or a listener that holds `max' in all, makes
%% room by shedding its longest-idle connection (the one whose last request
%% or line is oldest, busy ones excepted) provided it is at least `min_age'
%% old; when none is, the newcomer is refused. A flood from one address so
%% costs that address its own slots, never another's.
%%
%% Functions: {@link new/1}; the newcomer: {@link admit/4}; what a
%% connection did: {@link started/3}, {@link done/3}, {@link busy/2};
%% time: {@link expired/2}, {@link next_deadline/1}; the end:
%% {@link remove/2}; reading: {@link size/1}, {@link peers/1},
%% {@link is_member/2}.
-module(toroco_slots).

-export([new/1, admit/4, started/3, done/3, busy/2, expired/2, next_deadline/1,
         timeout_action/1, remove/2, size/1, peers/1, is_member/2]).
-export_type([slots/1, limits/0, refusal/0, expiry/0]).

-type limits() :: #{max := pos_integer(),
                    max_per_peer := pos_integer(),
                    min_age := non_neg_integer(),
                    request_timeout := pos_integer(),
                    idle_timeout := pos_integer()}.
-type refusal() :: too_many_from_peer | too_many_clients.
-type expiry() :: request_timeout | idle_timeout.
-type phase() :: request | idle | busy.
-type conn() :: #{peer := term(), since := integer(), last := integer(),
                  phase := phase(), began := integer()}.
-opaque slots(Id) :: #{limits := limits(),
                       conns := #{Id => conn()},
                       per_peer := #{term() => pos_integer()}}.

%% @doc No connection yet, under `Limits'.
-spec new(limits()) -> slots(_).
new(Limits = #{max := _, max_per_peer := _, min_age := _, request_timeout := _,
               idle_timeout := _}) ->
    #{limits => Limits, conns => #{}, per_peer => #{}}.

%% @doc A newcomer `Id' from address `Peer' at `Now': admitted (in phase
%% `request'), admitted after shedding `Victim' (already removed here; the
%% caller closes it), or refused with the reason.
-spec admit(Id, term(), integer(), slots(Id)) ->
          {ok, slots(Id)} | {shed, Id, slots(Id)} | {refuse, refusal(), slots(Id)}.
admit(Id, Peer, Now, S = #{limits := #{max := Max, max_per_peer := PerPeer},
                          conns := Cs, per_peer := PP}) ->
    Room = case {maps:get(Peer, PP, 0) >= PerPeer, map_size(Cs) >= Max} of
               {true, _} -> victim(fun(#{peer := P}) -> P =:= Peer end, too_many_from_peer, Now, S);
               {false, true} -> victim(fun(_) -> true end, too_many_clients, Now, S);
               {false, false} -> room
           end,
    case Room of
        room -> {ok, add(Id, Peer, Now, S)};
        {shed, Victim} -> {shed, Victim, add(Id, Peer, Now, remove(Victim, S))};
        {refuse, Why} -> {refuse, Why, S}
    end.

%% The longest-idle connection among those `Pred' picks, if old enough.
victim(Pred, Why, Now, #{limits := #{min_age := MinAge}, conns := Cs}) ->
    Candidates = [{Last, Id} || {Id, C = #{phase := Ph, last := Last, since := Since}}
                                    <- maps:to_list(Cs),
                                Ph =/= busy, Now - Since >= MinAge, Pred(C)],
    case lists:sort(Candidates) of
        [{_, Id} | _] -> {shed, Id};
        [] -> {refuse, Why}
    end.

add(Id, Peer, Now, S = #{conns := Cs, per_peer := PP}) ->
    S#{conns := Cs#{Id => #{peer => Peer, since => Now, last => Now, began => Now,
                            phase => request}},
       per_peer := PP#{Peer => maps:get(Peer, PP, 0) + 1}}.

%% @doc `Id' began a request (a line) at `Now': it must end within
%% `request_timeout'. One already begun keeps its start.
-spec started(Id, integer(), slots(Id)) -> slots(Id).
started(Id, Now, S) ->
    update(Id, fun(C = #{phase := request}) -> C;
                  (C) -> C#{phase := request, began := Now}
               end, S).

%% @doc `Id' finished a request (a line, a response) at `Now': idle from now.
-spec done(Id, integer(), slots(Id)) -> slots(Id).
done(Id, Now, S) ->
    update(Id, fun(C) -> C#{phase := idle, last := Now} end, S).

%% @doc `Id' is serving a request, or became a WebSocket: no deadline.
-spec busy(Id, slots(Id)) -> slots(Id).
busy(Id, S) ->
    update(Id, fun(C) -> C#{phase := busy} end, S).

update(Id, F, S = #{conns := Cs}) ->
    case Cs of
        #{Id := C} -> S#{conns := Cs#{Id := F(C)}};
        #{} -> S
    end.

%% @doc The connections whose deadline has come by `Now', with why; they
%% are removed here, the caller closes them.
-spec expired(integer(), slots(Id)) -> {[{Id, expiry()}], slots(Id)}.
expired(Now, S = #{conns := Cs}) ->
    Gone = [{Id, Why} || {Id, C} <- maps:to_list(Cs), {Why, At} <- [deadline(C, S)],
                         At =< Now],
    {Gone, lists:foldl(fun({Id, _}, Acc) -> remove(Id, Acc) end, S, Gone)}.

%% @doc When the next deadline comes (`infinity' when none is set).
-spec next_deadline(slots(_)) -> integer() | infinity.
next_deadline(S = #{conns := Cs}) ->
    maps:fold(fun(_, C, Min) ->
                      case deadline(C, S) of
                          {_, At} -> min(At, Min);
                          none -> Min
                      end
              end, infinity, Cs).

%% @doc The shell's timer for {@link next_deadline/1}: a gen_statem
%% absolute timeout `{timeout, slots}' (real time: strangers' sockets are
%% not the simulated lab's) with content `expire', or none.
-spec timeout_action(slots(_)) -> [gen_statem:action()].
timeout_action(S) ->
    case next_deadline(S) of
        infinity -> [];
        At -> [{{timeout, slots}, At, expire, [{abs, true}]}]
    end.

deadline(#{phase := busy}, _) ->
    none;
deadline(#{phase := request, began := B, last := L},
         #{limits := #{request_timeout := RT, idle_timeout := IT}}) ->
    %% a request begun late in an idle spell still ends with the spell
    case {B + RT, L + IT} of
        {R, I} when I < R -> {idle_timeout, I};
        {R, _} -> {request_timeout, R}
    end;
deadline(#{phase := idle, last := L}, #{limits := #{idle_timeout := IT}}) ->
    {idle_timeout, L + IT}.

%% @doc `Id' is gone (closed by either side); nothing if it was not here.
-spec remove(Id, slots(Id)) -> slots(Id).
remove(Id, S = #{conns := Cs, per_peer := PP}) ->
    case maps:take(Id, Cs) of
        {#{peer := Peer}, Cs1} ->
            PP1 = case maps:get(Peer, PP) of
                      1 -> maps:remove(Peer, PP);
                      N -> PP#{Peer := N - 1}
                  end,
            S#{conns := Cs1, per_peer := PP1};
        error ->
            S
    end.

%% @doc Whether `Id' holds a slot.
-spec is_member(Id, slots(Id)) -> boolean().
is_member(Id, #{conns := Cs}) ->
    is_map_key(Id, Cs).

%% @doc How many connections hold a slot.
-spec size(slots(_)) -> non_neg_integer().
size(#{conns := Cs}) ->
    map_size(Cs).

%% @doc Connections per peer address.
-spec peers(slots(_)) -> #{term() => pos_integer()}.
peers(#{per_peer := PP}) ->
    PP.
