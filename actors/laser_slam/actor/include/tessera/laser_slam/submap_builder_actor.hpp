// rbpf_submap_builder actor: local laser SLAM (docs/algorithms.md#rbpf-submaps). Feeds laser scans
// with the odometry pose at each scan's stamp into an Rbpf (rbpf.hpp) and cuts the map into
// submaps.
//
// Subscribes (local names; remap in the profile):
//   scan           msg::LaserScan    keep_latest(scan_queue)   sweeps with their laser mounting
//   odom           msg::Odometry     keep_latest(odom_queue)   base_link in odom
//   camera_events  msg::CameraEvent  reliable                  only with camera_trigger: entering
//                                                              a camera other than the last one
//                                                              starts a new submap
//   submap_poses   msg::SubmapPoses  keep_latest(1)            only with optimized_poses: where
//                                                              the graph optimiser put the submaps
// Publishes:
//   pose         msg::PoseStamped       every scan: base_link in map (best particle at updates,
//                                       in between scans matched against its map, or odometry
//                                       with track_between_updates false), covariance =
//                                       particle spread. The current submap is placed by
//                                       chaining hand-overs, or with optimized_poses by the
//                                       latest optimised graph: the optimised origin of the
//                                       newest submap it holds, chained from there (the best
//                                       current estimate, which a loop closure moves at once)
//   map_to_odom  msg::PoseStamped       every scan: the correction map ⊕ odom⁻¹
//   chained_pose msg::PoseStamped       every scan: base_link in the chained map frame (as pose
//                                       without optimized_poses; what the loop detector reads)
//   submaps      msg::Submap            reliable consumers: each finished submap, and the last
//                                       one (finished) in stop(), with the smoothed pose of
//                                       every scan in it (submap frame, as final_poses)
//   constraints  msg::SubmapConstraint  at each hand-over: the new submap's origin in the old one
//                                       (when the filter is lost, rbpf.lost_match_fraction: the
//                                       odometry's guess with the lost_sigma_* covariance, so
//                                       later constraints place the new submap)
//   loop_scans   msg::LaserScan         only with loop_scan_every n > 0: every n-th scan that got
//                                       a pose (the same message, zero copy), for a loop detector
//                                       on another host (its every_n_scans then 1): n times fewer
//                                       scan bytes cross than with every scan
//   final_poses  msg::PoseStamped       in stop(): one per scan, the best particle's pose at the
//                                       filter update before it (trajectory tree, submap by
//                                       submap, map frame) moved by the odometry since (with
//                                       track_between_updates, by the scan-matched motion of
//                                       the online pose since): the smoothed estimate (write
//                                       trajectory_final.tum). With
//                                       interpolate_updates, the odometry correction of a scan
//                                       between two updates is blended by time from the first
//                                       update's to the next one's, so the drift found at an
//                                       update is spread over the scans before it (the same for
//                                       the submaps' trajectories).
//
// The map frame is the first submap's frame; later submaps are placed by chaining hand-over
// constraints (the graph optimiser moves them later). submaps, constraints and final_poses stay
// in that chained frame whatever optimized_poses says: the optimiser and the loop detector
// place them themselves. The summary reports how far the optimised graph moved the live pose
// at once (`live_correction_max_m`, the largest jump between two scans), and the memory the
// particles' maps hold in the current submap (`memory_mb` at stop, `memory_peak_mb` the largest
// seen, sampled; MiB, shared tiles once). Scans wait (bounded) for
// an odometry pose at or after their stamp and are paired by interpolation; unpairable scans are
// counted.
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/geometry/pose_pairing.hpp>
#include <tessera/laser_slam/rbpf.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::laser_slam {

struct SubmapBuilderOptions {
  RbpfOptions rbpf;  // the filter, its grids and its scan matcher
  // Submaps.
  double submap_distance = 0.0;  // [m] travelled; 0 = never
  int submap_scans = 0;          // inserted scans; 0 = never
  bool camera_trigger = false;
  bool interpolate_updates = false;
  bool optimized_poses = false;
  int loop_scan_every = 0;
  bool keep_trajectory = true;
  // Plumbing.
  std::string frame_id = "map";
  int scan_queue = 8;
  int odom_queue = 64;
  int scan_buffer = 16;
  int pose_history = 512;
  double max_pose_gap_s = 1.0;

