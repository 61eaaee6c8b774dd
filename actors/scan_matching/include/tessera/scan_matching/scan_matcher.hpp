// ScanMatcher: aligns a planar laser scan with a log-odds occupancy grid by hill climbing, and
// fits the improved proposal of Grisetti et al. 2007 ("Improved Techniques for Grid Mapping with
// Rao-Blackwellized Particle Filters", eq. 9-11) around the match. Used by the RBPF, loop
// closure and localisation.
//
// Frames and units: metres and radians. ScanPoints are in the robot (base) frame; poses passed
// to score/match/fit are robot poses in the grid's frame ("map"). Moves are along the map axes.
//
// Beam model. For a robot pose, each endpoint e is transformed into the map. The search window
// is the (2r+1)² cells around e's cell (r = kernel_radius). A window cell c is a candidate when
//   logOdds(c) > occupied_threshold  and  logOdds(c + δ) ≤ occupied_threshold,
// where δ = round(o·u / resolution) is a per-beam cell offset against the beam direction u
// (o = effective free-check offset, see the option): the cell just in front of an obstacle,
// seen along the beam, must not be an obstacle itself, so a beam does not match the far side of
// a wall it would have crossed. d is the distance from e to the nearest candidate's centre,
// clamped to R = (r + ½)·resolution; beams with no candidate get d = R. R is the largest radius
// the window covers around every possible e, so cells entering or leaving the window as e
// crosses a cell boundary are always at d ≥ R: the clamped d, hence score and log-likelihood,
// are continuous in x and y (and in θ except where a beam direction flips some δ), which lets
// hill climbing reach sub-cell accuracy.
//   score          = Σ_beams (exp(−d²/2σ²) − exp(−R²/2σ²)) / (1 − exp(−R²/2σ²)),  σ = sigma
//                    (1 for a beam exactly on a cell centre, 0 for an unmatched beam, so the
//                    score reads as "beams matched, weighted by closeness")
//   log-likelihood = Σ_beams −d²/(2·likelihood_sigma²) / likelihood_gain
//                    (an unmatched beam costs −D²/(2·likelihood_sigma²)/likelihood_gain with
//                    D = max(R, no_hit_distance): by default as if its obstacle were R away)
// A beam is "matched" when d < R.
//
// Grid: any type providing `double resolution() const`, `Eigen::Vector2i worldToCell(const
// Eigen::Vector2d&) const`, `Eigen::Vector2d cellCenter(const Eigen::Vector2i&) const` and
// `float logOdds(const Eigen::Vector2i&) const` (0 = unknown) on a regular lattice of that
// resolution (grid::OccupancyGrid; the copy-on-write tiled grid). The inner loop locates cells by
// lattice arithmetic from cellCenter({0, 0}) and the resolution, so only logOdds() is called per
// cell; worldToCell() must agree with that lattice.
//
// Hit points. A Grid that also provides `bool tracksHitPoints() const` and `Eigen::Vector2d
// hitPoint(const Eigen::Vector2i&) const` (grid::TiledGrid with track_hit_points) and reports true
// is matched GMapping-style: d is measured to the candidate's hitPoint() (the mean endpoint
// that hit it, anywhere inside the cell) instead of its centre, which removes the cell-size
// quantisation of walls. Everything else (candidates, free check, window, R, score and
// likelihood) is unchanged. One difference: a hit point in a cell just outside the window can
// lie closer than R, so d may jump as such a cell enters or leaves the window (at d between
// r·resolution and R); centres never do.
//
// Occupancy rows. A Grid that also provides `void occupancyRows(int x0, int y0, int height,
// float threshold, std::uint32_t* rows) const` (bit j of rows[i] set iff logOdds({x0 + j, y0 +
// i}) > threshold; grid::TiledGrid, which caches these bits per tile) is read a window at a time:
// the candidates of a beam's window are found with a few word operations on 2r+3 rows instead of up
// to 2·(2r+1)² logOdds() calls, and a beam whose window holds no candidate skips the walk. The
// result is the same, bit for bit, except that the free-check direction is found by comparing
// squares rather than rounding a quotient, which could differ only for a beam exactly on a
// rounding boundary. Used when r ≤ kMaxBitRadius and the free-check offset is under 1.5 cells
// (the default √2 cells is), so the free-check cell is a neighbour.
//
// Several poses at once. Hill climbing scores its moves, and the proposal fit its samples, in
// one pass over the beams (on occupancy row grids): a beam's endpoints at nearby poses mostly
// fall within a few cells of each other, so their rows are read, and their free-check bits
// formed, once for all of them. Each pose's score and likelihood are the same, bit for bit, as
// scoring it alone.
//
// A ScanMatcher holds only its options: all methods are const, allocate nothing per score
// evaluation and may be called concurrently on grids nobody is writing.
//
// The templates are defined in src/scan_matcher_impl.hpp (the inner loop's cell arithmetic and
// SIMD helpers in src/matcher_cells.hpp) and instantiated in the library for grid::OccupancyGrid
// and grid::TiledGrid, so users of those grids need only this header. Code matching on another grid
// type (tests' fake grids) includes the implementation header.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <span>
#include <vector>

