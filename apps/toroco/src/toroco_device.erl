%% @doc Devices: sensors and actuators standing for hardware or services.
%%
%% A device module implements this behaviour. It takes part in wiring exactly
%% like a behavior (SPEC §7): its outputs are sources, its inputs are wired to
%% sources and delivered through `handle_input/4', and it emits with the same
%% `send' / `set' / `unset' actions. Devices are layer 0 and live under
%% `toroco_devices_sup'. They run on the behavior engine (`toroco_behavior'),
%% so everything said there holds; the differences are that `interface/1' and
%% `init/2' see the device's options (and `init/2' its name), and that the
%% optional `info/2' adds the device's own counters to `toroco:inspect(Name)'.
%%
%% Add one with `toroco:add_device(Name, Module, Opts)'; {@link start_link/3}
%% is the start function the supervisor calls. A device module's API reaches
%% its own process with {@link call/3} and {@link cast/2} (handled by its
%% `handle_event/4'), so it needs no name of the runtime's.
-module(toroco_device).

-export([start_link/3, spec/3, call/3, cast/2]).

-callback interface(Opts :: map()) -> #{inputs := [atom()], outputs := [atom()]}.
-callback init(Name :: atom(), Opts :: map()) ->
    {ok, State :: term(), Data :: term()} |
    {ok, State :: term(), Data :: term(), Actions :: toroco_behavior:actions()} |
    {error, Reason :: term()}.
-callback handle_input(Input :: atom(), Value :: term(), State :: term(), Data :: term()) ->
    toroco_behavior:result().
-callback handle_event(gen_statem:event_type(), Content :: term(), State :: term(),
                       Data :: term()) ->
    toroco_behavior:result().
-callback info(State :: term(), Data :: term()) -> map().
-callback terminate(Reason :: term(), State :: term(), Data :: term()) ->
    {emit, toroco_behavior:actions()} | term().
-optional_callbacks([handle_event/4, info/2, terminate/3]).

%% @doc Starts device `Name' running `Module' with `Opts', registered and
%% wired like a behavior of layer 0.
-spec start_link(atom(), module(), map()) -> gen_statem:start_ret().
start_link(Name, Module, Opts) ->
    toroco_behavior:start_link(spec(Name, Module, Opts)).

%% @doc A request to the process of device `Name' (its `handle_event({call,
%% From}, Request, ...)'); exits as `gen_statem:call/3' does when it is not
%% running or does not answer in time.
-spec call(atom(), term(), timeout()) -> term().
call(Name, Request, Timeout) ->
    gen_statem:call(toroco_names:process(Name), Request, Timeout).

%% @doc A message to the process of device `Name' (its `handle_event(cast,
%% Msg, ...)'); nothing happens if it is not running.
-spec cast(atom(), term()) -> ok.
cast(Name, Msg) ->
    gen_statem:cast(toroco_names:process(Name), Msg).

%% @doc The engine spec of a device.
-spec spec(atom(), module(), map()) -> toroco_behavior:spec().
spec(Name, Module, Opts) ->
    #{kind => device, name => Name, module => Module, layer => 0, args => Opts}.