  template <class V>
  void visit(V& v) {
    v("rbpf", rbpf, "particle filter");
    v("submap_distance", submap_distance, "start a new submap after this travel [m]; 0 = never");
    v("submap_scans", submap_scans, "start a new submap after this many inserted scans; 0 = never");
    v("camera_trigger", camera_trigger,
      "subscribe to camera_events: entering a new camera's view starts a new submap");
    v("interpolate_updates", interpolate_updates,
      "smoothed trajectory (final_poses, submap trajectories): blend each scan's odometry "
      "correction between the updates around it instead of holding the earlier one's");
    v("optimized_poses", optimized_poses,
      "subscribe to submap_poses: the live pose and map_to_odom place the current submap by the "
      "latest optimised graph instead of by chained hand-overs");
    v("loop_scan_every", loop_scan_every,
      "republish every n-th scan that got a pose on loop_scans (0 = off): what a loop detector "
      "on another host reads instead of every scan");
    v("keep_trajectory", keep_trajectory,
      "keep every scan's smoothed pose for final_poses at stop; false (lifelong mapping): only "
      "the last submap's, so nothing grows with the length of the run");
    v("frame_id", frame_id, "global frame of the published poses");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest)");
    v("odom_queue", odom_queue, "odometry mailbox size (keep-latest)");
    v("scan_buffer", scan_buffer, "scans kept waiting for odometry with a later stamp");
    v("pose_history", pose_history, "odometry poses remembered for pairing");
    v("max_pose_gap_s", max_pose_gap_s,
      "do not interpolate odometry over gaps longer than this [s]");
  }

  /// The flat keys of earlier versions, now inside the rbpf group.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"particles", "rbpf.particles"},
      {"resample_threshold", "rbpf.resample_threshold"},
      {"weight_divisor", "rbpf.weight_divisor"},
      {"linear_update", "rbpf.linear_update"},
      {"angular_update", "rbpf.angular_update"},
      {"temporal_update", "rbpf.temporal_update"},
      {"srr", "rbpf.motion.srr"},
      {"srt", "rbpf.motion.srt"},
      {"str", "rbpf.motion.str"},
      {"stt", "rbpf.motion.stt"},
      {"seed", "rbpf.seed"},
      {"parallel", "rbpf.parallel"},
      {"sample_proposal", "rbpf.sample_proposal"},
      {"resolution", "rbpf.grid.resolution"},
      {"hit_points", "rbpf.grid.track_hit_points"},
      {"l_occ", "rbpf.grid.log_odds.hit"},
      {"l_free", "rbpf.grid.log_odds.miss"},
      {"l_min", "rbpf.grid.log_odds.min"},
      {"l_max", "rbpf.grid.log_odds.max"},
      {"max_range", "rbpf.insert.max_range and rbpf.matcher.max_range"},
      {"max_free_range", "rbpf.insert.max_free_range"},
      {"match_beam_step", "rbpf.matcher.beam_step"},
      {"match_kernel_radius", "rbpf.matcher.kernel_radius"},
      {"coarse_kernel_radius", "rbpf.coarse_kernel_radius"},
      {"coarse_beam_step", "rbpf.coarse_beam_step"},
      {"recovery_sigma", "rbpf.recovery_sigma"},
      {"recovery_angular_step", "rbpf.recovery_angular_step"},
      {"min_overlap_fraction", "rbpf.min_overlap_fraction"},
      {"best_support_linear", "rbpf.best_support_linear"},
      {"best_support_angular", "rbpf.best_support_angular"},
      {"online_mean_linear", "rbpf.online_mean_linear"},
      {"online_mean_angular", "rbpf.online_mean_angular"},
      {"track_between_updates", "rbpf.track_between_updates"},
      {"track_linear_step", "rbpf.track_linear_step"},
      {"track_angular_step", "rbpf.track_angular_step"},
      {"track_refinements", "rbpf.track_refinements"},
      {"match_sigma", "rbpf.matcher.sigma"},
      {"match_likelihood_sigma", "rbpf.matcher.likelihood_sigma"},
      {"match_likelihood_gain", "rbpf.matcher.likelihood_gain"},
      {"match_linear_step", "rbpf.matcher.linear_step"},
      {"match_angular_step", "rbpf.matcher.angular_step"},
      {"match_refinements", "rbpf.matcher.refinements"},
      {"match_min_fraction", "rbpf.matcher.min_score_fraction"},
      {"match_no_hit_distance", "rbpf.matcher.no_hit_distance"},
      {"match_proposal_linear", "rbpf.matcher.proposal_linear"},
      {"match_proposal_angular", "rbpf.matcher.proposal_angular"},
      {"handover_sigma_linear", "rbpf.handover_sigma_linear"},
      {"handover_sigma_angular", "rbpf.handover_sigma_angular"},
  };
};

class SubmapBuilderActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit SubmapBuilderActor(SubmapBuilderOptions options);

  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const Rbpf& filter() const { return rbpf_; }

 private:
  void onScan(const Message<msg::LaserScan>& scan);
  void onOdometry(Nanos stamp, const tessera::Pose2& pose);
  void onCameraEvent(const Message<msg::CameraEvent>& event);
  void onSubmapPoses(const Message<msg::SubmapPoses>& poses);
  /// The current submap's origin in the published map frame: chained, or moved with the
  /// newest optimised submap (optimized_poses).
  tessera::Pose2 liveOrigin() const;
  /// Runs a scan, paired with the odometry pose at its stamp, through the filter.
  void process(const Message<msg::LaserScan>& scan, const tessera::Pose2& odom);
  void publishPose(Nanos stamp, const tessera::Pose2& odometry);
  /// lost: the filter lost the map (RbpfStep::lost); the new submap is unanchored.
  void handOver(Nanos stamp, bool lost = false);
  /// A smoothed scan pose, stamped exactly as its scan (the filter's stamps are seconds in a
  /// double, ~0.1 µs off at epoch times, so they only find the scan).
  struct ScanPose {
    Nanos stamp;
    tessera::Pose2 pose;
  };
  /// `trajectory`: the submap's smoothed scan poses, in its own frame.
  void publishSubmap(const FinishedSubmap& submap, Nanos stamp,
                     const std::vector<ScanPose>& trajectory);
  /// Every scan from the first of `updates` on, moved from the update before it.
  std::vector<ScanPose> densify(const std::vector<Rbpf::StampedPose>& updates) const;
  void appendBestTrajectory(std::vector<Rbpf::StampedPose>& out) const;

  SubmapBuilderOptions options_;
  Rbpf rbpf_;
  tessera::PosePairing<Message<msg::LaserScan>> pairing_;
  Publisher<msg::PoseStamped> pose_pub_, correction_pub_, chained_pub_;
  Publisher<msg::Submap> submap_pub_;
  Publisher<msg::SubmapConstraint> constraint_pub_;
  Publisher<msg::PoseStamped> final_pub_;
  Publisher<msg::LaserScan> loop_scan_pub_;
  std::uint64_t loop_scan_count_ = 0;
  std::vector<Rbpf::StampedPose> finished_trajectory_;  // best trajectories of closed submaps
  // Each scan's motion chain: odometry, or with tracking the online pose's scan-matched
  // motion between updates (densify() moves the smoothed update poses by it)
  struct ScanMotion {
    Nanos stamp;  // the scan's own; the filter was given nanosToSeconds(stamp)
    tessera::Pose2 motion;
    double seconds() const { return nanosToSeconds(stamp); }
  };
  std::vector<ScanMotion> scan_odometry_;
  tessera::Pose2 scan_motion_, last_odom_, last_online_;

  tessera::Pose2 submap_origin_;  // current submap's origin in the map frame
  // optimized_poses: the chained origin of every submap so far (index = id), and the latest
  // optimised graph's newest submap with its optimised origin.
  std::vector<tessera::Pose2> chained_origins_{tessera::Pose2()};
  int optimized_id_ = -1;
  tessera::Pose2 optimized_origin_;
  tessera::Pose2 last_live_origin_;
  int last_live_submap_ = -1;
  double live_correction_max_m_ = 0.0;
  std::uint64_t graph_updates_ = 0, live_corrections_ = 0;
  Nanos last_stamp_ = 0;
  int last_camera_ = -1;
  bool handover_requested_ = false;
  std::uint64_t scans_read_ = 0, odometry_invalid_ = 0;
  std::uint64_t submaps_published_ = 0, camera_handovers_ = 0;
};

}  // namespace tessera::laser_slam
