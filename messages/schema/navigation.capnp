# Navigation messages: goals for the navigation stack and its progress. Evolve by Cap'n Proto
# rules: add fields, never renumber.
#
# Types the navigation actors use that live elsewhere, because they already say what is needed:
# * a pose with covariance (localized_pose, initial_pose): common.capnp PoseStamped, whose Pose2D
#   carries the 3x3 covariance over (x [m], y [m], theta [rad]), row-major; the trajectory
#   writers and evaluators read that type already;
# * map -> odom: common.capnp PoseStamped (header.frameId = map, the pose of the odom frame's
#   origin in the map frame), as the laser SLAM actors publish it;
# * a velocity command (cmd_vel): common.capnp Twist (header + Twist2D: vx forward [m/s], vy
#   lateral [m/s], omega yaw rate [rad/s] in base_link; a differential drive sets vy = 0).
@0xbda2654fe6bfc4ad;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# A goal for the navigation stack: where base_link should end up.
struct NavGoal {
  header @0 :Common.Header;    # frameId = map; stampNs = when the goal was issued
  pose @1 :Common.Pose2D;      # target pose of base_link in the map frame [m, m, rad];
                               # covariance unused
  id @2 :UInt64;               # chosen by the sender; NavStatus echoes it. A new goal replaces
                               # the current one.
  toleranceXy @3 :Float64;     # [m] reached when this close in position; <= 0: the planner's
                               # default
  toleranceYaw @4 :Float64;    # [rad] and this close in heading; <= 0: the planner's default;
                               # NaN or +inf: heading does not matter
}

# The navigation stack's progress towards its current goal, published on every change of state
# and periodically while a goal is active.
struct NavStatus {
  enum State {
    idle @0;        # no goal
    planning @1;    # computing a global path
    driving @2;     # following the path
    recovering @3;  # stuck: a recovery behaviour runs (rotate, back up, clear the costmap)
    reached @4;     # within the goal's tolerances (final)
    failed @5;      # gave up after the recovery attempts, see reason (final)
    refused @6;     # never started: off the map, inside an obstacle, bad numbers; see reason
                    # (final)
  }
  header @0 :Common.Header;    # frameId = map
  goalId @1 :UInt64;           # the NavGoal id this is about (0 when idle)
  state @2 :State;
  reason @3 :Text;             # why failed or refused, which recovery runs; empty otherwise
  distanceRemaining @4 :Float64;  # [m] along the current path to the goal; NaN when unknown
}

# What the dynamic window weighed in one control period (docs/algorithms.md#local-planning):
# every sampled velocity pair's arc, for display (the viewer's DWA layer, Foxglove). Published
# at the navigator's local_plan_hz while a goal is being driven.
struct LocalPlan {
  struct Arc {
    v @0 :Float32;               # [m/s] the pair's forward speed
    w @1 :Float32;               # [rad/s] its yaw rate
    admissible @2 :Bool;         # the robot can stop before the arc's first contact
    score @3 :Float32;           # the dynamic window's normalised score (higher is better);
                                 # 0 when not admissible
    clearance @4 :Float32;       # [m] clear length along the arc (capped at the horizon)
    xy @5 :List(Float32);        # the rolled-out arc in the map frame: x0, y0, x1, y1, ... [m]
  }
  header @0 :Common.Header;      # frameId = map; stamp of the control period
  goalId @1 :UInt64;             # the goal being driven to
  command @2 :Common.Twist2D;    # the chosen pair (vy = 0)
  chosen @3 :Int32;              # index of the chosen arc in arcs; -1 when none was admissible
  arcs @4 :List(Arc);
}
