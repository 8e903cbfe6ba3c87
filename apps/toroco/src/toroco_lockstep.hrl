%% The lockstep clock's state, shared by `toroco_lockstep' and the modules
%% it is made of (`toroco_lockstep_settle', `_timers', `_remote', `_trace').

-define(TAG, '$toroco_lockstep').
-define(LOG, #{domain => [toroco, clock]}).
-define(SETTLE_GUARD_MS, 5000).

%% a queued message: its address, the process it was sent to, the message
-type item() :: {term(), pid() | undefined | remote, term()}.

%% what a process of the path said when it was up
-type proc() :: #{name := atom(), sup := pid() | undefined,
                  layer := non_neg_integer() | none | consumer, mon := reference()}.
%% a send, a timer or a cancel that arrived while an exit settled, with its sender
-type held() :: {send, term(), pid() | undefined | remote, term()}
              | {timer, pid(), term(), integer(), term()}
              | {cancel, pid(), term()}.
%% an exit settling: the restarts awaited (name -> supervisor), the layers
%% being taken out (supervisor -> layer), the barrier's answers awaited
-record(settle, {awaiting = #{} :: #{atom() => pid() | undefined},
                 takeout = #{} :: #{pid() => non_neg_integer() | devices},
                 barrier = none :: none | {reference(), #{pid() => true}},
                 %% the DOWNs that consumers monitoring the dead will hand over
                 expect = #{} :: #{{pid(), pid()} => true},
                 guard :: reference()}).

-record(s, {queue = queue:new() :: queue:queue(item()),
            inflight = none :: none | {reference() | none, reference(), pid() | {pending, node()}},
            procs = #{} :: #{pid() => proc()},
            %% the supervisors of the processes of the path, monitored
            sups = #{} :: #{pid() => {reference(), non_neg_integer() | none | consumer}},
            %% the consumers that monitor the process in flight (or killed)
            watch = #{} :: #{pid() => [pid()]},
            settle = none :: none | #settle{},
            held = [] :: [{non_neg_integer(), pid(), held()}],
            downs = [] :: [{non_neg_integer(), pid(), term()}],
            arrival = 0 :: non_neg_integer(),
            %% each layer supervisor's restarts, in simulated ms, newest first
            restarts = #{} :: #{pid() => [integer()]},
            intensity = {5, 10} :: {non_neg_integer(), pos_integer()},
            device_intensity = {20, 10} :: {non_neg_integer(), pos_integer()},
            unsettled = 0 :: non_neg_integer(),
            timers = gb_trees:empty() :: gb_trees:tree({integer(), non_neg_integer()},
                                                       {pid(), term(), term()}),
            owned = #{} :: #{{pid(), term()} => {integer(), non_neg_integer()}},
            seq = 0 :: non_neg_integer(),
            now = 0 :: integer(),
            target = 0 :: integer(),
            cell :: atomics:atomics_ref() | undefined,
            waiters = [] :: [gen_server:from()],
            %% a tick's stimuli: they go once its time is reached
            stimuli = [] :: [toroco_lockstep:stimulus()],
            trace = off :: off | [iodata()],
            steps = 0 :: non_neg_integer(),
            lost = 0 :: non_neg_integer(),
            %% the other nodes of the world, their cuts (toroco_lockstep_nodes)
            world = none :: none | toroco_lockstep_nodes:world()}).