namespace tessera::grid {
class TiledGrid;
}  // namespace tessera::grid

namespace tessera::scan_matching {

struct ScanMatcherOptions {
  double max_range = 30.0;  ///< [m] returns farther than this are not used for matching
  int beam_step = 1;        ///< use every n-th valid beam (≥ 1)
  int kernel_radius = 1;    ///< [cells] r: the search window is (2r+1)² cells around an endpoint
  double sigma = 0.05;  ///< [m] σ of the score kernel exp(−d²/2σ²) (see the header comment)
  double likelihood_sigma = 0.075;  ///< [m] σ of the per-beam log-likelihood −d²/2σ²
  /// The log-likelihood is divided by this (GMapping's lgain): beams are not independent, so
  /// their product is overconfident; flattening it keeps particle weights from collapsing.
  double likelihood_gain = 3.0;
  /// [m] An unmatched beam (no candidate within R) costs in the log-likelihood what a beam whose
  /// obstacle lies this far away would (D above; values below R mean R, so the default 0 keeps
  /// the likelihood continuous). The window only sees R = (kernel_radius + ½) cells, and a scan
  /// that is off by more than that loses beams to "unmatched" at barely more cost than a beam
  /// matched at the window's edge: the likelihood then hardly tells a pose 0.5 m off from a good
  /// one. A larger D is the distance at which the Gaussian beam model meets an outlier floor
  /// (GMapping's no-hit term amounts to about 0.7 m); it makes every unmatched beam count. Score
  /// and hill climbing are unaffected.
  double no_hit_distance = 0.0;
  float occupied_threshold = 0.0f;  ///< log-odds above which a cell counts as an obstacle
  /// [m] the free-check cell lies this far before the candidate along the beam. The effective
  /// offset is max(free_check_offset, √2·resolution) — √2·resolution is the shortest that
  /// always lands in another cell — so the default 0 means "one cell back". Negative disables
  /// the free check.
  double free_check_offset = 0.0;
  double linear_step = 0.05;   ///< [m] initial hill-climbing step along x and y
  double angular_step = 0.05;  ///< [rad] initial hill-climbing step in θ
  int refinements = 5;         ///< step halvings before hill climbing stops
  int max_iterations = 200;    ///< cap on score evaluations per match()
  /// match() fails when fewer than this fraction of the scan's beams are matched at the end.
  double min_score_fraction = 0.3;
  /// Proposal / covariance sampling: a grid of (2s+1)³ poses, s = proposal_steps, spaced
  /// proposal_linear [m] in x and y and proposal_angular [rad] in θ around the mode.
  double proposal_linear = 0.02;
  double proposal_angular = 0.01;
  int proposal_steps = 1;
  /// Match covariance sampling: a grid of (2c+1)³ poses, c = covariance_steps, spaced
  /// covariance_linear [m] and covariance_angular [rad] around the optimum. Wider than the
  /// proposal grid on purpose: the nearest-cell-centre distance has a texture with the period of
  /// a cell, and a fit over less than about two cells reads that texture as information along
  /// walls (see MatchResult::covariance).
  double covariance_linear = 0.025;
  double covariance_angular = 0.005;
  int covariance_steps = 2;
  /// match() fills MatchResult::covariance, at the cost of (2c+1)³ evaluations (125 by default,
  /// more than the hill climbing itself). A filter that calls fitProposal() anyway should turn
  /// this off.
  bool compute_covariance = true;

