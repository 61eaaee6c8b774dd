// shard_stitcher actor: the reduce step of batch reprocessing (docs/algorithms.md#batch-
// reprocessing). Reads the recordings of the shards' front ends (each a run of consecutive frames
// tracked on its own, overlapping the previous shard by a few frames; `tessera batch` writes
// them), places every shard in shard 0's frame and clock (joinShards, shard_join.hpp), and
// publishes the whole sequence as if one front end had tracked it, in stamp order on the
// simulated clock.
//
// Publishes:
//   keyframes     msg::Keyframe            pose moved into the world frame, ids renumbered 0, 1, …
//   camera_pose   msg::PoseStamped3D       every tracked frame, moved likewise
//   ground_truth  msg::GroundTruthPose3D   when the recordings hold it (stamps moved only)
// A shard's frames are taken from its first tracked frame up to the next shard's first tracked
// frame. All recordings are read in the constructor: one that is missing, damaged (any loss),
// holds a topic of the wrong type, a non-finite pose, or shares no tracked frame with the shard
// before it is a ConfigError naming the file, so nothing half-stitched is published.
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/shard_join.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace tessera::visual_slam {

struct ShardStitcherOptions {
  std::vector<std::string> recordings;
  std::string keyframes_topic = "keyframes";
  std::string poses_topic = "camera_pose";
  std::string ground_truth_topic = "ground_truth";

  template <class V>
  void visit(V& v) {
    v("recordings", recordings, "the shards' recordings, in frame order (required)");
    v("keyframes_topic", keyframes_topic, "keyframe topic in the recordings");
    v("poses_topic", poses_topic, "per-frame camera pose topic in the recordings");
    v("ground_truth_topic", ground_truth_topic,
      "ground-truth topic in the recordings (optional in them)");
  }
};

class ShardStitcherActor final : public Actor {
 public:
  /// Reads and joins every recording; throws ConfigError (see above).
  explicit ShardStitcherActor(ShardStitcherOptions options);
  ~ShardStitcherActor() override;
  void configure(ActorContext& ctx) override;
  void summarize(Summary& out) const override;

  struct Output;

 private:
  void publishDue();

  ShardStitcherOptions options_;
  std::vector<Output> outputs_;  // by global stamp
  std::size_t next_ = 0;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Keyframe> keyframe_pub_;
  Publisher<msg::PoseStamped3D> pose_pub_;
  Publisher<msg::GroundTruthPose3D> truth_pub_;
  struct Stats {
    std::int64_t keyframes = 0, poses = 0, ground_truth = 0, dropped_overlap = 0;
  } stats_;
  std::vector<std::int64_t> join_frames_;
  std::vector<ShardPlacement> placements_;
};

}  // namespace tessera::visual_slam
