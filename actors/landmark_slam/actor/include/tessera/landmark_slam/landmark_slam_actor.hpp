// landmark_slam actor: point-landmark SLAM (docs/algorithms.md#landmark-slam) from drive controls
// and range-bearing scans, with the EKF-SLAM baseline (filter: ekf) or the seed 004
// Rao-Blackwellised UKF/EKF filter (filter: rbekf). The filters are LandmarkFilter cores; their
// options (LandmarkSlamOptions) are the group `estimator`.
//
// Subscribes (reliable; local names):
//   control         msg::DriveControl   speed + steering (car-like) or turn rate (wheelbase 0)
//                                       over [stamp, stamp + dtS); dtS = 0: until the next one
//   landmarks       msg::LandmarkScan   observations at the stamp, sensor mount in the message
//   ground_truth    msg::GroundTruthPose  only with `ground_truth: true`: ATE in the summary
//   landmark_truth  msg::LandmarkMap    only with `landmark_truth: true`: landmark error (ids
//                                       matched, rigid alignment) in the summary
// Publishes:
//   pose               msg::PoseStamped  frame map, with the 3x3 pose covariance, after every
//                                        scan (the filtered estimate at the scan's stamp)
//   landmark_estimate  msg::LandmarkMap  frame map, with 2x2 covariances: every
//                                        `landmark_publish_every` scans and at stop()
// Files (with an output folder and svg_file set): a drawing of the run (trajectory, landmark
// estimates with 2-sigma ellipses, true landmarks and ground truth when subscribed).
//
// Time: the filter state has a time. A control is applied when a message with a later stamp
// arrives (so a scan at t is used before the control starting at t, whichever mailbox is
// handled first); a scan at t first applies every control up to t. A scan older than the state
// is still used, at the current pose, and counted (late_scans).
#pragma once

#include <tessera/msg/landmark.capnp.h>
#include <tessera/geometry/pose2.hpp>
#include <tessera/landmark_slam/landmark_filter.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <deque>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace tessera::landmark_slam {

struct LandmarkSlamActorOptions {
  FilterType filter = FilterType::kRbEkf;
  LandmarkSlamOptions estimator;  // noise, association, gates, start pose: the filter's own
  int landmark_publish_every = 0;
  bool ground_truth = false;
  bool landmark_truth = false;
  std::string frame_id = "map";
  std::string svg_file;

  template <class V>
  void visit(V& v) {
    v("filter", filter, "joint EKF-SLAM or the seed 004 filter (UKF pose + 2x2 EKFs)");
    v("estimator", estimator, "the filter's noise, data association and start pose");
    v("landmark_publish_every", landmark_publish_every,
      "publish the landmark estimate every this many scans (0 = only at the end)");
    v("ground_truth", ground_truth, "subscribe ground_truth and report ATE in the summary");
    v("landmark_truth", landmark_truth,
      "subscribe landmark_truth and report the landmark error in the summary");
    v("frame_id", frame_id, "frame of the published pose and landmarks");
    v("svg_file", svg_file,
      "with --out: draw the trajectory, landmark estimates (2-sigma ellipses) and any true "
      "landmarks into this SVG file at the end (\"\" = none)");
  }
  // The filter's keys moved into `estimator`; the angles there are in radians.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"association", "estimator.association"},
      {"range_std", "estimator.range_std"},
      {"bearing_std_deg", "estimator.bearing_std"},
      {"use_observation_std", "estimator.use_observation_std"},
      {"sigma_speed", "estimator.sigma_speed"},
      {"sigma_steer_deg", "estimator.sigma_steer"},
      {"sigma_turn_rate_deg", "estimator.sigma_turn_rate"},
      {"outlier_gate", "estimator.outlier_gate"},
      {"association_gate", "estimator.association_gate"},
      {"new_landmark_gate", "estimator.new_landmark_gate"},
      {"ambiguity_margin", "estimator.ambiguity_margin"},
      {"initial_pose", "estimator.initial_pose"},
      {"initial_std", "estimator.initial_std"},
  };
};

class LandmarkSlamActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit LandmarkSlamActor(LandmarkSlamActorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  /// filter, association, scans, controls, observations, corrections, landmarks,
  /// rejected_<reason> (non_finite, negative_range, unknown_id, gate, ambiguous, between_gates,
  /// duplicate, bad_control, bad_mount_scans), late_scans, filter_errors, mean_nis, nis_count,
  /// update_us_mean (per scan: observe + update + augment), predict_us_mean, final_x/y/theta;
  /// with truth: ate_rmse_m, ate_max_m, ate_pairs, landmark_rmse_m, landmark_mean_m,
  /// landmark_max_m, landmark_pairs.
  void summarize(Summary& out) const override;

  const LandmarkFilter& filter() const { return *filter_; }

 private:
  struct PendingControl {
    Nanos start = 0, end = -1;  // end < 0: until the next control
    tessera::landmark_slam::DriveInput input;
  };
  void onControl(const Message<msg::DriveControl>& m);
  void onScan(const Message<msg::LandmarkScan>& m);
  void advanceTo(Nanos t);
  void predictFor(const tessera::landmark_slam::DriveInput& u, Nanos dt);
  void publishPose(Nanos stamp);
  void publishLandmarks(Nanos stamp);
  void writeSvg(const std::string& path) const;
  void noteFilterError(const std::exception& e);

  LandmarkSlamActorOptions options_;
  std::unique_ptr<LandmarkFilter> filter_;
  Publisher<msg::PoseStamped> pose_pub_;
  Publisher<msg::LandmarkMap> map_pub_;
  std::deque<PendingControl> pending_;
  Nanos state_time_ = 0;
  bool have_time_ = false;
  Nanos last_stamp_ = 0;

  std::vector<std::pair<std::int64_t, tessera::Pose2>> estimate_, truth_;
  std::vector<std::pair<int, Eigen::Vector2d>> landmark_truth_;
  ActorContext* ctx_ = nullptr;
  std::string svg_error_;

  std::uint64_t scans_ = 0, controls_ = 0, observations_ = 0, corrections_ = 0, late_scans_ = 0;
  std::uint64_t predicts_ = 0, bad_controls_ = 0, bad_mounts_ = 0, filter_errors_ = 0;
  double update_s_ = 0, predict_s_ = 0;
};

}  // namespace tessera::landmark_slam
