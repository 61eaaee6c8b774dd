// map_merger actor: several robots' laser SLAM joined into one map (MapMerger,
// docs/algorithms.md#several-robots-one-map). Each robot runs its own two-level SLAM under its
// own topic namespace (`namespace: r1` in the profile); this actor, usually on a server, finds
// the inter-robot closures, keeps each robot's frame in the merged frame (the first robot's) and
// sends every robot the merged map and its pose in it.
//
// Subscribes, for each robot R of `robots`:
//   R/submaps        msg::Submap          reliable   finished submaps (others ignored); the
//                                                    grid, the chained origin and trajectory
//   R/submap_poses   msg::SubmapPoses     keep_latest(1), with optimized_poses: R's optimiser's
//                                         submap origins (R's frame), which win over chaining
//   R/pose           msg::PoseStamped     keep_latest(10), optional: R's live pose in R's frame
//   R/trajectory_final msg::PoseStamped   reliable, optional: R's final trajectory (R's frame)
//   R/ground_truth   msg::GroundTruthPose keep_latest(1000), with score_ground_truth: scores
//                                         every closure (simulation)
// Publishes:
//   map              msg::OccupancyGrid   the merged map: every robot joined to the first, each
//                                         at its frame; every publish_period_s when it changed,
//                                         and at stop
//   R/map_pose       msg::PoseStamped     R's live pose in the merged frame, once R is joined
//   R/trajectory_merged msg::PoseStamped  at stop: R's final trajectory in the merged frame
//                                         (when R is joined)
// Writes (with an output directory, at stop): frames_file (robot_frames.json): each robot's
// frame in the merged frame, whether it is joined, its closures.
//
// A submap's origin in its robot's frame: the robot's optimiser's when known, else its chained
// origin moved as the robot's newest optimised submap was (as the loop detector does).
// Bad input (non-finite poses, an inconsistent grid) is reported on stderr and counted.
#pragma once

#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/geometry/pose_history.hpp>
#include <tessera/laser_slam/map_merger.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

struct MapMergerActorOptions {
  std::vector<std::string> robots;
  MapMergerOptions merger;
  bool optimized_poses = true;
  double publish_period_s = 0.0;
  std::string frame_id = "map";
  bool score_ground_truth = false;
  double truth_tolerance_linear = 0.5;
  double truth_tolerance_angular = 0.1;
  std::string frames_file = "robot_frames.json";

  template <class V>
  void visit(V& v) {
    v("robots", robots,
      "topic namespaces of the robots, the first one's frame being the merged frame (>= 2)");
    v("merger", merger, "inter-robot closures and joining");
    v("optimized_poses", optimized_poses,
      "subscribe to each robot's submap_poses (its graph_optimizer) and place submaps there");
    v("publish_period_s", publish_period_s,
      "publish the merged map this often [s of runtime time] when it changed; 0: only at stop");
    v("frame_id", frame_id, "frame of the merged map and poses");
    v("score_ground_truth", score_ground_truth,
      "subscribe to each robot's ground_truth and count closures as true or false");
    v("truth_tolerance_linear", truth_tolerance_linear,
      "[m] a closure within this of the truth counts as true");
    v("truth_tolerance_angular", truth_tolerance_angular, "[rad] the same for heading");
    v("frames_file", frames_file,
      "each robot's frame in the merged frame, written here (JSON) at stop; empty: none");
  }
};

class MapMergerActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit MapMergerActor(MapMergerActorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const MapMerger& merger() const { return merger_; }

 private:
  struct RobotState {
    std::map<int, tessera::Pose2> chained, optimized;  // submap origins by id
    int newest_optimized = -1;  // newest submap with both (for the correction of new ones)
    std::map<int, SubmapTrajectoryPose> first_pose;  // each submap's first trajectory pose
    // Ground truth (score_ground_truth): 50 Hz for over 5 hours.
    PoseHistory truth{1'000'000, 0.5};
    std::vector<std::pair<Nanos, tessera::Pose2>> trajectory;  // trajectory_final
    Publisher<msg::PoseStamped> map_pose_pub, trajectory_pub;
  };

  void onSubmap(int robot, const Message<msg::Submap>& m);
  void onSubmapPoses(int robot, const Message<msg::SubmapPoses>& m);
  void onPose(int robot, const Message<msg::PoseStamped>& m);
  void publishMap();
  void scoreNewClosures();
  bool truthAt(const RobotState& r, Nanos stamp, tessera::Pose2& out) const;
  /// Pose of robot k's SLAM frame in the world, from its first submap's truth.
  bool truthFrame(int robot, tessera::Pose2& out) const;
  void writeFrames();

  MapMergerActorOptions options_;
  MapMerger merger_;
  std::vector<RobotState> robots_;
  Publisher<msg::OccupancyGrid> map_pub_;
  std::string output_dir_, frames_path_, write_error_;
  Nanos last_stamp_ = 0;
  bool dirty_ = false;
  std::size_t scored_ = 0;
  std::uint64_t truth_true_ = 0, truth_false_ = 0, truth_unknown_ = 0;
  std::uint64_t maps_published_ = 0, poses_published_ = 0, submaps_rejected_ = 0;
  std::uint64_t poses_invalid_ = 0;
};

}  // namespace tessera::laser_slam
