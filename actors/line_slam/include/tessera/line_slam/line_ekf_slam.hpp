// LineEkfSlam: EKF SLAM over a planar robot pose and infinite lines
// (docs/algorithms.md#line-ekf-slam, seed 001).
//
// State: [x, y, θ] of base_link in the map frame (m, m, rad), then one (r_i, φ_i) per map line in
// polar form (p·(cos φ, sin φ) = r, r >= 0 [m], φ in (−π, π]); a dense covariance over all of it.
// The map frame is wherever the filter was initialised (normally the first odometry pose).
//
// Motion: differential drive from odometry increments (pose ⊕ Δ, noise proportional to the
// increment), or the paper's car-like model (speed V, steering γ, wheelbase L, step ΔT).
// Observation of line i from the robot: r' = r_i − (x cos φ_i + y sin φ_i), φ' = φ_i − θ, made
// r' >= 0 by turning φ' by π. Observed segments come in the robot (base_link) frame with their
// (r, φ) covariance (see common/line_extraction.hpp).
//
// Association (paper): a map line is a candidate for an observed segment when the angle
// difference, the perpendicular distance of the segment to the line and the overlap ratio of
// the segment with the line's extent pass their gates; of the candidates the lowest weighted
// cost wins (terms weighted by inverse innovation variances). An unmatched segment waits in a
// tentative queue and becomes a map line after `tentative_sightings` consecutive sightings,
// initialised from the pose with P_new = G_x P G_xᵀ + G_z R G_zᵀ. Every `merge_interval` updates,
// pairs of map lines close in angle and distance whose Mahalanobis distance passes a χ² gate are
// fused by an EKF update of the constraint l_i − l_j = 0, and the duplicate is removed.
// `association = threshold` is the paper's "old method": the first candidate within the gates
// wins, and (with tentative_sightings = 1) unmatched segments enter the map at once.
//
// Plain C++ over Eigen, single-threaded; O(n²) per update in the number of lines.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/line_slam/line_extraction.hpp>

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tessera::line_slam {

enum class Association { kCost, kThreshold };
constexpr std::array<std::pair<const char*, Association>, 2> optionNames(Association) {
  return {{{"cost", Association::kCost}, {"threshold", Association::kThreshold}}};
}

struct LineEkfSlamOptions {
  // Odometry (differential drive) noise, std per increment.
  double odom_sigma_d = 0.05;            ///< [m/m] translation std per metre travelled
  double odom_sigma_theta_per_m = 0.02;  ///< [rad/m] heading std per metre travelled
  double odom_sigma_theta = 0.05;        ///< [rad/rad] heading std per radian turned
  double odom_sigma_min = 1e-4;          ///< [m or rad] floor on every std (keeps Q > 0)
  // Car-like model noise.
  double speed_sigma = 0.05;     ///< [m/s] speed std
  double steering_sigma = 0.02;  ///< [rad] steering-angle std
  // Observation noise added to the extractor's covariance (its fit is optimistic about model
  // errors: slightly bent walls, mixed pixels, timing).
  double obs_sigma_r = 0.01;     ///< [m]
  double obs_sigma_phi = 0.005;  ///< [rad]
  // Association gates (paper: 5°, 3 cm, 0.02).
  Association association = Association::kCost;
  double gate_angle = 0.0873;        ///< [rad] largest angle difference
  double gate_distance = 0.1;        ///< [m] largest perpendicular distance (mean over end points)
  double gate_overlap = 0.02;        ///< smallest overlap ratio (overlap length / segment length)
  double overlap_margin = 0.2;       ///< [m] a map line's extent is padded by this for overlap
  double cost_overlap_weight = 1.0;  ///< weight of (1 − overlap)² in the cost
  // New lines.
  int tentative_sightings =
      3;  ///< consecutive sightings before a line enters the map (1 = at once)
  double min_segment_length = 0.3;  ///< [m] shorter observed segments are not used
  // Map maintenance.
  int merge_interval = 2;       ///< updates between merge passes (0 = never)
  double merge_angle = 0.0873;  ///< [rad] candidate pairs: angle difference below this ...
  double merge_distance = 0.1;  ///< [m] ... r difference below this ...
  double merge_gap = 0.3;       ///< [m] ... and extents overlapping or this close
  double merge_chi2 = 9.21;     ///< Mahalanobis gate (χ², 2 dof, 99 %)

  template <class V>
  void visit(V& v) {
    v("odom_sigma_d", odom_sigma_d, "odometry translation std per metre travelled [m/m]");
    v("odom_sigma_theta_per_m", odom_sigma_theta_per_m,
      "odometry heading std per metre travelled [rad/m]");
    v("odom_sigma_theta", odom_sigma_theta, "odometry heading std per radian turned [rad/rad]");
    v("odom_sigma_min", odom_sigma_min, "floor on every odometry std [m or rad]");
    v("speed_sigma", speed_sigma, "car-like model: speed std [m/s]");
    v("steering_sigma", steering_sigma, "car-like model: steering angle std [rad]");
    v("obs_sigma_r", obs_sigma_r, "std added to each observed line's r [m]");
    v("obs_sigma_phi", obs_sigma_phi, "std added to each observed line's phi [rad]");
    v("association", association,
      "'cost': lowest weighted cost among gated candidates (the paper's); 'threshold': first "
      "candidate within the gates (the paper's old method)");
    v("gate_angle", gate_angle, "association: largest angle difference [rad] (paper 5 deg)");
    v("gate_distance", gate_distance,
      "association: largest perpendicular distance of the segment to the line [m] (paper 3 cm)");
    v("gate_overlap", gate_overlap, "association: smallest overlap ratio (paper 0.02)");
    v("overlap_margin", overlap_margin, "map line extents are padded by this for overlap [m]");
    v("cost_overlap_weight", cost_overlap_weight, "cost weight of (1 - overlap)^2");
    v("tentative_sightings", tentative_sightings,
      "consecutive sightings before a new line enters the map (1 = at once)");
    v("min_segment_length", min_segment_length, "shorter observed segments are ignored [m]");
    v("merge_interval", merge_interval, "updates between duplicate-merge passes (0 = never)");
    v("merge_angle", merge_angle, "merge candidates: angle difference below this [rad]");
    v("merge_distance", merge_distance, "merge candidates: r difference below this [m]");
    v("merge_gap", merge_gap, "merge candidates: extents overlap or are this close [m]");
    v("merge_chi2", merge_chi2, "merge gate on the Mahalanobis distance (chi^2, 2 dof)");
  }
};

/// One line of the map.
struct MapLine {
  std::int64_t id = 0;
  double r = 0.0, phi = 0.0;
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
  /// Extent along the line direction (−sin φ, cos φ), measured from the foot point r·n.
  double t_min = 0.0, t_max = 0.0;
  std::int64_t observations = 0;

  Eigen::Vector2d p0() const;
  Eigen::Vector2d p1() const;
};

struct LineEkfSlamStats {
  std::uint64_t updates = 0;             ///< update() calls that used their segments
  std::uint64_t segments = 0;            ///< observed segments given
  std::uint64_t segments_rejected = 0;   ///< non-finite, bad covariance or too short
  std::uint64_t matched = 0;             ///< segments that updated a map line
  std::uint64_t ambiguous = 0;           ///< segments with more than one candidate
  std::uint64_t tentative_created = 0;   ///< new tentative lines
  std::uint64_t tentative_promoted = 0;  ///< tentative lines that entered the map
  std::uint64_t tentative_dropped = 0;   ///< tentative lines not seen again in time
  std::uint64_t lines_added = 0;         ///< map lines ever added
  std::uint64_t lines_merged = 0;        ///< duplicates fused and removed
  std::uint64_t motion_rejected = 0;     ///< non-finite motion inputs
  std::uint64_t update_failures = 0;     ///< singular innovation covariance
};

class LineEkfSlam {
 public:
  /// Throws std::invalid_argument naming the first bad option.
  explicit LineEkfSlam(LineEkfSlamOptions options = {});

  /// Starts (or restarts) at `pose` with covariance `cov` and an empty map.
  void reset(const tessera::Pose2& pose, const Eigen::Matrix3d& cov = Eigen::Matrix3d::Zero());

  /// Differential drive: moves by the odometry increment `delta` (in the robot frame). False
  /// (counted, nothing changed) for a non-finite increment.
  bool predictOdometry(const tessera::Pose2& delta);
  /// The paper's car-like model over dt [s]. False (counted) for non-finite or dt <= 0, L <= 0.
  bool predictCarLike(double speed, double steering, double wheelbase, double dt);

  /// Associates, updates, promotes tentative lines and (every merge_interval calls) merges
  /// duplicates. `segments` are in the robot frame. Returns the number of matched segments.
  int update(const std::vector<tessera::line_slam::LineSegment>& segments);

  tessera::Pose2 pose() const;
  Eigen::Matrix3d poseCovariance() const { return cov_.topLeftCorner<3, 3>(); }
  std::size_t lineCount() const { return lines_.size(); }
  std::size_t tentativeCount() const { return tentative_.size(); }
  /// Map lines with their current estimates (copies out of the state).
  std::vector<MapLine> lines() const;
  const LineEkfSlamStats& stats() const { return stats_; }
  const LineEkfSlamOptions& options() const { return options_; }
  const Eigen::VectorXd& state() const { return state_; }
  const Eigen::MatrixXd& covariance() const { return cov_; }

  /// Predicted observation (robot frame, r >= 0) of map line `i` and its 2x5 Jacobian over
  /// (x, y, θ, r_i, φ_i). Exposed for tests.
  Eigen::Vector2d predict(std::size_t i, Eigen::Matrix<double, 2, 5>* jacobian = nullptr) const;

  /// The candidate map line for a robot-frame segment (-1 = none) and whether more than one
  /// passed the gates. Exposed for tests.
  int associate(const tessera::line_slam::LineSegment& robot_segment,
                bool* ambiguous = nullptr) const;

 private:
  struct LineMeta {
    std::int64_t id;
    double t_min, t_max;
    std::int64_t observations;
  };
  struct Tentative {
    tessera::line_slam::LineSegment world;  // last sighting in the map frame
    int sightings;
    std::uint64_t last_update;
  };
  struct Gates {
    double angle, distance, overlap;
  };

  Gates measure(double r, double phi, double t_min, double t_max,
                const tessera::line_slam::LineSegment& world) const;
  bool passes(const Gates& g) const;
  bool ekfUpdate(std::size_t i, const tessera::line_slam::LineSegment& robot_segment);
  void extend(std::size_t i, const tessera::line_slam::LineSegment& world);
  void addLine(const tessera::line_slam::LineSegment& robot_segment);
  void mergeDuplicates();
  void removeLine(std::size_t i);
  void normalizeLineState(std::size_t i);
  Eigen::Matrix2d observationNoise(const tessera::line_slam::LineSegment& s) const;

  LineEkfSlamOptions options_;
  Eigen::VectorXd state_;
  Eigen::MatrixXd cov_;
  std::vector<LineMeta> lines_;
  std::vector<Tentative> tentative_;
  std::int64_t next_id_ = 0;
  LineEkfSlamStats stats_;
};

}  // namespace tessera::line_slam