  template <class V>
  void visit(V& v) {
    v("max_range", max_range, "returns farther than this [m] are not used for matching");
    v("beam_step", beam_step, "match with every n-th valid beam");
    v("kernel_radius", kernel_radius, "cells searched around each beam endpoint");
    v("sigma", sigma, "score kernel width [m]");
    v("likelihood_sigma", likelihood_sigma, "likelihood kernel width [m]");
    v("likelihood_gain", likelihood_gain,
      "log-likelihood divided by this (flattens overconfident weights)");
    v("no_hit_distance", no_hit_distance,
      "[m] a beam with no obstacle within the kernel costs as much in the likelihood as one "
      "whose obstacle is this far away (0 = the kernel's reach): makes particles whose map "
      "disagrees with the scan lose weight");
    v("occupied_threshold", occupied_threshold,
      "log-odds above which a cell counts as an obstacle");
    v("free_check_offset", free_check_offset,
      "[m] the free-check cell lies this far before a candidate along the beam (at least one "
      "cell); negative disables the check");
    v("linear_step", linear_step, "initial hill-climbing step [m]");
    v("angular_step", angular_step, "initial hill-climbing step [rad]");
    v("refinements", refinements, "hill-climbing step halvings");
    v("max_iterations", max_iterations, "cap on score evaluations per match");
    v("min_score_fraction", min_score_fraction,
      "a match succeeds when at least this fraction of the beams lands near an obstacle");
    v("proposal_linear", proposal_linear,
      "[m] proposal fit: spacing of the pose samples in x and y around the matched pose");
    v("proposal_angular", proposal_angular,
      "[rad] proposal fit: spacing of the pose samples in heading around the matched pose");
    v("proposal_steps", proposal_steps, "proposal fit: samples per side and axis");
    v("covariance_linear", covariance_linear,
      "[m] match covariance: spacing of the pose samples in x and y");
    v("covariance_angular", covariance_angular,
      "[rad] match covariance: spacing of the pose samples in heading");
    v("covariance_steps", covariance_steps, "match covariance: samples per side and axis");
    v("compute_covariance", compute_covariance,
      "fit the match covariance (costs (2c+1)^3 evaluations per match)");
  }
};

/// A scan prepared once for matching: the used endpoints in the robot (base) frame.
struct ScanPoints {
  std::vector<Eigen::Vector2f> endpoints;            ///< [m] base frame
  Eigen::Vector2f origin = Eigen::Vector2f::Zero();  ///< [m] sensor position in the base frame
  std::size_t beams_total = 0;                       ///< beams in the raw scan, used or not

  std::size_t size() const { return endpoints.size(); }
  bool empty() const { return endpoints.empty(); }
};

struct MatchResult {
  Pose2 pose;                 ///< best pose found (the initial pose when nothing was usable)
  double score = 0;           ///< score() at pose
  double log_likelihood = 0;  ///< logLikelihood() at pose
  int matched_beams = 0;      ///< beams with d < R at pose
  /// Score evaluations spent hill climbing (not covariance), counting the moves that are
  /// skipped rather than recomputed (back to the previous pose, or onto any recently scored
  /// pose: neither can win).
  int evaluations = 0;
  /// matched_beams ≥ min_score_fraction · beams, with at least one beam matched.
  bool success = false;
  /// Laplace approximation of the likelihood around pose (no prior): the inverse of the
  /// negative Hessian of a quadratic least-squares fit of logLikelihood() over the covariance
  /// sample grid. Eigenvalues are bounded in sample-grid units (std between 0.01 and 100 grid
  /// steps), so a direction the scan does not constrain (a corridor's axis) shows up as a large
  /// variance (up to 100 steps = 2.5 m with defaults) instead of a singular matrix. Order
  /// (x, y, θ). Filled only with compute_covariance, else zero.
  /// Limits: it is local (beams beyond R from their cell flatten it) and the cell-centre
  /// texture leaves some spurious information along walls, so a corridor's axis variance is
  /// large but not reliably the cap; treat it as "well constrained or not" per direction.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};

/// The Gaussian proposal N(mean, covariance) fitted around a match, and its normaliser.
struct ProposalFit {
  Pose2 mean;
  /// Weighted sample covariance (x, y, θ) plus step²/12 per axis (the sampling grid's own
  /// resolution), so it is positive definite even when one sample takes all the weight.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  /// log η = log Σ_j p(z | m, x_j) · p(x_j | x', u) over the samples (the particle weight
  /// factor): the log-likelihood plus the full Gaussian log-density of the prior, summed by
  /// log-sum-exp. No sample-volume factor (the same for every particle).
  double log_eta = 0;
  int samples = 0;
};

namespace detail {
struct SampleGrid;  // a regular grid of poses around a centre (scan_matcher_impl.hpp)
}  // namespace detail

class ScanMatcher {
 public:
  /// Largest kernel radius read as occupancy rows: the window plus its free-check border,
  /// 2r+3 cells, fits one 32-bit row.
  static constexpr int kMaxBitRadius = 14;

  /// Throws std::invalid_argument naming the first bad option.
  explicit ScanMatcher(ScanMatcherOptions o = {});

  const ScanMatcherOptions& options() const { return options_; }

  /// Endpoints of the usable beams of `scan` in the base frame; `mount` is the laser pose in the
  /// base frame. Drops NaN, < range_min, ≤ 0, no-return (+inf or ≥ range_max) and > max_range
  /// beams, then keeps every beam_step-th of the rest. A scan with non-finite angles or mount
  /// gives no endpoints.
  ScanPoints prepare(const grid::RangeScan& scan, const Pose2& mount) const;

