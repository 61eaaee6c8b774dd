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
// Publishes:
//   pose         msg::PoseStamped       every scan: base_link in map (best particle at updates,
//                                       in between scans matched against its map, or odometry
//                                       with track_between_updates false), covariance =
//                                       particle spread
//   map_to_odom  msg::PoseStamped       every scan: the correction map ⊕ odom⁻¹
//   submaps      msg::Submap            reliable consumers: each finished submap, and the last
//                                       one (finished) in stop(), with the smoothed pose of
//                                       every scan in it (submap frame, as final_poses)
//   constraints  msg::SubmapConstraint  at each hand-over: the new submap's origin in the old one
//   final_poses  msg::PoseStamped       in stop(): one per scan, the best particle's pose at the
//                                       filter update before it (trajectory tree, submap by
//                                       submap, map frame) moved by the odometry since: the
//                                       smoothed estimate (write trajectory_final.tum). With
//                                       interpolate_updates, the odometry correction of a scan
//                                       between two updates is blended by time from the first
//                                       update's to the next one's, so the drift found at an
//                                       update is spread over the scans before it (the same for
//                                       the submaps' trajectories).
//
// The map frame is the first submap's frame; later submaps are placed by chaining hand-over
// constraints (the graph optimiser moves them later). Scans wait (bounded) for an odometry pose
// at or after their stamp and are paired by interpolation; unpairable scans are counted.
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/geometry/pose_pairing.hpp>
#include <tessera/laser_slam/rbpf.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::laser_slam {

struct SubmapBuilderOptions {
  // Filter (see RbpfOptions).
  int particles = 30;
  double resample_threshold = 0.5;
  double weight_divisor = 0.0;
  double linear_update = 1.0;
  double angular_update = 0.5;
  double temporal_update = 0.0;
  double srr = 0.1, srt = 0.2, str = 0.1, stt = 0.2;
  std::uint64_t seed = 1;
  bool parallel = true;
  bool sample_proposal = true;
  // Grid.
  double resolution = 0.05;
  bool hit_points = false;
  // A weaker miss than the known-pose mapper's: a wall cell crossed by grazing beams keeps its
  // evidence, so scan matching still finds it (GMapping counts a cell hit by 10 % of its beams).
  double l_occ = 0.85, l_free = -0.2, l_min = -2.0, l_max = 3.5;
  double max_range = 30.0;
  double max_free_range = 10.0;
  // Scan matcher (see ScanMatcherOptions).
  int match_beam_step = 1;
  int match_kernel_radius = 1;
  int coarse_kernel_radius = 4;
  int coarse_beam_step = 4;
  double recovery_sigma = 2.0;
  double recovery_angular_step = 0.05;
  double min_overlap_fraction = 0.0;
  double best_support_linear = 0.0, best_support_angular = 0.0;
  double online_mean_linear = 0.0, online_mean_angular = 0.0;
  bool track_between_updates = true;
  double track_linear_step = 0.0, track_angular_step = 0.0;
  int track_refinements = 0;
  double match_sigma = 0.05;
  double match_likelihood_sigma = 0.075;
  double match_likelihood_gain = 3.0;
  double match_linear_step = 0.05;
  double match_angular_step = 0.05;
  int match_refinements = 5;
  double match_min_fraction = 0.1;
  double match_no_hit_distance = 0.27;
  double match_proposal_linear = 0.02;
  double match_proposal_angular = 0.01;
  // Submaps.
  double submap_distance = 0.0;  // [m] travelled; 0 = never
  double handover_sigma_linear = 0.02, handover_sigma_angular = 0.005;
  int submap_scans = 0;  // inserted scans; 0 = never
  bool camera_trigger = false;
  bool interpolate_updates = false;
  // Plumbing.
  std::string frame_id = "map";
  int scan_queue = 8;
  int odom_queue = 64;
  int scan_buffer = 16;
  int pose_history = 512;
  double max_pose_gap_s = 1.0;

