// Rbpf: the local level of the two-level laser SLAM (docs/algorithms.md#rbpf-submaps): a
// Rao-Blackwellised particle filter that builds one occupancy-grid submap at a time from laser
// scans and wheel odometry, in the style of Grisetti et al. 2007 (GMapping).
//
// Per filter update, for every particle (in parallel, TBB):
//   1. predict: prior mean = particle pose ⊕ odometry increment, prior covariance from the
//      motion-noise model (srr, srt, str, stt as in GMapping);
//   2. scan-match the new scan against the particle's own map from the prior mean: a coarse
//      stage (wide kernel, every n-th beam) brings the pose into the basin of the fine stage;
//      when both fail from the prior mean, the coarse stage is retried from starts spread over
//      the prior (recovery_sigma) before giving up;
//   3. improved proposal: fit a Gaussian to p(z|m,x)·p(x|x',u) sampled around the matched mode,
//      draw the new pose from it, and multiply the weight by its normaliser η (divided by
//      weight_divisor, as GMapping flattens its weights); when both stages fail (too few beams
//      agree) the pose is drawn from the motion model instead;
//   4. resample (systematic) when N_eff = 1/Σw² < resample_threshold·N;
//   5. insert the scan into each particle's map. Particles copied by resampling share map tiles
//      (copy-on-write TiledGrid): identical copies insert once and share the result, so memory
//      grows with the explored area, not with particles × area.
// Updates are gated on travelled distance / rotation / time, as in GMapping; scans in between
// only move the online estimate by odometry.
//
// Submaps: startSubmap() closes the current submap and opens a new one whose origin is the
// robot's pose at that moment (x axis = heading). The robot pose in the old submap (best
// particle) and the weighted particle spread around it form the inter-submap constraint; in
// the new submap every particle starts at the origin with zero uncertainty and one shared map.
//
// Frames and units: the odometry pose is base_link in odom; particle poses are base_link in the
// current submap frame; metres, radians, seconds. Plain C++: no runtime or message types.
// Not thread-safe: one caller at a time (the filter parallelises internally).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/grid/tiled_grid.hpp>
#include <tessera/scan_matching/scan_matcher.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace tessera::laser_slam {

/// Odometry noise model, with GMapping's names and defaults: standard deviations of an
/// increment per unit of motion (s<error><cause>: r = translation, t = rotation).
struct MotionNoise {
  double srr = 0.1;  ///< [m/m] translation error per metre travelled
  double srt = 0.2;  ///< [m/rad] translation error per radian turned
  double str = 0.1;  ///< [rad/m] rotation error per metre travelled
  double stt = 0.2;  ///< [rad/rad] rotation error per radian turned

  template <class V>
  void visit(V& v) {
    v("srr", srr, "translation noise per metre travelled [m/m]");
    v("srt", srt, "translation noise per radian turned [m/rad]");
    v("str", str, "rotation noise per metre travelled [rad/m]");
    v("stt", stt, "rotation noise per radian turned [rad/rad]");
  }
};

/// Cap on the heading starts per side of the recovery search (RbpfOptions::recovery_sigma).
inline constexpr int kMaxRecoverySteps = 10;

