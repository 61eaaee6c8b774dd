// RgbdCameraActor ("rgbd_camera"): a simulated RGB-D camera on the simulator's robot. It renders
// colour + depth of the 3D view of the world (RgbdRenderer: walls extruded to wall_height,
// floor, ceiling, furniture, procedural textures, depth and colour noise) from the robot's true
// pose and the camera mount, and publishes them with the camera's true pose.
//
// Subscribes (local topic names):
//   ground_truth     msg::GroundTruthPose    the robot's true planar pose (base_link in map), as
//                                            the simulator publishes it
// Publishes:
//   rgbd             msg::RgbdFrame          "rgb8" colour, "16UC1" depth in millimetres
//                                            (depthScale 1000, 0 = no reading) or "32FC1" metres
//                                            (NaN = no reading); registered; ground truth set
//   ground_truth_3d  msg::GroundTruthPose3D  frame world_frame, child frame_id: camera (optical
//                                            frame) to world, z up from the floor
//
// Timing: frame k is due at first + k / rate_hz, `first` being the stamp of the first pose
// received; it is rendered at the first pose whose stamp is at or after its due time, and stamped
// with that pose's stamp, so the published ground truth is exactly the pose rendered. Poses
// arrive at the simulator's odometry rate, so a rate that divides it (10, 25 Hz with odom_hz 50)
// gives evenly spaced frames; others (15 Hz) are spaced to within one pose period. Each frame's
// noise comes from the seed and the frame number alone, so equal seeds give identical frames.
// Option errors throw ConfigError from the constructor, naming the key ("camera.mount.z").
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/rgbd_renderer.hpp>
#include <tessera/sim/world.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace tessera::sim {

struct RgbdCameraOptions {
  std::string world = "builtin:office";
  double world_resolution = 0.05;
  double wall_height = 2.5;
  double rate_hz = 15;
  RgbdCameraConfig camera;
  std::string depth = "uint16";
  std::string frame_id = "camera";
  std::string world_frame = "map";
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("world", world, "the simulator's world: 'builtin:NAME' or a PGM/PNG map");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("wall_height", wall_height, "[m] walls are extruded from the floor to this ceiling height");
    v("rate_hz", rate_hz, "frame rate [Hz]");
    v("camera", camera, "image size, intrinsics, range limits, noise and mount");
    v("depth", depth, "uint16 (16UC1 millimetres, 0 = none) | float (32FC1 metres, NaN = none)");
    v("frame_id", frame_id, "the camera's optical frame name");
    v("world_frame", world_frame, "the world frame name of the ground truth");
    v("seed", seed, "random seed of the depth and colour noise");
  }
};

class RgbdCameraActor final : public Actor {
 public:
  /// Loads the world and checks every option; throws ConfigError naming the option.
  explicit RgbdCameraActor(RgbdCameraOptions options);
  RgbdCameraActor(const RgbdCameraActor&) = delete;
  RgbdCameraActor& operator=(const RgbdCameraActor&) = delete;

  void configure(ActorContext& ctx) override;
  /// frames_published, render_ms_mean, render_ms_max, valid_depth_fraction (mean over frames).
  void summarize(Summary& out) const override;

  const RgbdRenderer& renderer() const { return *renderer_; }

 private:
  void onPose(Nanos stamp, const Pose2& base);
  void publish(Nanos stamp, const Eigen::Isometry3d& camera_to_world);

  RgbdCameraOptions options_;
  World world_;
  std::optional<RgbdRenderer> renderer_;  // points into world_
  bool float_depth_ = false;
  std::uint64_t noise_seed_ = 0;

  ActorContext* ctx_ = nullptr;
  Publisher<msg::RgbdFrame> rgbd_pub_;
  Publisher<msg::GroundTruthPose3D> gt_pub_;
  std::optional<Nanos> first_stamp_;
  std::int64_t next_frame_ = 0;
  RgbdImage image_;

  std::int64_t frames_ = 0;
  double render_ms_total_ = 0, render_ms_max_ = 0, valid_fraction_total_ = 0;
};

}  // namespace tessera::sim
