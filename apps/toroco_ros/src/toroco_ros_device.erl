%% @doc The `ros' device: what ROS clients publish on the robot's inbound
%% topics (SPEC §15) becomes sources the wiring can name. Add it as
%% `{device, ros, toroco_ros_device, #{}}' in a wiring file; its
%% output `cmd_vel' (the topic `/cmd_vel', `geometry_msgs/msg/Twist') is
%% the source `{ros, cmd_vel}', and each Twist published there is emitted
%% as `{Left, Right}' wheel velocities (`toroco_ros_topics:twist_to_wheels/2'
%% with `toroco_ros_topics:geometry/0'), a `send'. Holding the command, and
%% stopping when commands stop, are the wiring's: the library's teleop
%% (`toroco_lib_teleop') latches each command and lets it go `timeout_ms'
%% after the last.
%%
%% The rosbridge server (`toroco_ros_server') checks a message against
%% its type before it hands it over with {@link publish/3}, a call bounded by
%% `?CALL_MS': a device that does not take it by then (the robot is behind)
%% answers `{error, busy}' and the message is dropped, so a client waits at
%% most that long and a flood of publishes piles up nowhere. A Twist that
%% does not fit is counted as `bad_message' here too. `info/2': `received',
%% `emitted', `bad_message'; publishes refused as `busy' are counted by the
%% server (`/metrics').
%%
%% Time. In real time (`make run', `torobot_sim:run/2' with `speed') a
%% publish is emitted when it arrives. In lockstep (SPEC §14) the world is
%% the clock and a run depends only on what the world hands the robot: a
%% publish from a live client still arrives when it arrives (it is emitted
%% and its consequences run as steps at the robot's current simulated time),
%% so such a run is no longer exact; for a reproducible run hand the
%% commands as stimuli of the ticks instead: `toroco_clock:tick(T,
%% [toroco_ros_device:stimulus(ros, Twist)])', taken exactly like a
%% publish.
-module(toroco_ros_device).
-behaviour(toroco_device).

-export([publish/3, stimulus/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2]).

%% How long a publish may wait for the device.
-define(CALL_MS, 200).
%% The inbound topics: output name => ROS 2 type.
-define(INBOUND, #{cmd_vel => <<"geometry_msgs/msg/Twist">>}).

%% @doc Hands a message for output `Output' (`cmd_vel') to device `Name'.
-spec publish(atom(), atom(), map()) -> ok | {error, {not_running, atom()} | busy}.
publish(Name, Output, Msg) ->
    try toroco_device:call(Name, {?MODULE, publish, Output, Msg}, ?CALL_MS)
    catch
        exit:{timeout, _} -> {error, busy};
        exit:_ -> {error, {not_running, Name}}
    end.

%% @doc Lockstep: a message on `cmd_vel' for device `Name' as a stimulus
%% for `toroco_clock:tick/2'.
-spec stimulus(atom(), map()) -> toroco_clock:stimulus().
stimulus(Name, Msg) ->
    {Name, {?MODULE, publish, cmd_vel, Msg}}.

-spec interface(map()) -> #{inputs := [], outputs := [atom()]}.
interface(_Opts) ->
    #{inputs => [], outputs => maps:keys(?INBOUND)}.

-spec init(atom(), map()) -> {ok, listening, map()} | {error, term()}.
init(Name, Opts) ->
    case maps:keys(Opts) of
        [] -> {ok, listening, #{name => Name, received => 0, emitted => 0, bad_message => 0}};
        [K | _] -> {error, {unknown_option, K}}
    end.

-spec handle_input(atom(), term(), listening, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), listening, map()) ->
          toroco_behavior:result().
handle_event({call, From}, {?MODULE, publish, cmd_vel, Msg}, State, D) ->
    {keep_state, D1, Actions} = handle_event(info, {?MODULE, publish, cmd_vel, Msg}, State, D),
    {keep_state, D1, [{reply, From, ok} | Actions]};
handle_event({call, From}, _Request, _State, _D) ->
    {keep_state_and_data, [{reply, From, {error, unknown_call}}]};
handle_event(info, {?MODULE, publish, cmd_vel, Msg}, _State, D = #{received := R}) ->
    case toroco_ros_topics:twist_to_wheels(Msg, toroco_ros_topics:geometry()) of
        {ok, Wheels} ->
            #{emitted := E} = D,
            {keep_state, D#{received := R + 1, emitted := E + 1}, [{send, #{cmd_vel => Wheels}}]};
        {error, Why} ->
            #{name := Name, bad_message := B} = D,
            logger:warning("~p: a /cmd_vel message that is not a Twist: ~0p", [Name, Why],
                           #{domain => [toroco, ros]}),
            {keep_state, D#{received := R + 1, bad_message := B + 1}, []}
    end;
handle_event(_Type, _Content, _State, _D) ->
    keep_state_and_data.

-spec info(listening, map()) -> map().
info(_State, D) ->
    maps:with([received, emitted, bad_message], D).