struct RbpfOptions {
  int particles = 30;
  double resample_threshold = 0.5;  ///< resample when N_eff < this · particles (0..1]
  /// Log-weight increments are divided by this before they enter the weights (0 = the particle
  /// count, as GMapping does). Beams are not independent, so the raw scan likelihood is far too
  /// peaked: without it one particle takes all the weight at every update and the filter loses
  /// the diversity it needs to close loops.
  double weight_divisor = 0.0;
  double linear_update = 1.0;    ///< [m] travel that triggers a filter update
  double angular_update = 0.5;   ///< [rad] rotation that triggers a filter update
  double temporal_update = 0.0;  ///< [s] time that triggers an update; 0 disables
  MotionNoise motion;
  /// The grid's defaults but a weaker miss than the known-pose mapper's: a wall cell crossed
  /// by grazing beams keeps its evidence, so scan matching still finds it (GMapping counts a
  /// cell hit by 10 % of its beams).
  tessera::grid::TiledGridOptions grid = [] {
    tessera::grid::TiledGridOptions g;
    g.log_odds.miss = -0.2f;
    return g;
  }();
  tessera::grid::ScanInsertOptions insert;
  /// Fine matching, proposal and weights. Differs from the matcher's defaults where a
  /// particle filter wants it: a match counts with 10 % of the beams on the map (the particle
  /// weights judge the rest), a beam without an obstacle near costs as if it were 0.27 m off
  /// (so a particle whose map disagrees with the scan loses weight), and no covariance fit
  /// (the filter fits its own proposal).
  tessera::scan_matching::ScanMatcherOptions matcher = [] {
    tessera::scan_matching::ScanMatcherOptions m;
    m.min_score_fraction = 0.1;
    m.no_hit_distance = 0.27;
    m.compute_covariance = false;
    return m;
  }();
  /// Coarse first stage: a wider kernel on fewer beams widens the basin of attraction cheaply
  /// (odometry after a 1 m gate can be off by more than the fine kernel reaches); the fine
  /// stage starts where it ends. coarse_kernel_radius 0 disables the stage.
  int coarse_kernel_radius = 4;
  int coarse_beam_step = 4;
  /// When matching from the prior mean fails in both stages, the coarse stage is retried from
  /// starts within ±recovery_sigma prior standard deviations (heading every
  /// recovery_angular_step, at most kMaxRecoverySteps per side, each also shifted by half the
  /// reach along x and y); the best-scoring success goes on to the fine stage. 0 disables: the
  /// particle then follows the motion model and inserts its scan at the sampled pose.
  double recovery_sigma = 2.0;
  double recovery_angular_step = 0.05;  ///< [rad]
  /// A match whose fine stage finds fewer than this fraction of the scan's beams on the map is
  /// not trusted: the particle follows the motion model instead. Entering unmapped space, a
  /// handful of beams can agree with a wall at a wrong heading, and one such particle winning
  /// the weights turns the whole filter (seen on Intel at t = 911 s). 0 disables.
  double min_overlap_fraction = 0.0;
  /// The best particle (online pose, best map, submap hand-overs) is the one with the most
  /// posterior weight near its pose: a Gaussian kernel of these widths over the weighted
  /// particles, ties (resampled copies) to the highest accumulated log weight. When the cloud
  /// splits into hypotheses, the single heaviest particle is a near coin toss between them;
  /// the best-supported hypothesis is what the posterior favours. 0 (either): the highest
  /// accumulated log weight alone, as GMapping picks.
  double best_support_linear = 0.0;   ///< [m]
  double best_support_angular = 0.0;  ///< [rad]
  /// The online estimate at an update: the weighted mean of the particles within a Gaussian
  /// kernel of these widths around the best particle (kernelMean()), not the best particle's
  /// own pose, which is one draw from its proposal. Particles, maps and the best trajectory are
  /// unchanged. 0 (either): the best particle's pose.
  double online_mean_linear = 0.0;   ///< [m]
  double online_mean_angular = 0.0;  ///< [rad]
  /// Between filter updates, match each usable scan (the coarse stage's beams, fine kernel)
  /// against the best particle's map, from the last tracked pose moved by the odometry since:
  /// the online estimate pose() then follows the scans instead of the raw odometry (which over
  /// a 1 m / 0.5 rad gate drifts by degrees). A match is kept only when its likelihood (all
  /// beams) times the motion prior beats the odometry prediction's; otherwise the prediction
  /// stands. Particles, maps, weights and the best trajectory are unchanged.
  bool track_between_updates = true;
  /// Hill climbing of that tracking: initial steps and step halvings; 0 = the fine matcher's
  /// (matcher.linear_step, angular_step, refinements). The prediction from the last tracked scan
  /// is off by millimetres to a few centimetres, less than an update's odometry prior, so it
  /// can start with smaller steps; a first step of the fine stage's 5 cm can climb into a
  /// neighbouring ridge of the score.
  double track_linear_step = 0.0;   ///< [m]
  double track_angular_step = 0.0;  ///< [rad]
  int track_refinements = 0;
  std::uint64_t seed = 1;  ///< results are reproducible for a seed, whatever the thread count
  bool parallel = true;    ///< particles on TBB worker threads (false: one thread)
  /// Draw each particle's pose from the fitted proposal (Grisetti et al. 2007); false keeps the
  /// proposal's mean (GMapping's shortcut: less diversity, less jitter).
  bool sample_proposal = true;
  /// Random-walk floor on the hand-over constraint's covariance: σ² · d is added per axis, d =
  /// metres travelled in the submap ([m/√m] for x and y, [rad/√m] for θ). The particle spread
  /// alone understates how far a submap's end may be off: resampling collapses it, and the
  /// particles share most of their history.
  double handover_sigma_linear = 0.02;
  double handover_sigma_angular = 0.005;
  /// [m] At a hand-over, the new submap starts with the best particle's update scans of this
  /// much of its path (placed by its trajectory), not only the last scan: the filter then
  /// matches its first metres against walls it has just seen instead of one scan's view.
  /// 0: the last scan only. 5 m: live pose on Intel 0.123 -> 0.115 m (seeds 1-3), 0.135 ->
  /// 0.125 m (seeds 4-12), final +0.0008 m; simulated office live ATE 0.26 -> 0.13 m and final
  /// 0.098 -> 0.086 m (seeds 1-3); 2-3 m and 10 m were worse.
  double carry_over_distance = 5.0;
  /// Lost (kidnapped, or the odometry slipped beyond the matcher's reach): an update whose best
  /// match puts fewer than this fraction of the scan's beams on the map is suspect, and its scan
  /// is not inserted (a wrong pose would draw walls where there are none). `lost_updates`
  /// suspect updates in a row declare the robot lost (RbpfStep::lost); the caller then starts a
  /// fresh submap with startSubmapLost(). 0 disables (every scan is inserted).
  double lost_match_fraction = 0.0;
  int lost_updates = 3;
  /// Standard deviations of the lost hand-over: where the odometry says the robot went, with
  /// no more confidence than this (the graph places the new submap by later constraints).
  double lost_sigma_linear = 100.0;  ///< [m]
  double lost_sigma_angular = 3.0;   ///< [rad]

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
    v("motion", motion, "odometry noise model");
    v("seed", seed, "random seed (runs are reproducible for a seed)");
    v("parallel", parallel, "update particles on TBB worker threads");
    v("sample_proposal", sample_proposal,
      "draw poses from the fitted proposal (true) or keep its mean (false)");
    v("grid", grid, "each particle's submap");
    v("insert", insert, "how scans are drawn into the submaps");
    v("matcher", matcher, "fine scan matching, proposal fit and particle weights");
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
    v("handover_sigma_linear", handover_sigma_linear,
      "[m/sqrt(m)] hand-over covariance floor: variance += sigma^2 x metres travelled in the "
      "submap (x, y)");
    v("handover_sigma_angular", handover_sigma_angular, "[rad/sqrt(m)] the same for the heading");
    v("carry_over_distance", carry_over_distance,
      "[m] a new submap starts with the best particle's update scans of this much of its path "
      "(0: the last scan only)");
    v("lost_match_fraction", lost_match_fraction,
      "an update whose best match puts fewer than this fraction of the beams on the map is "
      "suspect (its scan is not inserted); lost_updates of them in a row: lost, a fresh submap "
      "starts; 0 disables");
    v("lost_updates", lost_updates, "suspect updates in a row that declare the robot lost");
    v("lost_sigma_linear", lost_sigma_linear,
      "[m] standard deviation of the hand-over into the submap started when lost (x, y)");
    v("lost_sigma_angular", lost_sigma_angular, "[rad] the same for the heading");
  }
};

