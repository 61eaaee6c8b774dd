// keyframe_graph actor: the SE(3) pose graph of RGB-D keyframes (KeyframeGraph,
// keyframe_graph.hpp).
//
// Subscribes:
//   keyframes          msg::Keyframe            reliable: each becomes a node tied to the
//                                               previous one by an odometry edge
//   loop_constraints   msg::KeyframeConstraint  reliable, only with `loops`: loop edges
//                                               (robust); each accepted one triggers an
//                                               optimisation
//   camera_pose        msg::PoseStamped3D       reliable, only with `frames_file`: the front
//                                               end's pose of every frame
// Publishes:
//   keyframe_poses     msg::KeyframePoses       after every optimisation, and in stop(): every
//                                               keyframe the graph holds. In lifelong mode
//                                               (graph.trimming) an optimisation is followed by
//                                               KeyframeGraph::trim(), and a keyframe missing
//                                               from the list (id below its newest) was trimmed:
//                                               the mapper and the loop detector drop it
// Writes (with an output directory, in stop()): keyframes.tum (keyframes_file: the optimised
// camera-to-world of every keyframe at its stamp, TUM format) and keyframe_graph.g2o (g2o_file:
// VERTEX_SE3:QUAT per keyframe, EDGE_SE3:QUAT per odometry and loop edge, FIX for the first)
// and, with frames_file, every frame's pose corrected by the optimisation: a frame moves with the
// latest keyframe at or before its stamp, T' = T_k,optimised · T_k,tracked⁻¹ · T (a correction in
// the world frame, so it holds whichever camera frame the front end reports poses in). In lifelong
// mode a trimmed keyframe's frames keep the correction it had when it was trimmed.
// A bad message (no keypoints or descriptors, counts that disagree, a non-finite pose or
// covariance, a constraint naming itself) is counted by kind and skipped, never a crash. A
// constraint naming a keyframe not seen yet waits for it; at stop the ones still waiting are
// counted (constraints_unresolved).
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/keyframe_graph.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

struct KeyframeGraphActorOptions {
  KeyframeGraphOptions graph;
  bool loops = true;
  std::string frame_id = "world";
  std::string keyframes_file = "keyframes.tum";
  std::string g2o_file = "keyframe_graph.g2o";
  std::string frames_file;  ///< e.g. trajectory_optimized.tum; empty: no camera_pose input

  template <class V>
  void visit(V& v) {
    v("graph", graph, "the keyframe pose graph (edge weights, solver)");
    v("loops", loops, "subscribe to loop_constraints (false in a profile without a loop detector)");
    v("frame_id", frame_id, "frame of the published poses");
    v("keyframes_file", keyframes_file,
      "optimised keyframe poses written here (TUM) at stop, in the output directory; empty: none");
    v("g2o_file", g2o_file, "final graph written here (g2o) at stop; empty: none");
    v("frames_file", frames_file,
      "every frame's pose (camera_pose) corrected by the optimised keyframes, written here (TUM) "
      "at stop; empty: camera_pose not subscribed");
  }
};

class KeyframeGraphActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit KeyframeGraphActor(KeyframeGraphActorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const KeyframeGraph& graph() const { return graph_; }

 private:
  void onKeyframe(const Message<msg::Keyframe>& m);
  void onConstraint(const Message<msg::KeyframeConstraint>& m);
  void onFramePose(const Message<msg::PoseStamped3D>& m);
  void optimizeAndPublish();
  /// Applies trimmed keyframe `id`'s correction (its optimised pose now) to its frames for good.
  void bakeFrames(std::int64_t id, const Pose3& optimised);
  void publishPoses(double chi2, int iterations);
  void writeFiles();

  KeyframeGraphActorOptions options_;
  KeyframeGraph graph_;
  Publisher<msg::KeyframePoses> poses_pub_;
  std::string output_dir_;
  std::map<std::int64_t, std::int64_t> stamps_;    ///< keyframe id -> header stamp [ns]
  std::map<std::int64_t, std::int64_t> by_stamp_;  ///< keyframe header stamp [ns] -> id
  std::map<std::int64_t, Pose3> tracked_;          ///< keyframe id -> the tracker's pose
  /// (stamp, pose) per frame, in time order: tracked, or baked (below)
  std::vector<std::pair<std::int64_t, Pose3>> frames_;
  /// Per frame: its keyframe was trimmed, and its pose holds the correction it had then
  std::vector<char> baked_;
  std::uint64_t frames_bad_ = 0;
  std::int64_t last_stamp_ = 0;
  std::uint64_t keyframes_ = 0, keyframes_bad_ = 0, constraints_ = 0, constraints_bad_ = 0;
  std::uint64_t optimizations_ = 0, published_ = 0, solver_failures_ = 0;
  double optimize_seconds_ = 0, last_chi2_ = 0;
  std::string keyframes_path_, graph_path_, frames_path_, write_error_;
};

}  // namespace tessera::visual_slam
