// line_slam actor: line-feature EKF SLAM (docs/algorithms.md#line-ekf-slam). Pairs each laser scan
// with the odometry pose at its stamp, predicts the filter with the odometry increment since the
// previous scan, extracts AIEPF line segments (common/line_extraction.hpp), moves them from the
// laser to base_link with the scan's mounting and updates a LineEkfSlam (line_ekf_slam.hpp).
// The two cores' options are the groups `extractor` and `ekf`.
//
// Subscribes (local names; remap in the profile):
//   scan          msg::LaserScan        keep_latest(scan_queue)
//   odom          msg::Odometry         keep_latest(odom_queue)   base_link in odom
//   ground_truth  msg::GroundTruthPose  keep_latest(odom_queue)   only with ground_truth: true;
//                                                                 used for the summary's errors
// Publishes:
//   pose      msg::PoseStamped  every paired scan: base_link in map, with the filter covariance
//   line_map  msg::LineMap      every map_every updates and once in stop(): the map lines
//
// The map frame is the odometry frame at the first paired scan (in simulation odometry starts at
// the true pose, so map = world). Bad scans (empty, no finite range, non-finite angles) and scans
// that cannot be paired with odometry are counted, never fatal.
#pragma once

#include <tessera/msg/lines.capnp.h>
#include <tessera/geometry/pose_pairing.hpp>
#include <tessera/line_slam/line_ekf_slam.hpp>
#include <tessera/line_slam/line_extraction.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace tessera::line_slam {

struct LineSlamActorOptions {
  tessera::line_slam::LineExtractorOptions extractor;
  LineEkfSlamOptions ekf;
  double min_travel = 0.0;    ///< [m] update after this much travel (0: every scan)
  double min_rotation = 0.0;  ///< [rad] ... or this much rotation
  bool ground_truth = false;
  int map_every = 10;
  std::string frame_id = "map";
  int scan_queue = 64;
  int odom_queue = 256;
  int scan_buffer = 16;
  int pose_history = 512;
  double max_pose_gap_s = 1.0;

  template <class V>
  void visit(V& v) {
    v("extractor", extractor, "line segments from each scan (AIEPF)");
    v("ekf", ekf, "the line EKF: motion and observation noise, association, map upkeep");
    v("min_travel", min_travel, "update the filter after this much travel [m]; 0 = every scan");
    v("min_rotation", min_rotation, "... or after this much rotation [rad]");
    v("ground_truth", ground_truth,
      "subscribe to ground_truth and report the final and largest pose errors");
    v("map_every", map_every, "publish the line map every this many updates (>= 1)");
    v("frame_id", frame_id, "frame of the published pose and line map");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest)");
    v("odom_queue", odom_queue, "odometry / ground-truth mailbox size (keep-latest)");
    v("scan_buffer", scan_buffer, "scans kept waiting for odometry with a later stamp");
    v("pose_history", pose_history, "odometry poses remembered for pairing");
    v("max_pose_gap_s", max_pose_gap_s, "do not interpolate odometry over longer gaps [s]");
  }
  // The extractor's and the filter's keys moved into their groups (the extractor's
  // segment_merge_* lost the prefix they needed beside the filter's merge_*).
  static constexpr RenamedKey kRenamedKeys[] = {
      {"range_sigma", "extractor.range_sigma"},
      {"range_sigma_rel", "extractor.range_sigma_rel"},
      {"breakpoint_distance", "extractor.breakpoint_distance"},
      {"breakpoint_factor", "extractor.breakpoint_factor"},
      {"split_mse", "extractor.split_mse"},
      {"split_max_distance", "extractor.split_max_distance"},
      {"fuzzy_iterations", "extractor.fuzzy_iterations"},
      {"fuzzy_exponent", "extractor.fuzzy_exponent"},
      {"fuzzy_far_distance", "extractor.fuzzy_far_distance"},
      {"min_points", "extractor.min_points"},
      {"min_length", "extractor.min_length"},
      {"segment_merge_angle", "extractor.merge_angle"},
      {"segment_merge_distance", "extractor.merge_distance"},
      {"max_range", "extractor.max_range"},
      {"split_fuzzy", "extractor.split_fuzzy"},
      {"odom_sigma_d", "ekf.odom_sigma_d"},
      {"odom_sigma_theta_per_m", "ekf.odom_sigma_theta_per_m"},
      {"odom_sigma_theta", "ekf.odom_sigma_theta"},
      {"odom_sigma_min", "ekf.odom_sigma_min"},
      {"speed_sigma", "ekf.speed_sigma"},
      {"steering_sigma", "ekf.steering_sigma"},
      {"obs_sigma_r", "ekf.obs_sigma_r"},
      {"obs_sigma_phi", "ekf.obs_sigma_phi"},
      {"association", "ekf.association"},
      {"gate_angle", "ekf.gate_angle"},
      {"gate_distance", "ekf.gate_distance"},
      {"gate_overlap", "ekf.gate_overlap"},
      {"overlap_margin", "ekf.overlap_margin"},
      {"cost_overlap_weight", "ekf.cost_overlap_weight"},
      {"tentative_sightings", "ekf.tentative_sightings"},
      {"min_segment_length", "ekf.min_segment_length"},
      {"merge_interval", "ekf.merge_interval"},
      {"merge_angle", "ekf.merge_angle"},
      {"merge_distance", "ekf.merge_distance"},
      {"merge_gap", "ekf.merge_gap"},
      {"merge_chi2", "ekf.merge_chi2"},
  };
};

class LineSlamActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit LineSlamActor(LineSlamActorOptions options);

  void configure(ActorContext& ctx) override;
  void stop() override;
  /// scans_read/processed/unpaired/rejected, segments, lines, tentative_*, lines_merged, final
  /// pose, and with ground truth final_position_error_m, final_heading_error_deg,
  /// max_position_error_m.
  void summarize(Summary& out) const override;

  const LineEkfSlam& filter() const { return slam_; }

 private:
  void onScan(const Message<msg::LaserScan>& scan);
  void onOdometry(Nanos stamp, const tessera::Pose2& pose);
  void process(const Message<msg::LaserScan>& scan, const tessera::Pose2& odom);
  void publishMap(Nanos stamp);
  void compareWithTruth(Nanos stamp);

  LineSlamActorOptions options_;
  tessera::line_slam::LineExtractor extractor_;
  LineEkfSlam slam_;
  tessera::PosePairing<Message<msg::LaserScan>> pairing_;
  tessera::PoseHistory truth_;
  Publisher<msg::PoseStamped> pose_pub_;
  Publisher<msg::LineMap> map_pub_;

  std::optional<tessera::Pose2> last_odom_;    // odometry at the previous paired scan
  std::optional<tessera::Pose2> update_odom_;  // odometry at the previous filter update
  Nanos last_stamp_ = 0;
  std::uint64_t scans_read_ = 0, scans_rejected_ = 0, scans_paired_ = 0;
  std::uint64_t filter_updates_ = 0, segments_extracted_ = 0, odometry_invalid_ = 0;
  std::uint64_t truth_compared_ = 0;
  double final_position_error_ = -1, final_heading_error_ = -1, max_position_error_ = -1;
};

}  // namespace tessera::line_slam