/// A pose with its uncertainty, e.g. an inter-submap constraint.
struct PoseWithCovariance {
  tessera::Pose2 pose;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< over (x, y, theta)
};

/// A submap closed by startSubmap(): the best particle's map and the hand-over constraint.
struct FinishedSubmap {
  int id = 0;
  tessera::grid::TiledGrid grid;    ///< in the submap's own frame (origin = its first pose)
  PoseWithCovariance next_in_this;  ///< the next submap's origin expressed in this submap
  std::uint64_t scans_inserted = 0;
  double travelled_m = 0.0;
};

/// What one addScan() did.
struct RbpfStep {
  bool updated = false;  ///< the filter ran (gate passed, scan usable)
  bool resampled = false;
  bool matched = false;        ///< at least one particle's scan match succeeded
  bool scan_unusable = false;  ///< no valid beam (NaN, empty, all no-return): odometry only
  double neff = 0.0;           ///< N_eff before resampling (valid when updated)
  /// Fraction of the scan's beams on the map at the best particle match (valid when updated
  /// after the first scan of a submap).
  double match_fraction = 0.0;
  bool suspect = false;  ///< below lost_match_fraction: the scan was not inserted
  bool lost = false;     ///< lost_updates suspect updates in a row: call startSubmapLost()
};

