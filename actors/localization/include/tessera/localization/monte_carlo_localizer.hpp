// MonteCarloLocalizer: adaptive Monte Carlo localisation on an occupancy map
// (docs/algorithms.md#monte-carlo-localisation).
//
// Particles (map-frame poses) move by the odometry increment since the last filter update through
// the odometry motion model (rotation, translation, rotation, each with noise from alpha1..4),
// are weighted by the likelihood field (TBB over particles), and are resampled with KLD-adaptive
// size: as many as the number k of occupied histogram bins needs for the KLD bound
//   n = (k − 1) / (2ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1))) · z)³,
// between min_particles and max_particles. Updates happen only after the robot moved update_min_d
// or turned update_min_a (or when forced). When the short-term average fit (of the best particle)
// drops below the long-term one (w_fast < w_slow), a fraction 1 − w_fast / w_slow of the resampled
// particles is drawn uniformly over free space instead (augmented MCL): that recovers a kidnapped
// robot. Separately, when the best particle leaves most beams away from any obstacle for several
// updates (lost_inlier_fraction), the particles are spread over the map again. The estimate is
// the weighted mean and covariance of the heaviest cluster of adjacent bins.
//
// Owns its particles and a copy of the likelihood field's map; one thread calls it.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/localization/likelihood_field.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <optional>
#include <random>
#include <span>
#include <vector>

namespace tessera::localization {

/// The odometry motion model's noise (Probabilistic Robotics' alpha1..4, as AMCL's odom_alpha1..4).
struct MotionNoise {
  double alpha1 = 0.2;  ///< rotation noise from rotation
  double alpha2 = 0.2;  ///< rotation noise from translation [rad/m]
  double alpha3 = 0.2;  ///< translation noise from translation
  double alpha4 = 0.2;  ///< translation noise from rotation [m/rad]

  template <class V>
  void visit(V& v) {
    v("alpha1", alpha1, "rotation noise from rotation");
    v("alpha2", alpha2, "rotation noise from translation");
    v("alpha3", alpha3, "translation noise from translation");
    v("alpha4", alpha4, "translation noise from rotation");
  }
};

struct MonteCarloOptions {
  int min_particles = 500;
  int max_particles = 2000;
  double kld_error = 0.01;             ///< ε: bound on the KL divergence of the sample set
  double kld_z = 2.326;                ///< upper standard normal quantile 1 − δ (δ = 0.01)
  double bin_xy = 0.5;                 ///< [m] histogram bin for KLD and clustering
  double bin_theta = 0.1745;           ///< [rad] (10°)
  double update_min_d = 0.2;           ///< [m] translation between filter updates
  double update_min_a = 0.5236;        ///< [rad] rotation between filter updates (30°)
  int max_beams = 60;                  ///< beams used per update, evenly spread
  double recovery_alpha_slow = 0.001;  ///< long-term fit average rate (0 disables recovery)
  double recovery_alpha_fast = 0.1;    ///< short-term fit average rate
  /// Particles of a uniform (global) start; 0: max_particles. Resampling keeps at most
  /// max(max_particles, what tempering needs), see min_ess.
  int global_particles = 0;
  /// Adaptive tempering of a global start: while the set is larger than max_particles and the
  /// scan's likelihoods would leave fewer than min_ess × N effective particles, they are raised
  /// to the power β < 1 that leaves that many, so the set keeps its plausible hypotheses instead
  /// of collapsing onto the first lucky particle; the KLD bound then shrinks it as it converges.
  /// 0: off (plain Bayes).
  double min_ess = 0;
  /// Relocalisation (0: off): when fewer than this share of the best particle's beams end within
  /// inlier_distance of an obstacle for lost_updates filter updates in a row, the robot is taken
  /// to be lost (kidnapped, or the track slipped) and the particles are spread over the free
  /// space again as a global start (global_particles, tempered by min_ess). Unlike the
  /// random-particle recovery it does not react to a passing person or clutter: those leave
  /// most beams on the walls.
  double lost_inlier_fraction = 0;
  double inlier_distance = 0.2;  ///< [m]
  int lost_updates = 5;
  /// Scan-matched estimate (refine_step 0: off). After each weighted update the estimate (the
  /// heaviest cluster's mean) is moved to the nearby pose where every finite beam of the scan
  /// fits the likelihood field best: hill climbing in x, y (refine_step) and heading
  /// (refine_step / 2 rad per metre of step), halving the steps four times. A move further than
  /// refine_max_shift from the mean is not taken (the mean stays the estimate). The particles
  /// follow the estimate by the same shift (refine_particles), so odometry slip the motion noise
  /// did not cover is corrected where the scan pins the pose down; the cloud's spread is kept.
  double refine_step = 0;         ///< [m] first hill-climbing step; 0: off
  double refine_max_shift = 0.3;  ///< [m] larger corrections are refused
  bool refine_particles = true;
  MotionNoise motion;
  LikelihoodFieldOptions field;
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("min_particles", min_particles, "particles kept at least");
    v("max_particles", max_particles, "particles at most");
    v("kld_error", kld_error, "KLD bound epsilon");
    v("kld_z", kld_z, "upper standard normal quantile of the KLD bound");
    v("bin_xy", bin_xy, "[m] histogram bin size in x and y");
    v("bin_theta", bin_theta, "[rad] histogram bin size in heading");
    v("update_min_d", update_min_d, "[m] translation between filter updates");
    v("update_min_a", update_min_a, "[rad] rotation between filter updates");
    v("max_beams", max_beams, "beams used per update");
    v("recovery_alpha_slow", recovery_alpha_slow, "long-term fit average rate (0: no recovery)");
    v("recovery_alpha_fast", recovery_alpha_fast, "short-term fit average rate");
    v("global_particles", global_particles,
      "particles of a uniform (global) start; 0: max_particles");
    v("min_ess", min_ess,
      "temper the scan likelihood so at least this share of particles stays effective; 0: off");
    v("lost_inlier_fraction", lost_inlier_fraction,
      "relocalise globally when fewer beams than this share end near an obstacle; 0: off");
    v("inlier_distance", inlier_distance, "[m] a beam ending this close to an obstacle fits");
    v("lost_updates", lost_updates,
      "updates in a row below lost_inlier_fraction before relocalising");
    v("refine_step", refine_step,
      "[m] first step of the scan-matched refinement of the estimate; 0: off");
    v("refine_max_shift", refine_max_shift, "[m] larger refinements are refused");
    v("refine_particles", refine_particles, "shift the particles by the refinement too");
    v("motion", motion, "odometry motion model noise");
    v("field", field, "likelihood-field sensor model");
    v("seed", seed, "random seed");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

struct Particle {
  Pose2 pose;
  double weight = 0;  ///< normalised
};

struct PoseEstimate {
  Pose2 pose;  ///< map frame, at the last filter update
  /// The odometry pose of that update: the robot's map pose now is pose ⊕ (odom⁻¹ ⊕ odom_now),
  /// and map→odom is pose ⊕ odom⁻¹.
  Pose2 odom;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< over (x, y, theta)
  double cluster_weight = 0;  ///< share of the weight in the chosen cluster
  int clusters = 0;
};

/// The KLD bound for k occupied bins (at least 1 sample).
int kldSampleCount(int k, double epsilon, double z);

class MonteCarloLocalizer {
 public:
  /// Throws std::invalid_argument for bad options or a map the likelihood field refuses.
  MonteCarloLocalizer(const grid::OccupancyMap& map, double range_max,
                      const MonteCarloOptions& options = {});

