# Two-level laser SLAM messages (docs/algorithms.md#submap-hand-over-and-loop-detection): finished local maps and the constraints between them.
# Evolve by Cap'n Proto rules: add fields, never renumber.
@0x801dd893863307a2;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";
using Map = import "map.capnp";

struct Submap {
  header @0 :Common.Header;     # stamp of the last scan in it; frameId = map
  id @1 :UInt32;                # 0, 1, 2, ... in creation order
  grid @2 :Map.OccupancyGrid;   # in the submap's own frame (origin = robot pose at its start)
  globalPose @3 :Common.Pose2D; # submap origin in the map frame, from chained constraints
  scans @4 :UInt32;             # scans inserted
  travelledM @5 :Float64;       # [m] odometry path length inside the submap
  finished @6 :Bool;            # false: a snapshot of the submap still being built
  # Finished submaps: the robot's smoothed pose at each scan in the submap, in the submap's
  # frame (the final best particle's poses at its filter updates, moved by odometry between
  # them). Consumers that used the online estimate of a scan (e.g. for a loop closure) replace
  # it with this once the submap is done. Empty when the producer keeps no trajectory.
  trajectory @7 :List(ScanPose);
  struct ScanPose {
    stampNs @0 :Int64;
    x @1 :Float64;              # [m]
    y @2 :Float64;              # [m]
    theta @3 :Float64;          # [rad]
  }
}

struct SubmapConstraint {
  header @0 :Common.Header;     # stamp of the measurement
  fromId @1 :UInt32;            # submap i
  toId @2 :UInt32;              # submap j
  # Pose of submap j's origin in submap i's frame, with covariance (x, y, theta) in frame i.
  relative @3 :Common.Pose2D;
  kind @4 :Kind;
  enum Kind {
    handOver @0;                # the robot's pose in i when j started (docs/algorithms.md#submap-hand-over-and-loop-detection)
    revisit @1;                 # a relocalisation in an existing submap (camera, loop closure)
  }
  # Revisits found by matching one scan (loop detector): the robot's pose at the header's stamp
  # in submap j's frame, i.e. the match itself, with its covariance (x, y, theta in frame j).
  # A scan-level graph attaches that scan to submap j with it. Unset for hand-overs and for
  # revisits not made from a scan.
  scanInTo @5 :Common.Pose2D;
  # Hand-overs only: the builder was lost when it started j (its scan matching collapsed,
  # docs/algorithms.md#camera-network-calibration), so j is placed by odometry alone, with a wide
  # covariance, and is not anchored to i until a revisit (a camera or a loop closure) places it.
  lost @6 :Bool;
}

# The global level's answer: every submap's optimised origin in the map frame (docs/algorithms.md#submap-hand-over-and-loop-detection).
struct SubmapPoses {
  header @0 :Common.Header;     # stamp of the newest constraint in the graph; frameId = map
  poses @1 :List(SubmapPose);   # by increasing id
  chi2 @2 :Float64;             # g2o objective after this optimisation (without the 1/2)
  iterations @3 :UInt32;        # solver iterations this optimisation took
  # Lifelong mapping (docs/algorithms.md#lifelong-mapping): every submap removed from the map so
  # far, newer ones covering its area, by increasing id. Consumers drop them (cumulative, so a
  # keep_latest subscriber that skips messages still learns of each one).
  trimmed @4 :List(UInt32);
  struct SubmapPose {
    id @0 :UInt32;
    pose @1 :Common.Pose2D;     # covariance left zero
  }
}
