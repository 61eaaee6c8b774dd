// map_assembler actor: the global occupancy grid drawn from all submaps (MapAssembler).
//
// Subscribes:
//   submaps      msg::Submap            reliable   finished submaps (grid in the submap frame)
//   constraints  msg::SubmapConstraint  reliable   hand-over constraints place each new submap
//                                                  relative to the previous one (chained)
//   submap_poses msg::SubmapPoses       keep_latest(1), only with optimized_poses: true — the
//                                       graph optimiser's poses, which win over chaining; the
//                                       submaps lifelong mapping trimmed are dropped (cells,
//                                       poses and the constraints that name them), and so are
//                                       later messages about them
//   camera_calibrations msg::CameraCalibration  reliable, optional (none need be published):
//                                       environment cameras' calibrations (camera_network_slam);
//                                       the latest per camera id is kept for the saved state, an
//                                       invalid one (homography not 9 finite numbers or singular,
//                                       bad quality figures) is reported and counted
// Publishes:
//   map          msg::OccupancyGrid     every publish_period_s when a submap arrived, and in
//                                       stop() (the final map)
// A submap's global pose: the optimiser's when it has one, else chained from its hand-over
// constraint when its predecessor is placed, otherwise the globalPose its message carries.
//
// Memory: every submap's grid is kept, its cells zstd-compressed (MapAssembler; ~14x smaller
// than 1 byte per cell on the Intel submaps), to redraw the map when poses change; summary
// memory_mb (at stop) and memory_peak_mb give their packed bytes, which grow with the explored
// area. Saving the state at stop unpacks every submap into the state being written.
//
// Saved state (slam_state.hpp, docs/architecture.md#saved-slam-state):
//   state_dir   at stop, with an output folder, writes what it holds there (relative to the
//               output folder): every placed submap at the pose it was drawn with, and every
//               distinct constraint received with a valid covariance (not fused), information
//               = covariance⁻¹, and each camera's latest calibration whose submap is saved
//               (others are reported and counted in state_cameras_unsaved).
//   load_state  a state directory read at construction (ConfigError naming the path and field
//               on failure); the actor then serves that map: it subscribes to nothing, publishes
//               the assembled map in start() and again in stop(), so a profile needs no SLAM.
//               Its constraints and cameras are kept, so a state_dir saves them again.
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/laser_slam/map_assembler.hpp>
#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace tessera::laser_slam {

struct MapAssemblerOptions {
  double resolution = 0.0;
  double publish_period_s = 0.0;
  std::string frame_id = "map";
  bool optimized_poses = false;
  std::string state_dir = "slam_state";
  std::string load_state;

  template <class V>
  void visit(V& v) {
    v("optimized_poses", optimized_poses,
      "subscribe to submap_poses (graph_optimizer) and draw submaps at those poses");
    v("resolution", resolution, "cell size of the global map [m]; 0 = the submaps'");
    v("publish_period_s", publish_period_s,
      "publish the map this often [s of runtime time] when it changed; 0: only at stop");
    v("frame_id", frame_id, "frame of the published map");
    v("state_dir", state_dir,
      "at stop, save the SLAM state (submaps, poses, constraints) in this folder of the output "
      "directory; empty: none");
    v("load_state", load_state,
      "serve the map of this saved SLAM state (no subscriptions; published at start and stop)");
  }
};

class MapAssemblerActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit MapAssemblerActor(MapAssemblerOptions options);
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  void summarize(Summary& out) const override;

  const MapAssembler& assembler() const { return assembler_; }

 private:
  void onSubmap(const Message<msg::Submap>& m);
  void onConstraint(const Message<msg::SubmapConstraint>& m);
  void keepConstraint(const Message<msg::SubmapConstraint>& m, const tessera::Pose2& relative);
  void onOptimizedPoses(const Message<msg::SubmapPoses>& m);
  void dropTrimmed(int id);
  void onCameraCalibration(const Message<msg::CameraCalibration>& m);
  void placeChained();
  void publishMap();
  void loadState();
  void writeState();
  /// Bytes of the (packed) submap grids held now.
  std::size_t gridBytes() const;
  void noteGridBytes() { grid_bytes_peak_ = std::max(grid_bytes_peak_, gridBytes()); }

  MapAssemblerOptions options_;
  MapAssembler assembler_;
  Publisher<msg::OccupancyGrid> map_pub_;
  std::map<int, tessera::Pose2> message_pose_;  // globalPose carried by each submap message
  std::map<int, std::pair<int, tessera::Pose2>> handover_;  // to-id -> (from-id, relative)
  std::map<int, tessera::Pose2> optimized_;                 // from the graph optimiser
  std::map<int, bool> finished_;                            // each submap's finished flag
  std::vector<SavedConstraint> kept_;  // distinct constraints with a valid covariance, in order
  std::set<std::tuple<int, int, double, double, double>> kept_keys_;
  std::map<int, SavedCamera> cameras_;  // latest calibration per camera id
  std::set<int> trimmed_;               // submaps lifelong mapping removed
  std::uint64_t ignored_trimmed_ = 0;   // messages about them after the trim
  std::size_t trimmed_listed_ = 0;      // length of the last submap_poses.trimmed handled
  std::string output_dir_, state_path_, state_error_;
  bool loaded_ = false;
  std::uint64_t constraints_unsaved_ = 0, state_submaps_ = 0, state_constraints_ = 0;
  std::uint64_t calibrations_received_ = 0, calibrations_rejected_ = 0, cameras_unsaved_ = 0,
                state_cameras_ = 0;
  Nanos last_stamp_ = 0;
  bool dirty_ = false;
  std::uint64_t submaps_ = 0, constraints_ = 0, maps_published_ = 0, submaps_rejected_ = 0;
  std::uint64_t constraints_rejected_ = 0, pose_updates_ = 0;
  int map_width_ = 0, map_height_ = 0;
  std::size_t grid_bytes_peak_ = 0;  // largest gridBytes() so far
};

}  // namespace tessera::laser_slam