  template <class V>
  void visit(V& v) {
    v("particles", particles, "particles per submap");
    v("resample_threshold", resample_threshold,
      "resample when N_eff < this fraction of the particle count (0..1]");
    v("weight_divisor", weight_divisor,
      "log-weight increments are divided by this (0 = the particle count, as GMapping)");
    v("linear_update", linear_update, "filter update after this much travel [m]");
    v("angular_update", angular_update, "filter update after this much rotation [rad]");
    v("temporal_update", temporal_update, "filter update after this much time [s]; 0 disables");
    v("srr", srr, "odometry noise: translation per metre travelled [m/m]");
    v("srt", srt, "odometry noise: translation per radian turned [m/rad]");
    v("str", str, "odometry noise: rotation per metre travelled [rad/m]");
    v("stt", stt, "odometry noise: rotation per radian turned [rad/rad]");
    v("seed", seed, "random seed (runs are reproducible for a seed)");
    v("parallel", parallel, "update particles on TBB worker threads");
    v("sample_proposal", sample_proposal,
      "draw poses from the fitted proposal (true) or keep its mean (false)");
    v("resolution", resolution, "submap cell size [m]");
    v("hit_points", hit_points,
      "keep each cell's mean hit position and match against it (sub-cell accuracy, 2.5x tile "
      "memory)");
    v("l_occ", l_occ, "log-odds added at a beam endpoint (> 0)");
    v("l_free", l_free, "log-odds added along a beam (< 0)");
    v("l_min", l_min, "lower log-odds clamp (< 0)");
    v("l_max", l_max, "upper log-odds clamp (> 0)");
    v("max_range", max_range,
      "returns beyond this [m] are used neither for matching nor as obstacles");
    v("max_free_range", max_free_range,
      "no-return beams clear free space this far [m]; 0 disables");
    v("match_beam_step", match_beam_step, "scan matching uses every n-th valid beam");
    v("match_kernel_radius", match_kernel_radius, "cells searched around each beam endpoint");
    v("coarse_kernel_radius", coarse_kernel_radius,
      "coarse matching stage: cells searched around each endpoint (wider basin); 0 disables");
    v("coarse_beam_step", coarse_beam_step, "coarse matching stage uses every n-th beam");
    v("recovery_sigma", recovery_sigma,
      "when matching from the odometry prior fails, retry the coarse stage from starts within "
      "this many prior standard deviations; 0 disables");
    v("recovery_angular_step", recovery_angular_step,
      "heading spacing of the recovery search's starts [rad]");
    v("min_overlap_fraction", min_overlap_fraction,
      "a match with fewer than this fraction of the scan's beams on the map is not trusted: "
      "the particle follows the motion model; 0 disables");
    v("best_support_linear", best_support_linear,
      "best particle = most posterior weight within a Gaussian kernel of this width [m] around "
      "its pose; 0: highest accumulated weight alone");
    v("best_support_angular", best_support_angular,
      "angular width of that kernel [rad]; 0: highest accumulated weight alone");
    v("online_mean_linear", online_mean_linear,
      "online pose at updates = weighted mean of the particles within a Gaussian kernel of this "
      "width [m] around the best particle; 0: the best particle's pose");
    v("online_mean_angular", online_mean_angular,
      "angular width of that kernel [rad]; 0: the best particle's pose");
    v("track_between_updates", track_between_updates,
      "between filter updates, match each scan against the best particle's map so the online "
      "pose follows the scans rather than the odometry");
    v("track_linear_step", track_linear_step,
      "tracking's initial hill-climbing step [m]; 0: the fine matcher's");
    v("track_angular_step", track_angular_step,
      "tracking's initial hill-climbing step [rad]; 0: the fine matcher's");
    v("track_refinements", track_refinements,
      "tracking's step halvings before it stops; 0: the fine matcher's");
    v("match_sigma", match_sigma, "score kernel width [m]");
    v("match_likelihood_sigma", match_likelihood_sigma, "likelihood kernel width [m]");
    v("match_likelihood_gain", match_likelihood_gain,
      "log-likelihood divided by this (flattens overconfident weights)");
    v("match_linear_step", match_linear_step, "initial hill-climbing step [m]");
    v("match_angular_step", match_angular_step, "initial hill-climbing step [rad]");
    v("match_refinements", match_refinements, "hill-climbing step halvings");
    v("match_no_hit_distance", match_no_hit_distance,
      "[m] a beam with no obstacle within the kernel costs as much in the likelihood as one "
      "whose obstacle is this far away (0 = the kernel's reach): makes particles whose map "
      "disagrees with the scan lose weight");
    v("match_proposal_linear", match_proposal_linear,
      "[m] proposal fit: spacing of the pose samples in x and y around the matched pose");
    v("match_proposal_angular", match_proposal_angular,
      "[rad] proposal fit: spacing of the pose samples in heading around the matched pose");
    v("match_min_fraction", match_min_fraction,
      "a match succeeds when at least this fraction of the beams lands near an obstacle; "
      "otherwise the particle follows odometry");
    v("submap_distance", submap_distance, "start a new submap after this travel [m]; 0 = never");
    v("submap_scans", submap_scans, "start a new submap after this many inserted scans; 0 = never");
    v("handover_sigma_linear", handover_sigma_linear,
      "[m/sqrt(m)] hand-over covariance floor: variance += sigma^2 x metres travelled in the "
      "submap (x, y)");
    v("handover_sigma_angular", handover_sigma_angular, "[rad/sqrt(m)] the same for the heading");
    v("camera_trigger", camera_trigger,
      "subscribe to camera_events: entering a new camera's view starts a new submap");
    v("interpolate_updates", interpolate_updates,
      "smoothed trajectory (final_poses, submap trajectories): blend each scan's odometry "
      "correction between the updates around it instead of holding the earlier one's");
    v("frame_id", frame_id, "global frame of the published poses");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest)");
    v("odom_queue", odom_queue, "odometry mailbox size (keep-latest)");
    v("scan_buffer", scan_buffer, "scans kept waiting for odometry with a later stamp");
    v("pose_history", pose_history, "odometry poses remembered for pairing");
    v("max_pose_gap_s", max_pose_gap_s,
      "do not interpolate odometry over gaps longer than this [s]");
  }

  /// The filter options these parameters describe.
  RbpfOptions rbpf() const;
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
  /// Runs a scan, paired with the odometry pose at its stamp, through the filter.
  void process(const Message<msg::LaserScan>& scan, const tessera::Pose2& odom);
  void publishPose(Nanos stamp, const tessera::Pose2& odometry);
  void handOver(Nanos stamp);
  /// `trajectory`: the submap's smoothed scan poses, in its own frame.
  void publishSubmap(const FinishedSubmap& submap, Nanos stamp,
                     const std::vector<Rbpf::StampedPose>& trajectory);
  /// The current submap's best trajectory, in the map frame, after `out`'s last stamp.
  std::vector<Rbpf::StampedPose> densify(const std::vector<Rbpf::StampedPose>& updates) const;
  void appendBestTrajectory(std::vector<Rbpf::StampedPose>& out) const;

  SubmapBuilderOptions options_;
  Rbpf rbpf_;
  tessera::PosePairing<Message<msg::LaserScan>> pairing_;
  Publisher<msg::PoseStamped> pose_pub_, correction_pub_;
  Publisher<msg::Submap> submap_pub_;
  Publisher<msg::SubmapConstraint> constraint_pub_;
  Publisher<msg::PoseStamped> final_pub_;
  std::vector<Rbpf::StampedPose> finished_trajectory_;  // best trajectories of closed submaps
  std::vector<std::pair<double, tessera::Pose2>> scan_odometry_;  // [s], odometry of each scan

  tessera::Pose2 submap_origin_;  // current submap's origin in the map frame
  Nanos last_stamp_ = 0;
  int last_camera_ = -1;
  bool handover_requested_ = false;
  std::uint64_t scans_read_ = 0, odometry_invalid_ = 0;
  std::uint64_t submaps_published_ = 0, camera_handovers_ = 0;
};

}  // namespace tessera::laser_slam
