%% @doc Supervises the devices (sensors and actuators, layer 0).
%%
%% Its restart intensity (app env `device_restart_intensity', default 20
%% restarts in 10 s) counts the runtime's clock: in real time OTP counts it;
%% in lockstep `toroco_lockstep' counts it in simulated time (SPEC §17) and
%% this supervisor's own, in real seconds, is lifted. When lockstep spends
%% it, the devices are taken out ({@link take_out/0}); in real time this
%% supervisor gives up and `toroco_sup' restarts the runtime's lower half.
-module(toroco_devices_sup).
-behaviour(supervisor).

-export([start_link/0, follow_clock/0, take_out/0, init/1]).

-define(LIFTED, 1000000).

-spec start_link() -> {ok, pid()} | {error, term()}.
start_link() ->
    supervisor:start_link({local, ?MODULE}, ?MODULE, []).

%% @doc Takes the restart intensity of the clock now in use (called as
%% lockstep starts and ends): the supervisor reads its flags again, its
%% devices untouched.
-spec follow_clock() -> ok | {error, term()}.
follow_clock() ->
    case whereis(?MODULE) of
        undefined ->
            ok;
        _ ->
            ok = sys:suspend(?MODULE),
            try sys:change_code(?MODULE, ?MODULE, undefined, [])
            after sys:resume(?MODULE)
            end
    end.

%% @doc Stops and removes every device: what lockstep does when their
%% restart intensity is spent in simulated time.
-spec take_out() -> ok.
take_out() ->
    Names = [Id || {Id, _, _, _} <- supervisor:which_children(?MODULE)],
    logger:error("toroco: the devices exceeded their restart intensity in simulated time "
                 "and were taken out: ~0p", [Names], #{domain => [toroco, lockstep]}),
    _ = [begin
             _ = supervisor:terminate_child(?MODULE, Id),
             supervisor:delete_child(?MODULE, Id)
         end || Id <- Names],
    ok.

-spec init([]) -> {ok, {supervisor:sup_flags(), []}}.
init([]) ->
    %% one_for_one: a device failing says nothing about the others.
    {R, P} = case toroco_clock:mode() of
                 lockstep -> {?LIFTED, 1};
                 realtime -> application:get_env(toroco, device_restart_intensity, {20, 10})
             end,
    {ok, {#{strategy => one_for_one, intensity => R, period => P}, []}}.