struct RbpfStats {
  std::uint64_t scans = 0;    ///< addScan() calls
  std::uint64_t updates = 0;  ///< filter updates (including the first scan)
  std::uint64_t resamples = 0;
  std::uint64_t match_failures = 0;  ///< particle updates that fell back to the motion model
  /// particle updates whose match from the prior mean failed and the wider search recovered
  std::uint64_t match_recoveries = 0;
  std::uint64_t particle_updates = 0;
  std::uint64_t coarse_evaluations = 0;  ///< scan scores computed by the coarse stage
  std::uint64_t fine_evaluations = 0;    ///< by the fine stage
  std::uint64_t unusable_scans = 0;
  std::uint64_t tracked_scans = 0;         ///< scans matched between updates (tracking on)
  std::uint64_t tracking_failures = 0;     ///< of those, left on odometry (no better match)
  std::uint64_t tracking_evaluations = 0;  ///< scan scores computed by tracking
  std::uint64_t invalid_odometry = 0;      ///< non-finite odometry poses ignored
  std::uint64_t suspect_updates = 0;       ///< updates whose scan was not inserted (lost_*)
  std::uint64_t lost = 0;                  ///< times the filter declared itself lost
  double match_fraction_min = 1.0;         ///< lowest RbpfStep::match_fraction seen
  /// largest Rbpf::mapBytes() seen: sampled every Rbpf::kMapBytesEvery updates and when a
  /// submap closes
  std::size_t map_bytes_peak = 0;
};

/// Systematic (low-variance) resampling: n = weights.size() draws at u0 + k/n, k = 0..n-1, on
/// the cumulative normalised weights; u0 in [0, 1/n). Returns the index drawn for each slot.
/// Every index i is drawn floor(n·w_i) or ceil(n·w_i) times. Weights need not sum to 1.
std::vector<std::size_t> systematicResample(const std::vector<double>& weights, double u0);

/// Index of the particle with the most weight near its pose: support_i = Σ_j w_j ·
/// exp(-½ (|Δxy|² / σ_linear² + Δθ² / σ_angular²)). Supports within 1e-9 (relative) tie, and
/// ties go to the highest tie_break (the first of equals). σ = 0 (either): tie_break alone.
/// The spans have one entry per particle; weights need not be normalised.
std::size_t selectBestParticle(std::span<const tessera::Pose2> poses,
                               std::span<const double> weights, std::span<const double> tie_break,
                               double sigma_linear, double sigma_angular);