  /// Higher is better; 0 when nothing matches (see the header comment).
  template <class Grid>
  double score(const Grid& grid, const ScanPoints& points, const Pose2& robot_pose) const;

  /// log p(z | m, x) up to a constant, flattened by likelihood_gain; ≤ 0. `matched`, when
  /// given, receives the number of beams with d < R.
  template <class Grid>
  double logLikelihood(const Grid& grid, const ScanPoints& points, const Pose2& robot_pose,
                       int* matched = nullptr) const;

  /// Hill climbing on score() from `initial`: try ±linear_step in x and y and ±angular_step in
  /// θ, move to the best improving neighbour, halve both steps when none improves; stop after
  /// `refinements` halvings or max_iterations evaluations.
  template <class Grid>
  MatchResult match(const Grid& grid, const ScanPoints& points, const Pose2& initial) const;

  /// Improved proposal around `mode` (normally match().pose): samples x_j on the proposal grid,
  /// weights w_j = p(z | m, x_j) · N(x_j; prior_mean, prior_cov) (angle differences wrapped),
  /// returns their weighted mean and covariance and log Σ w_j. prior_cov must be symmetric
  /// positive semi-definite (tiny eigenvalues are raised to 1e-12); throws
  /// std::invalid_argument otherwise or for non-finite poses.
  template <class Grid>
  ProposalFit fitProposal(const Grid& grid, const ScanPoints& points, const Pose2& mode,
                          const Pose2& prior_mean, const Eigen::Matrix3d& prior_cov) const;

 private:
  // Most poses evaluateRows() takes in one pass over the beams (the whole default proposal
  // grid, 27, fits), and most window rows it reads at once for such a group.
  static constexpr int kMaxGroup = 32;
  static constexpr int kMaxRows = 64;

  // The evaluation machinery behind the templates above; documented where it is defined, in
  // src/scan_matcher_impl.hpp.
  struct Eval;
  struct KernelTerms;
  template <class Grid, bool kScore>
  Eval evaluate(const Grid& grid, const ScanPoints& points, const Pose2& pose) const;
  template <class Grid, bool kScore>
  void evaluateMany(const Grid& grid, const ScanPoints& points, std::span<const Pose2> poses,
                    Eval* out) const;
  template <class Grid>
  bool usesRows(const Grid& grid) const;
  template <class Grid, bool kScore, int kRadius = 0>
  void evaluateRows(const Grid& grid, const ScanPoints& points, const Pose2* poses, int n,
                    Eval* out) const;
  template <class Grid, bool kScore>
  void evaluateRowsAnyRadius(const Grid& grid, const ScanPoints& points, const Pose2* poses, int n,
                             Eval* out) const;
  template <class Grid, bool kScore, bool kHitPoints, bool kBits>
  Eval evaluateBeams(const Grid& grid, const ScanPoints& points, const Pose2& pose) const;
  template <class Grid>
  std::vector<double> sampleLogLikelihood(const Grid& grid, const ScanPoints& points,
                                          const Pose2& centre, const detail::SampleGrid& g) const;
  KernelTerms kernelTerms(double res, int r) const;

  ScanMatcherOptions options_;
  // The (2r+1)² kernel offsets, nearest to the centre cell first: the search stops as soon as
  // no remaining offset can beat the best distance found, which for a beam on a wall is after a
  // handful of cells instead of all of them.
  struct KernelOffset {
    int dx, dy;
    float distance;  // |offset| [cells]
    // Least distance from the centre cell's centre to the square of this or any later cell
    // [cells]: the walk's bound when distances are to points anywhere in a cell (hit points).
    float square_floor;
  };
  std::vector<KernelOffset> kernel_;
};

// Instantiated in the library (scan_matcher_grids.cpp) for the repository's two grids.
#define TESSERA_SCAN_MATCHER_GRID(Grid, prefix)                                                 \
  prefix template double ScanMatcher::score<Grid>(const Grid&, const ScanPoints&, const Pose2&) \
      const;                                                                                    \
  prefix template double ScanMatcher::logLikelihood<Grid>(const Grid&, const ScanPoints&,       \
                                                          const Pose2&, int*) const;            \
  prefix template MatchResult ScanMatcher::match<Grid>(const Grid&, const ScanPoints&,          \
                                                       const Pose2&) const;                     \
  prefix template ProposalFit ScanMatcher::fitProposal<Grid>(                                   \
      const Grid&, const ScanPoints&, const Pose2&, const Pose2&, const Eigen::Matrix3d&) const;
TESSERA_SCAN_MATCHER_GRID(grid::OccupancyGrid, extern)
TESSERA_SCAN_MATCHER_GRID(grid::TiledGrid, extern)

}  // namespace tessera::scan_matching
