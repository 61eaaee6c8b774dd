// CameraNetworkActor ("camera_network"): the environment camera network of
// docs/algorithms.md#simulated-motion-and-sensors as a sensor actor driven by a simulator's ground
// truth (see camera_network.hpp for the model).
//
// Subscribes (reliable):
//   ground_truth       msg::GroundTruthPose  the true base_link pose in the map frame
// Publishes:
//   camera_events      msg::CameraEvent      the marker entered / left a camera's footprint
//   camera_detections  msg::MarkerDetection  one per camera whose footprint holds the marker,
//                                            per frame; detected = false when missed
//   camera_footprints  msg::CameraFootprints the true cameras' floor footprints (frame id "map",
//                                            calibrated = false; stamp = run clock), at the first
//                                            frame and then every footprint_period_s, so a viewer
//                                            that connects later still gets them
//   camera_images      msg::Image            only with render_images: a camera's rendered image
//                                            ("mono8", camera.width_px x height_px) per frame in
//                                            which the marker is within image_margin_m of that
//                                            camera's footprint (see below)
// Events, detections and images carry the stamp of the ground-truth pose the frame was taken at,
// frame id "camera_<id>" (msg::Image has no camera id: the frame id names the camera); a frame's
// events come before its detections, and its images (cameras in id order) after both. With
// publish_detections = false the geometric events and detections are not advertised at all, so
// that marker_camera actors detecting the marker in camera_images can take those topics over.
//
// Rendered images (render_images, issue 23): each camera's view of the floor texture and the
// robot's ArUco marker (sim/camera_image.hpp: the marker warped by the camera's true homography,
// at the marker position with the robot's heading, then blur and noise; `image` sets marker size,
// id, blur, noise and floor). Rendering costs ~3 ms per camera and frame (the floor is made once
// per camera), so only cameras that can see the marker, or nearly, render: a camera renders a
// frame when the marker is inside its footprint or within image_margin_m of it. The frames in the
// margin show the floor without the marker (or part of it), so a detector following the images
// sees the marker leave and counts its misses; farther away nothing is published (a subscriber
// must not wait for frames of a camera that cannot see the robot). Images draw their noise from
// their own random stream, so the geometric detections do not change with render_images.
//
// Footprint polygons: EnvironmentCamera::footprintPolygon, counter-clockwise seen from above; a
// view reaching past the horizon is cut at kFootprintRange ceiling heights from the site.
//
// Frames: one at the first pose stamped at or after each multiple of 1/camera_hz (with the
// simulator's ground truth at 50 Hz and camera_hz dividing 50 that is exactly every multiple).
// A separate actor rather than options of "simulator", so that the camera network works with any
// pose source (both simulators, a dataset's ground truth) and the simulator stays as it is.
//
// File (in the run's output folder, at start, when named): `cameras_file` lists the true cameras
// (site, tilt, image size and floor -> pixel homography), so calibrations can be scored.
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace tessera::sim {

struct CameraNetworkOptions {
  std::string world = "builtin:camera_floor";
  double world_resolution = 0.05;
  std::vector<std::array<double, 2>> camera_sites;
  int camera_hz = 10;
  CameraIntrinsics camera;
  std::vector<double> marker = {0, 0};
  std::string cameras_file;
  double footprint_period_s = 5.0;
  bool publish_detections = true;
  bool render_images = false;
  CameraImageOptions image;
  double image_margin_m = 1.0;
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("world", world, "world whose camera sites are used ('builtin:camera_floor' has 7)");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("camera_sites", camera_sites,
      "camera floor points [[x, y], ...] [m] (untilted, image u along +x, ids 0, 1, ...); "
      "empty = the world's sites");
    v("camera_hz", camera_hz, "camera frame rate [Hz]");
    v("camera", camera, "what every camera shares: mounting height, optics and noise");
    v("marker", marker, "marker position in base_link [x m, y m]");
    v("cameras_file", cameras_file,
      "write the true cameras to this file in the output folder; empty = none");
    v("footprint_period_s", footprint_period_s,
      "publish camera_footprints at the first frame and then this often (run clock); 0 = only "
      "once [s]");
    v("publish_detections", publish_detections,
      "publish the geometric camera_events and camera_detections; false leaves them to "
      "marker_camera actors reading camera_images");
    v("render_images", render_images,
      "publish each camera's rendered image (floor texture, the robot's ArUco marker, blur and "
      "noise) on camera_images while the marker is in or near its view");
    v("image", image, "rendered images: marker size and id, blur, noise, floor texture");
    v("image_margin_m", image_margin_m,
      "a camera renders while the marker is within this distance of its footprint [m]");
    v("seed", seed, "random seed for noise and misses");
  }

  /// The flat keys of earlier versions, now inside the camera group.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"ceiling_height", "camera.ceiling_height"}, {"focal_px", "camera.focal_px"},
      {"image_width", "camera.width_px"},          {"image_height", "camera.height_px"},
      {"pixel_noise", "camera.pixel_noise"},       {"miss_prob", "camera.miss_probability"},
  };
};

class CameraNetworkActor final : public Actor {
 public:
  /// A footprint that reaches past the horizon is cut this many ceiling heights from its site.
  static constexpr double kFootprintRange = 10.0;

  /// Throws ConfigError naming the option.
  explicit CameraNetworkActor(CameraNetworkOptions options);
  void configure(ActorContext& ctx) override;
  /// Writes cameras_file when named; throws std::runtime_error naming the file.
  void start() override;
  /// camera_count, frames, detections, misses, events, footprint_messages; with render_images
  /// also images (published) and image_render_ms_mean (wall time per rendered image).
  void summarize(Summary& out) const override;

  const CameraNetwork& network() const { return *network_; }

 private:
  void onPose(Nanos stamp, double x, double y, double theta);
  void publishDetections(Nanos stamp, const Pose2& marker);
  void publishImages(Nanos stamp, const Pose2& marker);
  void publishFootprints();

  CameraNetworkOptions options_;
  std::optional<CameraNetwork> network_;
  std::mt19937_64 rng_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::MarkerDetection> detection_pub_;
  Publisher<msg::CameraEvent> event_pub_;
  Publisher<msg::CameraFootprints> footprint_pub_;
  Publisher<msg::Image> image_pub_;
  std::vector<CameraImageRenderer> renderers_;            ///< per camera, with render_images
  std::vector<std::vector<Eigen::Vector2d>> footprints_;  ///< per camera, for image_margin_m
  std::mt19937_64 image_rng_;
  double render_ms_total_ = 0;
  std::int64_t images_ = 0;
  bool footprints_started_ = false;  ///< the first frame has been taken
  Nanos period_ = 0;
  std::optional<Nanos> next_frame_;
  std::int64_t frames_ = 0, detections_ = 0, misses_ = 0, events_ = 0, footprint_messages_ = 0;
};

}  // namespace tessera::sim
