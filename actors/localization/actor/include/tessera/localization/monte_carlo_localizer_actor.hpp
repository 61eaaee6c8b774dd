// monte_carlo_localizer actor: adaptive Monte Carlo localisation on a known occupancy map
// (docs/algorithms.md#monte-carlo-localisation), a thin adapter over MonteCarloLocalizer.
//
// Map: a PGM+YAML file (map_file, ROS map_server format, loaded at construction: a missing or
// malformed file is a ConfigError naming it), or, with map_file empty, the latest OccupancyGrid on
// `map`. A new map there replaces the likelihood field and keeps the particles (same map frame,
// e.g. a SLAM map that grew).
// Subscribes (local names; remap in the profile):
//   scan         msg::LaserScan     keep_latest(scan_queue): each scan is paired with the odometry
//                                   pose at its stamp (interpolated, PoseHistory); beams NaN, below
//                                   rangeMin or at/after the range limit are dropped; the rest,
//                                   moved by the scan's mount into base_link, weigh the particles
//   odom         msg::Odometry      keep_latest(odom_queue): base_link in the odom frame
//   initial_pose msg::PoseStamped   reliable, only with initial_pose_topic (a profile must not
//                                   leave a subscription unpublished): base_link in the map frame
//                                   with its covariance (9 values over x, y, theta; absent:
//                                   initial.sigma_*); restarts the filter there
//   map          msg::OccupancyGrid keep_latest(1), only without map_file
// Publishes (frame map, stamped with the scan's stamp):
//   localized_pose  msg::PoseStamped  after each filter update (and for every paired scan with
//                                     pose_every_scan: the last update moved on by odometry): the
//                                     estimate, with its 3x3 covariance over (x, y, theta)
//   map_to_odom     msg::PoseStamped  after each filter update: the odom frame's pose in the map
//                                     frame, estimate ⊕ odom⁻¹; map pose = map_to_odom ⊕ odom pose
// The filter starts at initial (x, y, theta with sigmas) or, with global: true, uniformly over
// the free cells; an initial_pose message restarts it. Bad input (NaN odometry, scans with bad
// fields or no usable beam, unpairable scans, bad maps or initial poses) is counted by kind and
// skipped; a pose is published only when finite.
#pragma once

#include <tessera/geometry/pose_history.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/localization/monte_carlo_localizer.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::localization {

/// Where the filter starts (map frame) when no initial_pose message has come.
struct InitialPoseOptions {
  double x = 0, y = 0, theta = 0;  ///< [m, m, rad]
  double sigma_xy = 0.25;          ///< [m] standard deviation in x and y
  double sigma_theta = 0.2;        ///< [rad]

  template <class V>
  void visit(V& v) {
    v("x", x, "[m] start x in the map frame");
    v("y", y, "[m] start y in the map frame");
    v("theta", theta, "[rad] start heading in the map frame");
    v("sigma_xy", sigma_xy, "[m] standard deviation of the start in x and y");
    v("sigma_theta", sigma_theta, "[rad] standard deviation of the start heading");
  }
};

struct MonteCarloLocalizerActorOptions {
  MonteCarloOptions mcl;
  std::string map_file;  ///< ROS map YAML; empty: the latest map on the `map` topic
  double range_max = 0;  ///< [m] beams at or beyond are dropped; 0: the scan's rangeMax
  InitialPoseOptions initial;
  bool global = false;  ///< start uniformly over the free cells instead of at `initial`
  bool initial_pose_topic = false;
  bool pose_every_scan = false;
  std::string frame_id = "map";
  int scan_queue = 8;
  int odom_queue = 64;
  int scan_buffer = 16;
  int pose_history = 512;
  double max_pose_gap_s = 0.5;

  template <class V>
  void visit(V& v) {
    v("mcl", mcl, "the filter: particles, KLD, update thresholds, beams, motion and sensor model");
    v("map_file", map_file, "map YAML (ROS map_server format); empty: use the 'map' topic");
    v("range_max", range_max, "[m] beams at or beyond this are dropped; 0: the scan's rangeMax");
    v("initial", initial, "start pose and its spread (without an initial_pose message)");
    v("global", global, "start uniformly over the map's free cells (global localisation)");
    v("initial_pose_topic", initial_pose_topic,
      "subscribe to 'initial_pose' (PoseStamped with covariance) to restart the filter");
    v("pose_every_scan", pose_every_scan,
      "publish localized_pose for every paired scan (last update + odometry), not only updates");
    v("frame_id", frame_id, "frame of the map and of the published poses");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest: older scans are dropped)");
    v("odom_queue", odom_queue, "odometry mailbox size (keep-latest)");
    v("scan_buffer", scan_buffer, "scans kept waiting for an odometry pose with a later stamp");
    v("pose_history", pose_history, "odometry poses remembered for pairing with scans");
    v("max_pose_gap_s", max_pose_gap_s,
      "do not interpolate between odometry poses further apart than this [s]; drop the scan");
  }
};

class MonteCarloLocalizerActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options or a map file that cannot be loaded (naming it).
  explicit MonteCarloLocalizerActor(MonteCarloLocalizerActorOptions options);
  ~MonteCarloLocalizerActor() override;

  void configure(ActorContext& ctx) override;
  void stop() override;
  /// Updates, particles (mean/min/max), ms per update (mean/p95/max), random share, scans by
  /// fate, bad input by kind, the map.
  void summarize(Summary& out) const override;

  /// The filter, once a map and the first scan (for its range) are there.
  const MonteCarloLocalizer* localizer() const { return mcl_.get(); }

 private:
  void onScan(const Message<msg::LaserScan>& scan);
  void onOdom(const Message<msg::Odometry>& m);
  void onInitialPose(const Message<msg::PoseStamped>& m);
  void onMap(const Message<msg::OccupancyGrid>& m);
  /// Handles the scan if its odometry pose is known; false when it must wait for more.
  bool tryScan(const Message<msg::LaserScan>& scan);
  void useMap(grid::OccupancyMap map);
  void startFilter();
  void publish(Nanos stamp, bool updated, const Pose2& odom);
  void bad(const std::string& kind, const std::string& why);

  MonteCarloLocalizerActorOptions options_;
  std::optional<grid::OccupancyMap> map_;  // until the filter exists (it needs a scan's range)
  std::unique_ptr<MonteCarloLocalizer> mcl_;
  /// Start pose and covariance from an initial_pose message (nullopt: the options' start).
  std::optional<std::pair<Pose2, Eigen::Matrix3d>> pending_start_;
  bool start_pending_ = true;
  PoseHistory odom_;
  std::deque<Message<msg::LaserScan>> waiting_;  // scans newer than every odometry pose
  Publisher<msg::PoseStamped> pose_pub_, map_to_odom_pub_;
  std::vector<Eigen::Vector2d> points_;  // reused per scan

  std::uint64_t scans_ = 0, scans_used_ = 0, updates_ = 0, maps_ = 0, initial_poses_ = 0;
  std::uint64_t beams_used_ = 0, beams_dropped_ = 0, poses_published_ = 0;
  std::map<std::string, std::uint64_t> bad_;
  std::vector<double> update_ms_;
  std::uint64_t particles_sum_ = 0;
  std::size_t particles_min_ = 0, particles_max_ = 0;
  double random_share_sum_ = 0, random_share_max_ = 0, inlier_fraction_sum_ = 0;
  std::string map_source_;
};

}  // namespace tessera::localization
