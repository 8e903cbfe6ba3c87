%% @doc How often each behavior and device was restarted, for `toroco:top()'.
%%
%% The supervisors of the layers and of the devices already report every
%% child that dies abnormally (a `{supervisor, child_terminated}' report)
%% just before they restart it, so the count is read off those reports: this
%% module is a `logger' handler that bumps one `counters' cell per name, kept
%% in `persistent_term'. Nothing is added to the event path or to the
%% engine, and no process of its own is needed.
%%
%% The releases install the handler from their `sys.config' (kernel `logger'
%% handler `toroco_restarts'), so counts start at boot; elsewhere
%% {@link install/0} adds it (the first `toroco:top()' does), and counts
%% start then. A count survives `remove' and a later `add' of the same name.
%% It counts nothing while the primary logger level is above `error'.
-module(toroco_restarts).

-export([install/0, count/1]).
-export([log/2]).

-define(HANDLER, toroco_restarts).

%% @doc Adds the handler unless it is there already.
-spec install() -> ok | {error, term()}.
install() ->
    case logger:get_handler_config(?HANDLER) of
        {ok, _} -> ok;
        {error, _} ->
            case logger:add_handler(?HANDLER, ?MODULE, #{level => error}) of
                ok -> ok;
                {error, {already_exist, _}} -> ok;
                {error, _} = Err -> Err
            end
    end.

%% @doc Restarts of behavior or device `Name' seen since the handler was
%% installed.
-spec count(atom()) -> non_neg_integer().
count(Name) ->
    case persistent_term:get({?MODULE, Name}, undefined) of
        undefined -> 0;
        Ref -> counters:get(Ref, 1)
    end.

%% @private logger handler callback; runs in the reporting supervisor.
-spec log(logger:log_event(), logger:handler_config()) -> ok.
log(#{msg := {report, #{label := {supervisor, child_terminated}, report := Report}}}, _Config)
  when is_list(Report) ->
    Offender = proplists:get_value(offender, Report, []),
    case {proplists:get_value(id, Offender), proplists:get_value(mfargs, Offender)} of
        {Name, {toroco_behavior, start_link, _}} when is_atom(Name) -> bump(Name);
        _ -> ok
    end;
log(_Event, _Config) ->
    ok.

bump(Name) ->
    Key = {?MODULE, Name},
    Ref = case persistent_term:get(Key, undefined) of
              undefined ->
                  %% A new key costs no global garbage collection; one is
                  %% created per name, on its first restart.
                  R = counters:new(1, [write_concurrency]),
                  persistent_term:put(Key, R),
                  R;
              R -> R
          end,
    counters:add(Ref, 1, 1).