  /// Particles from a Gaussian around `mean` (covariance over x, y, theta).
  void initialise(const Pose2& mean, const Eigen::Matrix3d& covariance);
  /// Particles uniformly over the map's free cells, global_particles (or max_particles) of them.
  void initialiseGlobal();
  bool initialised() const { return !particles_.empty(); }
  /// Swaps in a new map (e.g. a SLAM map that grew), same frame: the likelihood field and the
  /// free cells are rebuilt, the particles and the fit averages are kept. Throws
  /// std::invalid_argument (the filter unchanged) for a map the likelihood field refuses.
  void setMap(const grid::OccupancyMap& map);

  /// One filter step at odometry pose `odom` with the scan endpoints `points` (robot frame, beams
  /// at range_max left out). Does nothing (returns false) until the robot moved far enough since
  /// the last update, unless `force`. Non-finite input is ignored (returns false).
  bool update(const Pose2& odom, std::span<const Eigen::Vector2d> points, bool force = false);

  PoseEstimate estimate() const;
  std::span<const Particle> particles() const { return particles_; }
  /// The recovery's current share of random particles, 1 − w_fast / w_slow (≥ 0).
  double randomShare() const;
  const LikelihoodField& field() const { return field_; }
  int updates() const { return updates_; }
  /// Share of the best particle's beams within inlier_distance of an obstacle at the last
  /// weighted update (1 before any).
  double inlierFraction() const { return inlier_fraction_; }
  /// Global re-spreads after the robot was found lost (lost_inlier_fraction).
  int relocalisations() const { return relocalisations_; }
  /// Refinements taken, and refused (further than refine_max_shift), so far.
  int refinements() const { return refinements_; }
  int refinementsRefused() const { return refinements_refused_; }
  /// [m] length of the last refinement taken (0 before any).
  double lastRefinementShift() const { return last_refinement_shift_; }

 private:
  double beta_ = 1.0;  // tempering exponent of the last update
  static std::vector<Eigen::Vector2i> freeCells(const LikelihoodField& field);
  Pose2 randomFreePose();
  void resample();
  PoseEstimate clusterEstimate() const;
  void refine(std::span<const Eigen::Vector2d> points);

  MonteCarloOptions options_;
  LikelihoodField field_;
  std::vector<Eigen::Vector2i> free_cells_;
  std::vector<Particle> particles_;
  std::optional<Pose2> last_odom_;
  double w_slow_ = 0, w_fast_ = 0;
  int updates_ = 0;
  double inlier_fraction_ = 1.0;
  int lost_streak_ = 0, relocalisations_ = 0;
  std::optional<Pose2> refined_;  // the refined estimate of the current particle set
  int refinements_ = 0, refinements_refused_ = 0;
  double last_refinement_shift_ = 0;
  std::mt19937_64 rng_;
};

}  // namespace tessera::localization
