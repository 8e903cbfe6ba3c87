%% @doc The root of `toroco_rec'.
%%
%% ```
%% toroco_rec_sup (one_for_one)
%%   toroco_rec_flight    the flight recorder (always on) and the recording
%%                        asked for (toroco_rec:record/2)
%% '''
%%
%% The rest of the application is code its callers run: the JSON of terms
%% (`toroco_rec_json'), the channels (`toroco_rec_channels'), the tap's
%% client (`toroco_rec_tap'), MCAP (`toroco_rec_mcap') and replay
%% (`toroco_rec_replay', in the caller's process).
-module(toroco_rec_sup).
-behaviour(supervisor).

-export([start_link/0, init/1]).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

-spec init([]) -> {ok, {supervisor:sup_flags(), [supervisor:child_spec()]}}.
init([]) ->
    Flags = #{strategy => one_for_one, intensity => 5, period => 10},
    %% A recording being written is completed on the way down.
    Flight = #{id => toroco_rec_flight, start => {toroco_rec_flight, start_link, []},
               shutdown => 30000},
    {ok, {Flags, [Flight]}}.
