// rgbd_front_end actor: RGB-D visual odometry (Tracker, tracker.hpp) on msg::RgbdFrame.
//
// Subscribes:
//   rgbd          msg::RgbdFrame          keep_latest(1): a frame that arrives while one is being
//                                         tracked replaces the waiting one (counted as dropped)
//   keyframe_poses msg::KeyframePoses     keep_latest(1), only with forget_trimmed (lifelong
//                                         mode): a keyframe the message says left the graph
//                                         (KeptKeyframes, messages/keyframe_poses.hpp) has its
//                                         features and points released (Tracker::forgetKeyframe)
// Publishes:
//   camera_pose   msg::PoseStamped3D      every tracked frame: camera-to-world of the dataset's
//                                         camera (the depth camera when colour and depth are not
//                                         registered), frame world_frame, child frame_id, the
//                                         frame's index and how it was tracked; lost and skipped
//                                         frames publish nothing
//   keyframes     msg::Keyframe           reliable, each keyframe the tracker inserts (the
//                                         colour camera: keypoints, descriptors, 3D points and a
//                                         depth image every keyframe_depth_step-th pixel)
// Colour and depth that are not registered (7-Scenes, colorRegistered = false): with
// tracker.register_depth, the depth is re-projected into the colour camera with 7-Scenes' usual
// calibration and the colour camera is tracked (depth_registration.hpp); the published
// camera_pose is moved back to the depth camera, the frame of the dataset's poses.
// A frame the actor cannot read (unknown encoding, sizes that disagree, data shorter than
// height x step) is skipped and counted by reason, as are the tracker's own skips; never an
// exception. Ground truth carried by the frames gives the ATE (rigid alignment, evaluation core)
// in the summary; keep_trajectory: false (lifelong) keeps no per-frame poses for it.
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/depth_registration.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::visual_slam {

struct RgbdFrontEndOptions {
  TrackerOptions tracker;  ///< register_depth among them (one default with `bench rgbd`)
  int keyframe_depth_step = 4;
  std::string world_frame = "world";
  std::string frame_id = "camera";
  bool forget_trimmed = false;
  bool keep_trajectory = true;
  /// register_depth moved into the tracker's options (shared with `bench rgbd`).
  static constexpr RenamedKey kRenamedKeys[] = {{"register_depth", "tracker.register_depth"}};

  template <class V>
  void visit(V& v) {
    v("tracker", tracker, "the tracker (features, matching, PnP, keyframe rule, local map)");
    v("keyframe_depth_step", keyframe_depth_step,
      "keyframe messages keep every n-th depth pixel of every n-th row (0 = no depth)");
    v("world_frame", world_frame, "frame of the published poses");
    v("frame_id", frame_id, "child frame of the published poses");
    v("forget_trimmed", forget_trimmed,
      "lifelong mode: subscribe to keyframe_poses and release the keyframes the graph trimmed");
    v("keep_trajectory", keep_trajectory,
      "keep every frame's pose for the summary's ATE (false: memory stays flat in long runs)");
  }
};

class RgbdFrontEndActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options (naming the key).
  explicit RgbdFrontEndActor(RgbdFrontEndOptions options);
  ~RgbdFrontEndActor() override;
  void configure(ActorContext& ctx) override;
  /// frames, tracked, keyframes, lost, relocalised, skipped (and skipped_<reason>), ms per frame
  /// mean / p95 and the split, ate_rmse_m with ground truth.
  void summarize(Summary& out) const override;

  const Tracker* tracker() const { return tracker_.get(); }

 private:
  void onFrame(const Message<msg::RgbdFrame>& m);
  void onPoses(const Message<msg::KeyframePoses>& m);
  void skip(const std::string& reason);
  /// Builds the tracker on the first frame (intrinsics come with the frames); "" or why not.
  std::string setUp(msg::RgbdFrame::Reader f);

  RgbdFrontEndOptions options_;
  std::unique_ptr<Tracker> tracker_;
  PinholeCamera depth_camera_;
  std::optional<ColorCalibration> calibration_;  ///< set when depth is registered to colour
  Publisher<msg::PoseStamped3D> pose_pub_;
  Publisher<msg::Keyframe> keyframe_pub_;

  std::uint64_t frames_ = 0, published_ = 0, keyframes_ = 0;
  std::map<std::string, std::uint64_t> skipped_;
  std::vector<double> ms_;
  FrameTiming split_sum_;
  struct Stamped {
    std::int64_t stamp_ns;
    Eigen::Isometry3d pose;
  };
  std::vector<Stamped> estimate_, truth_;
};

}  // namespace tessera::visual_slam
