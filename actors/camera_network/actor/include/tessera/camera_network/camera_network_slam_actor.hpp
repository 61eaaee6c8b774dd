// camera_network_slam actor: the environment cameras as part of the two-level laser SLAM
// (docs/algorithms.md#camera-network-calibration), around CameraConstraintBuilder.
//
// Subscribes:
//   camera_events      msg::CameraEvent       reliable            enter / leave a camera's view
//   camera_detections  msg::MarkerDetection   keep_latest(detection_queue)  marker pixels
//   chained_pose       msg::PoseStamped       keep_latest(pose_queue)  the submap builder's
//                                             robot pose (chained map frame), for pairing
//   constraints        msg::SubmapConstraint  reliable   the builder's hand-overs: where each
//                                             submap starts (other kinds are ignored); one marked
//                                             `lost` (the builder was lost) starts an unanchored
//                                             submap, which the next calibrated camera
//                                             relocalises at once
//   odom               msg::Odometry          keep_latest(odom_queue), with builder.odometry_shape:
//                                             each sighting carries the odometry's pose then, so
//                                             a visit's path is the odometry's placed on the SLAM
//   submaps            msg::Submap            reliable   finished submaps' smoothed trajectories
//                                             (builder.smoothed_poses: visits wait for them)
//   ground_truth       msg::GroundTruthPose   keep_latest(1000), only with score_ground_truth:
//                                             scores revisits and camera localisation
// Publishes:
//   camera_constraints msg::SubmapConstraint  kind revisit, from the submap the robot is in to
//                                             the one the camera was calibrated in (pose of the
//                                             latter's origin in the former's frame), at the end
//                                             of each visit of a calibrated camera
//   camera_calibrations msg::CameraCalibration  reliable: each time a camera is calibrated, or
//                                             calibrated again (the calibration in force then:
//                                             its submap, floor -> pixel homography, quality);
//                                             the map assembler saves them with the map
// Events and detections are paired with the chained pose at their stamp (interpolated) and
// handled in arrival order, so a visit ends after its last sighting. Missed detections
// (detected = false) and non-finite ones are counted and skipped.
//
// Writes (with an output directory, in stop()): calibrations_file (YAML, written atomically and
// read back by readCameraCalibrations, camera_calibration_file.hpp): per calibrated camera its
// submap, floor -> pixel homography (row-major, submap frame), and quality.
//
// Summary: calibrations, calibrations_refused (with the last reason), revisits,
// relocalisations (revisits that placed unanchored submaps, provisional), relocalisations_refined
// (the same visits again on smoothed poses), unanchored_handovers,
// revisits_refused, checks, sightings, sightings_unpaired, with builder.odometry_shape
// sightings_with_odometry, visits_odometry_shaped and odometry_ignored (non-finite poses),
// calibration_rms_px (mean over the calibrations in force); with score_ground_truth also
// revisits_true / revisits_false (against the true relative pose of the two submaps' start poses,
// within truth_tolerance_*), revisit_nees (each scored revisit's error against that truth in its
// covariance's metric, averaged; 3 when consistent) and camera_localisation_rms_m /
// camera_localisation_max_m: every sighting of a calibrated camera localised through its
// homography, against the true marker position in that submap; for detections with corners
// (marker_camera) also camera_heading_rms_rad and camera_pose_nees (the full pose from the corners,
// localizeMarkerPose, against the truth; 3 when consistent).
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/camera_network/camera_constraint_builder.hpp>
#include <tessera/geometry/pose_history.hpp>
#include <tessera/geometry/pose_pairing.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <array>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>

namespace tessera::camera_network {

struct CameraNetworkSlamOptions {
  CameraConstraintBuilderOptions builder;
  std::string calibrations_file = "camera_calibrations.yaml";
  bool score_ground_truth = false;
  double truth_tolerance_linear = 0.3;
  double truth_tolerance_angular = 0.1;
  int detection_queue = 256;
  int pose_queue = 256;
  int pose_history = 512;
  int odom_queue = 512;
  int odom_history = 6000;
  double max_pose_gap_s = 1.0;