/// Weighted mean of the poses within a Gaussian kernel around `centre`, each weighted by
/// weights_i · exp(-½ (|Δxy|² / σ_linear² + Δθ² / σ_angular²)); headings are averaged as
/// differences from the centre's, so the mean is continuous across ±π. `centre` itself when
/// the kernel holds no weight or σ = 0 (either).
tessera::Pose2 kernelMean(std::span<const tessera::Pose2> poses, std::span<const double> weights,
                          const tessera::Pose2& centre, double sigma_linear, double sigma_angular);

class Rbpf {
 public:
  /// Throws std::invalid_argument naming the offending option.
  explicit Rbpf(RbpfOptions options);

  /// Feeds one scan with the robot's odometry pose at the scan's time (odom frame) and the
  /// laser mounting (laser in base_link). Never throws on bad data: NaN/empty scans and
  /// non-finite odometry are counted and leave the filter as it was.
  RbpfStep addScan(double stamp_s, const tessera::grid::RangeScan& scan,
                   const tessera::Pose2& mount, const tessera::Pose2& odometry);

  /// True once the first usable scan has been inserted.
  bool initialized() const { return initialized_; }
  /// Online estimate of base_link in the current submap at the last scan: the best particle's
  /// pose at the last update (with online_mean_*: the particles' mean around it) composed with
  /// the odometry travelled since (with track_between_updates: with the scan-matched motion
  /// since).
  tessera::Pose2 pose() const;
  /// Best particle's pose and the weighted spread of all particles around it, at the last
  /// update (in the current submap).
  PoseWithCovariance poseWithCovariance() const;
  /// Closes the current submap at the last scan and starts the next one there. The last scan
  /// (if usable) is inserted into the new submap so consecutive submaps overlap.
  /// Precondition: initialized().
  FinishedSubmap startSubmap();
  /// startSubmap() for a robot that is lost (RbpfStep::lost): the hand-over is the odometry's
  /// guess with the lost_sigma_* covariance, and the new submap starts from the last scan alone
  /// (the kept scans are of the place the robot was taken from). Precondition: initialized().
  FinishedSubmap startSubmapLost();
  /// The current submap as startSubmap() would close it now, without closing it (e.g. the last
  /// submap at the end of a run). Precondition: initialized().
  FinishedSubmap currentSubmap() const;

  int submapId() const { return submap_id_; }
  /// Current best map (best particle), in the current submap frame.
  const tessera::grid::TiledGrid& bestMap() const;
  /// Scans inserted into the current submap; metres travelled in it (odometry).
  std::uint64_t submapScans() const { return submap_scans_; }
  double submapTravelled() const { return submap_travelled_; }

  /// Best particle's poses at its filter updates in the current submap (trajectory tree walk).
  struct StampedPose {
    double stamp_s;
    tessera::Pose2 pose;
  };
  std::vector<StampedPose> bestTrajectory() const;

  const RbpfStats& stats() const { return stats_; }
  const RbpfOptions& options() const { return options_; }
  int particleCount() const { return static_cast<int>(particles_.size()); }
  /// Normalised weights (sum 1), for tests and diagnostics.
  std::vector<double> weights() const;
  /// Every particle's pose at the last update (current submap frame), for tests and diagnostics.
  std::vector<tessera::Pose2> particlePoses() const;
  /// Distinct map objects the particles hold (copies made by resampling share one until they
  /// diverge), for tests and diagnostics.
  int distinctMaps() const;
  /// Bytes the particles' maps hold together (tiles shared by several maps counted once; see
  /// TiledGrid::sharedMemoryBytes), in the current submap.
  std::size_t mapBytes() const;
  /// RbpfStats::map_bytes_peak is sampled every this many updates.
  static constexpr std::uint64_t kMapBytesEvery = 8;

