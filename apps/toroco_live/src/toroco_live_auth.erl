%% @doc (API) Who may drive the robot: the token checks of every `toroco_live'
%% port (the dashboard's controls and WebSocket, the rosbridge server's
%% publishers), each answered here, and the failures counted per client
%% address so that the token cannot be guessed: after `?MAX_FAILURES'
%% wrong tokens within `?WINDOW_MS' an address is refused every check for
%% `?BAN_MS', the right token included, and told when to come back. A
%% child of `toroco_live_dashboard_sup', before the listener that asks it.
%%
%% A credential is the token itself (`{token, T}': `Authorization: Bearer
%% T', the first visit's `?token=T', rosbridge's `?token=T' and `auth' op)
%% or the page's session (`{session, S}': the cookie the first visit set,
%% {@link session/1}: an HMAC of the token under a key drawn at each start,
%% so the cookie is not the token, cannot be computed from a guess of it,
%% and ends with the dashboard). Both are compared in constant time
%% (`toroco_live_digest:equal/2', of their SHA-256 digests). Only tokens
%% are counted and limited: a session cannot be guessed any faster than
%% its 256-bit key, and a page left open across a restart presents a stale
%% one at each reconnect, which must not lock its person out. A request
%% with no credential is not a failure: it is read-only.
%%
%% The decisions are a pure core over `(Core, Ip, Now)' ({@link new/0},
%% {@link check/4}); the process owns the core, the clock and the counters
%% `/metrics' shows ({@link stats/0}). The addresses it remembers are
%% bounded (`?MAX_ADDRESSES'): past them the oldest entry goes.
%%
%% Messages, built and matched only here:
%% | from    | to   | message                       | answer |
%% |---------|------|-------------------------------|--------|
%% | handler | auth | `{check, Ip, Credential}' (call) | `true', `false' or `{limited, Ms}' (tokens only) |
%% | anyone  | auth | `stats' (call)                | `stats()' |
-module(toroco_live_auth).
-behaviour(gen_server).

-export([start_link/0, authorize/2, session/1, stats/0]).
-export([new/0, check/4]).
-export([init/1, handle_call/3, handle_cast/2, handle_info/2]).

-export_type([credential/0, verdict/0, core/0, stats/0]).

-define(MAX_FAILURES, 10).
-define(WINDOW_MS, 60000).
-define(BAN_MS, 60000).
-define(MAX_ADDRESSES, 4096).
-define(LOG, #{domain => [toroco, live, auth]}).

-type credential() :: {token, binary()} | {session, binary()} | none.
%% `{limited, Ms}': refused without a look at the credential, for `Ms' more.
-type verdict() :: boolean() | {limited, pos_integer()}.
%% Per address: the times of its recent failures, or the end of its ban.
-opaque core() :: #{inet:ip_address() => {failing, [integer()]} | {banned, integer()}}.
-type stats() :: #{failures := non_neg_integer(), limited := non_neg_integer(),
                   banned_now := non_neg_integer()}.

%%====================================================================
%% API
%%====================================================================

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    gen_server:start_link({local, ?MODULE}, ?MODULE, [], []).

%% @doc Whether `Credential', presented from `Ip', lets its holder drive
%% the robot. `false' without a credential (no failure counted), and when
%% the dashboard does not run.
-spec authorize(inet:ip_address() | unknown, credential()) -> verdict().
authorize(_Ip, none) ->
    false;
authorize(Ip, Credential) ->
    try gen_server:call(?MODULE, {check, Ip, Credential}, 5000)
    catch exit:_ -> false
    end.

%% @doc The page's session for `Token' while the dashboard runs: what its
%% cookie holds (the running dashboard's `session_key', drawn at start).
-spec session(binary()) -> binary().
session(Token) ->
    Key = case toroco_live_config:get(session_key, undefined) of
              K when is_binary(K) -> K;
              %% not running: a session no one can present
              undefined -> toroco_live_digest:random_bytes(32)
          end,
    base64url(toroco_live_digest:hmac_sha256(Key, Token)).