  template <class V>
  void visit(V& v) {
    v("builder", builder, "calibration, revisit constraints and the marker's mounting");
    v("calibrations_file", calibrations_file,
      "write the calibrations (YAML) to this file in the output folder; empty = none");
    v("score_ground_truth", score_ground_truth,
      "subscribe to ground_truth and score revisits and camera localisation (simulation)");
    v("truth_tolerance_linear", truth_tolerance_linear,
      "a revisit within this of the truth counts as true [m]");
    v("truth_tolerance_angular", truth_tolerance_angular,
      "a revisit within this of the truth counts as true [rad]");
    v("detection_queue", detection_queue, "detection mailbox size and pairing buffer");
    v("pose_queue", pose_queue, "chained pose mailbox size (keep-latest)");
    v("pose_history", pose_history, "chained poses remembered for pairing");
    v("odom_queue", odom_queue, "odometry mailbox size (keep-latest; builder.odometry_shape)");
    v("odom_history", odom_history, "odometry poses remembered for the sightings");
    v("max_pose_gap_s", max_pose_gap_s, "do not interpolate poses over gaps longer than this [s]");
  }
};

class CameraNetworkSlamActor final : public Actor {
 public:
  /// Throws ConfigError naming the option.
  explicit CameraNetworkSlamActor(CameraNetworkSlamOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const CameraConstraintBuilder& builder() const { return builder_; }

 private:
  struct Item {
    enum class Kind { kEnter, kLeave, kSighting } kind = Kind::kSighting;
    int camera = 0;
    Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
    double pixel_std = 1.0;
    std::optional<std::array<Eigen::Vector2d, 4>> corners;  // when the camera sent them
  };
  void use(const Item& item, std::int64_t stamp, const Pose2& chained);
  void handle(const std::vector<CameraOutput>& outputs);
  void publishRevisit(const CameraOutput& o);
  void publishCalibration(const CameraCalibration& c);
  bool truthAt(std::int64_t stamp, Pose2& out) const;
  void scoreSighting(const CameraSighting& s,
                     const std::optional<std::array<Eigen::Vector2d, 4>>& corners);

  CameraNetworkSlamOptions options_;
  CameraConstraintBuilder builder_;
  PosePairing<std::pair<Item, std::int64_t>> pairing_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::SubmapConstraint> constraint_pub_;
  Publisher<msg::CameraCalibration> calibration_pub_;
  std::map<std::uint32_t, std::int64_t> submap_start_;  // hand-over stamps
  std::map<std::uint32_t, Pose2> start_truth_;          // true pose at each submap's start
  std::map<std::uint32_t, Pose2> chained_origins_;
  // Ground truth for scoring: the last ~2 min at a simulator's 50 Hz (non-finite poses dropped).
  PoseHistory truth_{6000, 1.0};
  PoseHistory odom_;
  std::int64_t last_stamp_ = 0;
  std::int64_t calibrations_ = 0, calibrations_refused_ = 0, revisits_ = 0, revisits_refused_ = 0,
               checks_ = 0, sightings_ = 0, sightings_with_odometry_ = 0, odom_ignored_ = 0,
               misses_ = 0, revisits_true_ = 0, revisits_false_ = 0, revisits_unscored_ = 0,
               relocalisations_ = 0, relocalisations_refined_ = 0, unanchored_handovers_ = 0;
  std::string last_refusal_;
  double loc_sq_ = 0, loc_max_ = 0;
  std::int64_t loc_count_ = 0;
  double heading_sq_ = 0, heading_nees_ = 0, revisit_nees_ = 0;
  std::int64_t heading_count_ = 0, revisit_nees_count_ = 0;
};

}  // namespace tessera::camera_network