 private:
  void noteMapBytes();
  struct TrajectoryNode {
    double stamp_s;
    tessera::Pose2 pose;
    std::shared_ptr<const TrajectoryNode> parent;
  };
  struct Particle {
    tessera::Pose2 pose;
    double log_weight = 0.0;  ///< normalised after each update (log Σw = 0)
    double log_score = 0.0;   ///< accumulated log weight increments: picks the best particle
    std::shared_ptr<tessera::grid::TiledGrid> map;  ///< replaced, never written, when shared
    std::shared_ptr<const TrajectoryNode> node;
  };

  void initialize(double stamp_s, const tessera::grid::RangeScan& scan, const tessera::Pose2& mount,
                  const tessera::Pose2& odometry);
  /// Returns how many particles fell back to the motion model.
  /// For each particle, the first particle holding the same map at the same pose (itself when
  /// none does): copies made by resampling, whose matches and insertions are the same.
  std::vector<std::size_t> copySources() const;
  std::size_t updateParticles(const tessera::scan_matching::ScanPoints& points,
                              const tessera::scan_matching::ScanPoints& coarse_points,
                              const tessera::Pose2& odom_delta);
  double normalizeWeights();
  void resample();
  void insertScan(const tessera::grid::RangeScan& scan, const tessera::Pose2& mount);
  Eigen::Matrix3d motionCovariance(const tessera::Pose2& delta) const;
  int bestIndex() const;
  /// Between updates: moves the online estimate by the odometry since the last tracked scan and
  /// matches `scan` against the best map there (track_between_updates).
  void trackScan(const tessera::grid::RangeScan& scan, const tessera::Pose2& mount,
                 const tessera::scan_matching::ScanPoints& points, const tessera::Pose2& odometry);
  /// Restarts between-update tracking at the best particle's pose and the odometry there.
  void resetTracking(const tessera::Pose2& odometry);

  RbpfOptions options_;
  tessera::scan_matching::ScanMatcher matcher_;
  tessera::scan_matching::ScanMatcher tracking_matcher_;  // matcher_ with the tracking's steps
  std::optional<tessera::scan_matching::ScanMatcher> coarse_matcher_;
  std::vector<Particle> particles_;
  bool initialized_ = false;
  int submap_id_ = 0;
  std::uint64_t submap_scans_ = 0;
  double submap_travelled_ = 0.0;

  tessera::Pose2 last_odometry_;    // at the last scan
  tessera::Pose2 update_odometry_;  // at the last filter update
  double update_stamp_s_ = 0.0;
  double travelled_since_update_ = 0.0;
  double turned_since_update_ = 0.0;
  int best_ = 0;  // best particle at the last update
  // Online estimate at the last tracked scan and the odometry there (= the best particle and
  // update_odometry_ when tracking is off or nothing was tracked since the update).
  tessera::Pose2 tracked_;
  tessera::Pose2 tracked_odometry_;
  std::uint64_t update_index_ = 0;    // seeds the per-particle random streams
  double last_match_fraction_ = 0.0;  // best match of the last update (updateParticles)
  int suspect_run_ = 0;               // suspect updates in a row (lost_match_fraction)

  // The last usable scan, kept so startSubmap() can seed the next submap with it.
  std::vector<float> last_ranges_;
  tessera::grid::RangeScan last_scan_;  // views last_ranges_
  tessera::Pose2 last_mount_;
  bool last_scan_usable_ = false;  // the most recent scan was usable and is kept above
  double last_stamp_s_ = 0.0;
  // carry_over_distance: the update scans of the current submap's last metres (path = the
  // submap's travel when the scan was inserted), oldest first.
  struct KeptScan {
    double stamp_s = 0.0;
    std::vector<float> ranges;
    tessera::grid::RangeScan scan;  // its ranges view `ranges`
    tessera::Pose2 mount;
    double path_m = 0.0;
  };
  std::vector<KeptScan> kept_;

  RbpfStats stats_;
};

}  // namespace tessera::laser_slam