%% @doc `failures' (wrong credentials), `limited' (checks refused because
%% the address was banned), `banned_now' (addresses banned now); empty when
%% the dashboard does not run.
-spec stats() -> stats() | #{}.
stats() ->
    try gen_server:call(?MODULE, stats, 5000)
    catch exit:_ -> #{}
    end.

%%====================================================================
%% The pure core
%%====================================================================

%% @doc No address has failed.
-spec new() -> core().
new() ->
    #{}.

%% @doc The verdict on a check from `Ip' at `Now' (ms) whose credential
%% `Good' was right or not, and the core after it.
-spec check(inet:ip_address() | unknown, boolean(), integer(), core()) -> {verdict(), core()}.
check(Ip, Good, Now, Core) ->
    case maps:get(Ip, Core, {failing, []}) of
        {banned, Until} when Until > Now ->
            {{limited, Until - Now}, Core};
        {banned, _} ->
            check(Ip, Good, Now, maps:remove(Ip, Core));
        {failing, _} when Good ->
            {true, Core};
        {failing, Times} ->
            Recent = [T || T <- Times, T > Now - ?WINDOW_MS],
            Entry = case length(Recent) + 1 >= ?MAX_FAILURES of
                        true -> {banned, Now + ?BAN_MS};
                        false -> {failing, [Now | Recent]}
                    end,
            {false, bounded(Core#{Ip => Entry}, Now)}
    end.

%% Past ?MAX_ADDRESSES, the stale entries go, then the oldest.
bounded(Core, _Now) when map_size(Core) =< ?MAX_ADDRESSES ->
    Core;
bounded(Core, Now) ->
    Live = maps:filter(fun(_, E) -> last(E) > Now - max(?WINDOW_MS, ?BAN_MS) end, Core),
    case map_size(Live) =< ?MAX_ADDRESSES of
        true -> Live;
        false ->
            {Oldest, _} = lists:foldl(fun({Ip, E}, {_, T} = Acc) ->
                                              case last(E) < T of
                                                  true -> {Ip, last(E)};
                                                  false -> Acc
                                              end
                                      end, {none, Now + ?BAN_MS + 1}, maps:to_list(Live)),
            maps:remove(Oldest, Live)
    end.

last({banned, Until}) -> Until;
last({failing, [T | _]}) -> T;
last({failing, []}) -> 0.

%%====================================================================
%% gen_server
%%====================================================================

-spec init([]) -> {ok, map()}.
init([]) ->
    {ok, #{core => new(), failures => 0, limited => 0}}.

-spec handle_call(term(), gen_server:from(), map()) -> {reply, term(), map()}.
handle_call({check, _Ip, {session, _} = Session}, _From, S) ->
    {reply, good(Session), S};
handle_call({check, Ip, Credential}, _From, S = #{core := Core}) ->
    Now = erlang:monotonic_time(millisecond),
    {Verdict, Core1} = check(Ip, good(Credential), Now, Core),
    S1 = S#{core := Core1},
    case Verdict of
        true ->
            {reply, true, S1};
        false ->
            case maps:get(Ip, Core1) of
                {banned, _} ->
                    logger:warning("toroco_live: ~b wrong tokens from ~ts within ~b s: its "
                                   "checks are refused for ~b s",
                                   [?MAX_FAILURES, address(Ip), ?WINDOW_MS div 1000,
                                    ?BAN_MS div 1000], ?LOG);
                _ -> ok
            end,
            {reply, false, S1#{failures := maps:get(failures, S1) + 1}};
        {limited, _} ->
            {reply, Verdict, S1#{limited := maps:get(limited, S1) + 1}}
    end;
handle_call(stats, _From, S = #{core := Core, failures := F, limited := L}) ->
    Now = erlang:monotonic_time(millisecond),
    Banned = maps:size(maps:filter(fun(_, {banned, U}) -> U > Now; (_, _) -> false end, Core)),
    {reply, #{failures => F, limited => L, banned_now => Banned}, S};
handle_call(_, _From, S) ->
    {reply, {error, unknown_call}, S}.

-spec handle_cast(term(), map()) -> {noreply, map()}.
handle_cast(_, S) ->
    {noreply, S}.

-spec handle_info(term(), map()) -> {noreply, map()}.
handle_info(_, S) ->
    {noreply, S}.

%% The credential against the running dashboard's token, in constant time.
good({token, Presented}) when is_binary(Presented) ->
    equal(toroco_live_config:get(token, undefined), Presented);
good({session, Presented}) when is_binary(Presented) ->
    case toroco_live_config:get(token, undefined) of
        Token when is_binary(Token) -> equal(session(Token), Presented);
        _ -> false
    end;
good(_) ->
    false.

%% Comparing digests keeps the time independent of the presented length
%% too.
equal(Secret, Presented) when is_binary(Secret) ->
    toroco_live_digest:equal(toroco_live_digest:sha256(Secret),
                             toroco_live_digest:sha256(Presented));
equal(_, _) ->
    false.

address(unknown) -> "an unknown address";
address(Ip) -> inet:ntoa(Ip).

base64url(Bytes) ->
    << <<(case C of $+ -> $-; $/ -> $_; _ -> C end)>> || <<C>> <= base64:encode(Bytes), C =/= $= >>.
