%% The world value, shared by `torobot_world' (which exports it as the
%% opaque `torobot_world:world()') and the modules it delegates to:
%% `torobot_world_file' builds it, `torobot_world_step' moves the robot in
%% it, `torobot_world_sensing' reads its sensors. Private to this app.

-record(world, {
          arena :: {float(), float()},
          walls :: [{torobot_geometry:point(), torobot_geometry:point()}],
          objects :: [{torobot_world:colour(), torobot_geometry:point(), float()}],
          obstacles :: [torobot_geometry:obstacle()],
          start :: torobot_world:pose(),
          pos :: torobot_geometry:point(),
          theta :: float(),
          time_ms = 0 :: non_neg_integer(),
          duration_ms :: pos_integer(),
          geometry :: map(),
          ir :: map(),
          camera :: map(),
          seed :: integer(),
          tick_ms :: pos_integer(),
          stop_on_red :: boolean(),
          touching = [] :: ordsets:ordset(torobot_world_step:key()),
          wall_contacts = 0 :: non_neg_integer(),
          blue_contacts = 0 :: non_neg_integer(),
          red_touched_ms = none :: non_neg_integer() | none,
          distance = 0.0 :: float(),
          trajectory = [] :: [torobot_world:sample()],
          extras = #{} :: map(),
          %% Several robots in one world: this robot's name and colour, the
          %% other robots where the simulator last put them, and the
          %% contacts with them.
          name :: atom() | undefined,
          colour = none :: torobot_world:colour() | none,
          others = [] :: [torobot_world:body()],
          robot_contacts = 0 :: non_neg_integer()
         }).

%% A contact begins within TOUCH of an obstacle and ends beyond RELEASE
%% (metres); overlaps smaller than SLACK are rounding, not penetration.
-define(TOUCH, 1.0e-4).
-define(RELEASE, 5.0e-3).
-define(SLACK, 1.0e-9).
