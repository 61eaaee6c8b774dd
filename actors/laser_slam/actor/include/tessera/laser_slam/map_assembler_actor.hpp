// map_assembler actor: the global occupancy grid drawn from all submaps (MapAssembler).
//
// Subscribes:
//   submaps      msg::Submap            reliable   finished submaps (grid in the submap frame)
//   constraints  msg::SubmapConstraint  reliable   hand-over constraints place each new submap
//                                                  relative to the previous one (chained)
//   submap_poses msg::SubmapPoses       keep_latest(1), only with optimized_poses: true — the
//                                       graph optimiser's poses, which win over chaining
// Publishes:
//   map          msg::OccupancyGrid     every publish_period_s when a submap arrived, and in
//                                       stop() (the final map)
// A submap's global pose: the optimiser's when it has one, else chained from its hand-over
// constraint when its predecessor is placed, otherwise the globalPose its message carries.
#pragma once

#include <tessera/msg/submap.capnp.h>
#include <tessera/laser_slam/map_assembler.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <map>
#include <string>

namespace tessera::laser_slam {

struct MapAssemblerOptions {
  double resolution = 0.0;
  double publish_period_s = 0.0;
  std::string frame_id = "map";
  bool optimized_poses = false;

  template <class V>
  void visit(V& v) {
    v("optimized_poses", optimized_poses,
      "subscribe to submap_poses (graph_optimizer) and draw submaps at those poses");
    v("resolution", resolution, "cell size of the global map [m]; 0 = the submaps'");
    v("publish_period_s", publish_period_s,
      "publish the map this often [s of runtime time] when it changed; 0: only at stop");
    v("frame_id", frame_id, "frame of the published map");
  }
};

class MapAssemblerActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit MapAssemblerActor(MapAssemblerOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const MapAssembler& assembler() const { return assembler_; }

 private:
  void onSubmap(const Message<msg::Submap>& m);
  void onConstraint(const Message<msg::SubmapConstraint>& m);
  void onOptimizedPoses(const Message<msg::SubmapPoses>& m);
  void placeChained();
  void publishMap();

  MapAssemblerOptions options_;
  MapAssembler assembler_;
  Publisher<msg::OccupancyGrid> map_pub_;
  std::map<int, tessera::Pose2> message_pose_;  // globalPose carried by each submap message
  std::map<int, std::pair<int, tessera::Pose2>> handover_;  // to-id -> (from-id, relative)
  std::map<int, tessera::Pose2> optimized_;                 // from the graph optimiser
  Nanos last_stamp_ = 0;
  bool dirty_ = false;
  std::uint64_t submaps_ = 0, constraints_ = 0, maps_published_ = 0, submaps_rejected_ = 0;
  std::uint64_t constraints_rejected_ = 0, pose_updates_ = 0;
  int map_width_ = 0, map_height_ = 0;
};

}  // namespace tessera::laser_slam
