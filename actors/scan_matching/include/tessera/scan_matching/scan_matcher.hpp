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
// cell; worldToCell() must agree with that lattice. The templates live in this header.
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
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <stdexcept>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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
/// Grids that can report, per cell, the mean position of the beam endpoints that hit it.
template <class Grid>
concept HitPointGrid = requires(const Grid& g, const Eigen::Vector2i& c) {
  { g.tracksHitPoints() } -> std::convertible_to<bool>;
  { g.hitPoint(c) } -> std::convertible_to<Eigen::Vector2d>;
};

/// Grids that can report a window's occupancy as bit rows (see the header comment).
template <class Grid>
concept OccupancyRowGrid = requires(const Grid& g, std::uint32_t* rows) {
  g.occupancyRows(0, 0, 1, 0.0f, rows);
};

/// floor(t) for the matcher's cell arithmetic, as an int. The SSE2 baseline has no rounding
/// instruction, and std::floor's generic sequence took a tenth of the matcher's time;
/// truncation and a branch-free correction (cells are negative as often as not) give the same
/// value. t is first clamped to ±2²⁹ cells, far beyond any map (27 000 km at 5 cm), so absurd
/// poses give far-away cells rather than overflow.
inline constexpr double kMaxCellIndex = 536870912.0;  // 2^29
inline int floorIndex(double t) {
  t = t < -kMaxCellIndex ? -kMaxCellIndex : t;
  t = t > kMaxCellIndex ? kMaxCellIndex : t;
  const int k = static_cast<int>(t);  // toward zero
  return k - static_cast<int>(t < static_cast<double>(k));
}

/// One beam endpoint e (base frame) at poses k < n, each given as translation (x, y) and the
/// cosine and sine of its heading: the cell of e in the map, relative to the cell whose centre
/// is `centre0` (the nearest lattice point: floorIndex(q + ½), q = (p − centre0)/res in cell
/// units, p = the pose applied to e), and e's offset from that cell's centre [m], in float.
/// The arrays hold an even number of entries at least n (on SSE2 two poses go at a time, with
/// the same operations in the same order as one at a time, hence the same values).
inline void endpointCells(int n, const double* x, const double* y, const double* cos_h,
                          const double* sin_h, double ex, double ey, const Eigen::Vector2d& centre0,
                          double res, int* cell_x, int* cell_y, float* ux, float* uy) {
  const double inv_res = 1.0 / res;
#if defined(__SSE2__)
  const __m128d vex = _mm_set1_pd(ex), vey = _mm_set1_pd(ey);
  const __m128d c0x = _mm_set1_pd(centre0.x()), c0y = _mm_set1_pd(centre0.y());
  const __m128d vinv = _mm_set1_pd(inv_res), vres = _mm_set1_pd(res), half = _mm_set1_pd(0.5);
  const __m128d lo = _mm_set1_pd(-kMaxCellIndex), hi = _mm_set1_pd(kMaxCellIndex);
  const __m128d one = _mm_set1_pd(1.0);
  auto floor2 = [&](__m128d t) {  // floorIndex() of both lanes, as doubles
    t = _mm_min_pd(_mm_max_pd(t, lo), hi);
    const __m128d k = _mm_cvtepi32_pd(_mm_cvttpd_epi32(t));
    return _mm_sub_pd(k, _mm_and_pd(_mm_cmplt_pd(t, k), one));
  };
  for (int k = 0; k < n; k += 2) {
    const __m128d c = _mm_loadu_pd(cos_h + k), s = _mm_loadu_pd(sin_h + k);
    // x + c·ex − s·ey and y + s·ex + c·ey, evaluated left to right as in scalar code.
    const __m128d px =
        _mm_sub_pd(_mm_add_pd(_mm_loadu_pd(x + k), _mm_mul_pd(c, vex)), _mm_mul_pd(s, vey));
    const __m128d py =
        _mm_add_pd(_mm_add_pd(_mm_loadu_pd(y + k), _mm_mul_pd(s, vex)), _mm_mul_pd(c, vey));
    const __m128d qx = _mm_mul_pd(_mm_sub_pd(px, c0x), vinv);
    const __m128d qy = _mm_mul_pd(_mm_sub_pd(py, c0y), vinv);
    const __m128d fx = floor2(_mm_add_pd(qx, half)), fy = floor2(_mm_add_pd(qy, half));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cell_x + k), _mm_cvttpd_epi32(fx));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cell_y + k), _mm_cvttpd_epi32(fy));
    _mm_storel_pi(reinterpret_cast<__m64*>(ux + k),
                  _mm_cvtpd_ps(_mm_mul_pd(_mm_sub_pd(qx, fx), vres)));
    _mm_storel_pi(reinterpret_cast<__m64*>(uy + k),
                  _mm_cvtpd_ps(_mm_mul_pd(_mm_sub_pd(qy, fy), vres)));
  }
#else
  for (int k = 0; k < n; ++k) {
    const double c = cos_h[k], s = sin_h[k];
    const double px = x[k] + c * ex - s * ey, py = y[k] + s * ex + c * ey;
    const double qx = (px - centre0.x()) * inv_res, qy = (py - centre0.y()) * inv_res;
    cell_x[k] = floorIndex(qx + 0.5);
    cell_y[k] = floorIndex(qy + 0.5);
    ux[k] = static_cast<float>((qx - cell_x[k]) * res);
    uy[k] = static_cast<float>((qy - cell_y[k]) * res);
  }
#endif
}

/// Index of the lowest / highest set bit of a non-zero word: one instruction, where
/// std::countr_zero / countl_zero add a test for zero on the x86-64 baseline.
inline int lowestBit(std::uint32_t nonzero) {
#if defined(__GNUC__)
  return __builtin_ctz(nonzero);
#else
  return std::countr_zero(nonzero);
#endif
}
inline int highestBit(std::uint32_t nonzero) {
#if defined(__GNUC__)
  return 31 - __builtin_clz(nonzero);
#else
  return 31 - std::countl_zero(nonzero);
#endif
}

/// A regular grid of (2·steps+1)³ poses around a centre, `linear` [m] and `angular` [rad] apart.
struct SampleGrid {
  double linear, angular;
  int steps;
  int size() const { return (2 * steps + 1) * (2 * steps + 1) * (2 * steps + 1); }
  /// Sample k's offset from the centre in steps, x slowest, θ fastest.
  Eigen::Vector3i index(int k) const;
  /// Sample k around `centre`.
  Pose2 at(const Pose2& centre, int k) const;
};
inline SampleGrid proposalGrid(const ScanMatcherOptions& o) {
  return {o.proposal_linear, o.proposal_angular, o.proposal_steps};
}
inline SampleGrid covarianceGrid(const ScanMatcherOptions& o) {
  return {o.covariance_linear, o.covariance_angular, o.covariance_steps};
}
/// MatchResult::covariance from logLikelihood() at the covariance samples around the optimum.
Eigen::Matrix3d laplaceCovariance(const SampleGrid& g, std::span<const double> ll);
/// fitProposal() from logLikelihood() at the proposal samples around `mode`.
ProposalFit fitProposalFromSamples(const ScanMatcherOptions& o, std::span<const double> ll,
                                   const Pose2& mode, const Pose2& prior_mean,
                                   const Eigen::Matrix3d& prior_cov);
}  // namespace detail

class ScanMatcher {
 public:
  /// Largest kernel radius read as occupancy rows: the window plus its free-check border,
  /// 2r+3 cells, fits one 32-bit row.
  static constexpr int kMaxBitRadius = 14;
  /// Most poses evaluated in one pass over the beams (see evaluateRows()): the whole default
  /// proposal grid (27).
  static constexpr int kMaxGroup = 32;
  /// Most window rows evaluateRows() reads at once for a group (plus a one-cell border where
  /// the free-check cells of the windows' edges lie, |back| ≤ 1 per axis there).
  static constexpr int kMaxRows = 64;

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
  double score(const Grid& grid, const ScanPoints& points, const Pose2& robot_pose) const {
    return evaluate<Grid, true>(grid, points, robot_pose).score;
  }

  /// log p(z | m, x) up to a constant, flattened by likelihood_gain; ≤ 0.
  template <class Grid>
  double logLikelihood(const Grid& grid, const ScanPoints& points, const Pose2& robot_pose,
                       int* matched = nullptr) const {
    const Eval e = evaluate<Grid, false>(grid, points, robot_pose);
    if (matched) *matched = e.matched;
    return e.log_likelihood;
  }

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
  struct Eval {
    double score = 0;
    double log_likelihood = 0;
    int matched = 0;
  };
  template <class Grid, bool kScore>
  Eval evaluate(const Grid& grid, const ScanPoints& points, const Pose2& pose) const;
  /// evaluate() at every pose: out[k] for poses[k], the same values, bit for bit. On occupancy
  /// row grids the poses are evaluated kMaxGroup at a time by evaluateRows().
  template <class Grid, bool kScore>
  void evaluateMany(const Grid& grid, const ScanPoints& points, std::span<const Pose2> poses,
                    Eval* out) const;
  /// True when `grid` is read as occupancy rows by evaluateRows() (see the header comment).
  template <class Grid>
  bool usesRows(const Grid& grid) const;
  /// evaluate() at n ≤ kMaxGroup finite poses in one pass over the beams, for occupancy row
  /// grids without hit points. Poses a matcher compares (hill-climbing moves, proposal samples)
  /// are close, so a beam's endpoints at them mostly fall within a few cells of each other:
  /// per beam the poses are split into clusters whose windows fit one read of rows, and each
  /// cluster's rows are read once, and its free-check pass done once per free-check direction,
  /// instead of once per pose. Each pose still gets exactly what a pass of its own would.
  /// kRadius > 0 fixes the kernel radius at compile time (it must equal the option), so the row
  /// loops unroll.
  template <class Grid, bool kScore, int kRadius = 0>
  void evaluateRows(const Grid& grid, const ScanPoints& points, const Pose2* poses, int n,
                    Eval* out) const;
  /// evaluateRows() with the RBPF's fine and coarse radii unrolled (the bulk of its time).
  template <class Grid, bool kScore>
  void evaluateRowsAnyRadius(const Grid& grid, const ScanPoints& points, const Pose2* poses, int n,
                             Eval* out) const;
  /// evaluate() with d measured to cell centres or (kHitPoints) to the grid's hit points, and
  /// candidates read from occupancy rows (kBits, hit points only) or cell by cell.
  template <class Grid, bool kScore, bool kHitPoints, bool kBits>
  Eval evaluateBeams(const Grid& grid, const ScanPoints& points, const Pose2& pose) const;
  template <class Grid>
  std::vector<double> sampleLogLikelihood(const Grid& grid, const ScanPoints& points,
                                          const Pose2& centre, const detail::SampleGrid& g) const;

  /// Per-evaluation constants of the score kernel and free check, for grid resolution `res` and
  /// kernel radius r [cells].
  struct KernelTerms {
    float resf, big_r2;  // resolution; squared kernel reach R = (r + ½) cells [m²]
    bool free_check;
    double free_cells, quarter_inv_free2;  // free-check offset [cells]; ¼ / free_cells²
    // Score kernel rescaled so that d = 0 gives 1 and d = R gives 0.
    float inv_two_sigma2, kernel_floor, kernel_scale;
    double no_hit_extra;  // D² − R² [m²]: added to d² for each unmatched beam
  };
  KernelTerms kernelTerms(double res, int r) const {
    KernelTerms k;
    k.resf = static_cast<float>(res);
    const float big_r = (static_cast<float>(r) + 0.5f) * k.resf;
    k.big_r2 = big_r * big_r;
    k.free_check = options_.free_check_offset >= 0.0;
    k.free_cells = std::max(options_.free_check_offset / res, std::numbers::sqrt2);
    k.quarter_inv_free2 = 0.25 / (k.free_cells * k.free_cells);
    k.inv_two_sigma2 = static_cast<float>(1.0 / (2.0 * options_.sigma * options_.sigma));
    k.kernel_floor = std::exp(-k.big_r2 * k.inv_two_sigma2);
    k.kernel_scale = 1.0f / (1.0f - k.kernel_floor);
    k.no_hit_extra =
        std::max(options_.no_hit_distance * options_.no_hit_distance - double{k.big_r2}, 0.0);
    return k;
  }

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

// ---- template definitions ----

template <class Grid>
bool ScanMatcher::usesRows(const Grid& grid) const {
  if constexpr (detail::OccupancyRowGrid<Grid>) {
    if constexpr (detail::HitPointGrid<Grid>) {
      if (grid.tracksHitPoints()) return false;
    }
    const bool near_free_check =
        options_.free_check_offset < 0.0 || options_.free_check_offset / grid.resolution() < 1.5;
    return options_.kernel_radius <= kMaxBitRadius && near_free_check;
  } else {
    return false;
  }
}

template <class Grid, bool kScore>
ScanMatcher::Eval ScanMatcher::evaluate(const Grid& grid, const ScanPoints& points,
                                        const Pose2& pose) const {
  if constexpr (detail::OccupancyRowGrid<Grid>) {
    if (usesRows(grid)) {
      Eval out;
      if (!points.empty() && pose.isFinite())
        evaluateRowsAnyRadius<Grid, kScore>(grid, points, &pose, 1, &out);
      return out;
    }
    const bool near_free_check =
        options_.free_check_offset < 0.0 || options_.free_check_offset / grid.resolution() < 1.5;
    if constexpr (detail::HitPointGrid<Grid>) {
      if (grid.tracksHitPoints() && options_.kernel_radius <= kMaxBitRadius && near_free_check)
        return evaluateBeams<Grid, kScore, true, true>(grid, points, pose);
    }
  }
  if constexpr (detail::HitPointGrid<Grid>) {
    if (grid.tracksHitPoints()) return evaluateBeams<Grid, kScore, true, false>(grid, points, pose);
  }
  return evaluateBeams<Grid, kScore, false, false>(grid, points, pose);
}

template <class Grid, bool kScore>
void ScanMatcher::evaluateMany(const Grid& grid, const ScanPoints& points,
                               std::span<const Pose2> poses, Eval* out) const {
  const std::size_t n = poses.size();
  if (!usesRows(grid) || n < 2 || points.empty()) {
    for (std::size_t k = 0; k < n; ++k) out[k] = evaluate<Grid, kScore>(grid, points, poses[k]);
    return;
  }
  if constexpr (detail::OccupancyRowGrid<Grid>) {
    // Non-finite poses evaluate to nothing, as in evaluate().
    Pose2 group[kMaxGroup];
    std::size_t index[kMaxGroup];
    Eval result[kMaxGroup];
    int size = 0;
    for (std::size_t k = 0; k < n; ++k) {
      if (poses[k].isFinite()) {
        group[size] = poses[k];
        index[size++] = k;
      } else {
        out[k] = Eval{};
      }
      if (size == kMaxGroup || (k + 1 == n && size > 0)) {
        evaluateRowsAnyRadius<Grid, kScore>(grid, points, group, size, result);
        for (int g = 0; g < size; ++g) out[index[g]] = result[g];
        size = 0;
      }
    }
  }
}

template <class Grid, bool kScore>
void ScanMatcher::evaluateRowsAnyRadius(const Grid& grid, const ScanPoints& points,
                                        const Pose2* poses, int n, Eval* out) const {
  switch (options_.kernel_radius) {
    case 1:
      return evaluateRows<Grid, kScore, 1>(grid, points, poses, n, out);
    case 4:
      return evaluateRows<Grid, kScore, 4>(grid, points, poses, n, out);
    default:
      return evaluateRows<Grid, kScore>(grid, points, poses, n, out);
  }
}

template <class Grid, bool kScore, int kRadius>
void ScanMatcher::evaluateRows(const Grid& grid, const ScanPoints& points, const Pose2* poses,
                               int n, Eval* out) const {
  const double res = grid.resolution();
  const int r = kRadius > 0 ? kRadius : options_.kernel_radius;
  const KernelTerms kt = kernelTerms(res, r);
  const float threshold = options_.occupied_threshold;

  // The lattice is regular, so cells are found by arithmetic from one reference centre instead
  // of a worldToCell/cellCenter call pair per beam.
  const Eigen::Vector2d centre0 = grid.cellCenter(Eigen::Vector2i::Zero());
  // The poses ordered by heading (stable), so that per beam the free-check direction is found,
  // and a cluster's free-check pass made, once per heading: out[order[p]] is sorted pose p's.
  int order[kMaxGroup];
  for (int p = 0; p < n; ++p) {
    int k = p;
    for (; k > 0 && poses[order[k - 1]].theta > poses[p].theta; --k) order[k] = order[k - 1];
    order[k] = p;
  }
  // Padded to an even count for detail::endpointCells() with a copy of the last pose.
  double pose_x[kMaxGroup], pose_y[kMaxGroup], cos_p[kMaxGroup], sin_p[kMaxGroup];
  bool new_heading[kMaxGroup];
  for (int p = 0; p < n; ++p) {
    const Pose2& pose = poses[order[p]];
    pose_x[p] = pose.x;
    pose_y[p] = pose.y;
    new_heading[p] = p == 0 || pose.theta != poses[order[p - 1]].theta;
    cos_p[p] = std::cos(pose.theta);
    sin_p[p] = std::sin(pose.theta);
  }
  if (n % 2 != 0) {
    pose_x[n] = pose_x[n - 1];
    pose_y[n] = pose_y[n - 1];
    cos_p[n] = cos_p[n - 1];
    sin_p[n] = sin_p[n - 1];
  }
  const Eigen::Vector2f o = points.origin;
  // Candidate bits of window rows: bit dx + r + 1 of a pose's row dy + r (bit 0 is the border).
  const std::uint32_t window = ((std::uint32_t{1} << (2 * r + 1)) - 1) << 1;
  const int centre = r + 1;  // bit of dx = 0
  const std::uint32_t below = (std::uint32_t{1} << centre) - 1;
  const std::uint32_t all = n == 32 ? ~std::uint32_t{0} : (std::uint32_t{1} << n) - 1;
  // Cell offsets [m] as floats, k·resolution for k in [−32, 32) (row and column offsets of the
  // window, and the bit scans' sentinels): looked up rather than converted per row.
  float offset_table[64];
  for (int k = 0; k < 64; ++k) offset_table[k] = static_cast<float>(k - 32) * kt.resf;
  const float* offset = offset_table + 32;

  double d2_sum[kMaxGroup] = {}, score_sum[kMaxGroup] = {};
  int matched[kMaxGroup] = {};
  for (const Eigen::Vector2f& e : points.endpoints) {
    const double ex = e.x(), ey = e.y();
    // Per pose: the endpoint's cell (the nearest lattice point to it in cell units relative to
    // the reference centre), the (small, so float is plenty) offset from that cell's centre,
    // and the free-check direction back. Here free_cells < 1.5, so each component of back =
    // round(−free_cells·d/|b|) is −1, 0 or 1, decided by comparing squares: no square root or
    // division per beam. back is kept as (back_x + 1) + 3·(back_y + 1), 4 = none.
    const double bx = ex - o.x(), by = ey - o.y();
    const double limit = (bx * bx + by * by) * kt.quarter_inv_free2;  // (½·|b|/free_cells)²
    const bool check = kt.free_check && limit > 0.0;
    auto component = [limit](double d) {  // floor(x + ½) for x = −free_cells·d/|b|
      // Branch-free: the signs of beam directions do not follow a pattern.
      const double d2 = d * d;
      return static_cast<int>((d < 0.0) & (d2 >= limit)) -
             static_cast<int>(!(d < 0.0) & (d2 > limit));
    };
    // The free-check direction, once per heading.
    int back[kMaxGroup];
    int heading_back = 4;
    for (int p = 0; p < n; ++p) {
      if (new_heading[p])
        heading_back = check ? component(cos_p[p] * bx - sin_p[p] * by) + 1 +
                                   3 * (component(sin_p[p] * bx + cos_p[p] * by) + 1)
                             : 4;
      back[p] = heading_back;
    }
    int cell_x[kMaxGroup], cell_y[kMaxGroup];
    float ux[kMaxGroup], uy[kMaxGroup];
    detail::endpointCells(n, pose_x, pose_y, cos_p, sin_p, ex, ey, centre0, res, cell_x, cell_y, ux,
                          uy);
    // Rows of the current cluster's windows plus a one-cell border, where the free-check cells
    // of the windows' edges lie (|back| ≤ 1 per axis here), and their candidate bits: the cells
    // above the threshold whose free-check cell is not, for the direction cand_back.
    std::uint32_t occ[kMaxRows + 2], cand[kMaxRows];
    // d² to the nearest candidate of the window whose rows start at rows_in[0], shifted right by
    // `shift` bits; R² when there is none. Per window row the nearest candidate to e is the one
    // nearest in x, i.e. the first set bit on either side of e's column; taking it from bit
    // scans avoids a walk's unpredictable branches. A side without candidates yields an offset
    // beyond the window (d > R), which the minimum ignores.
    auto nearest = [&](const std::uint32_t* rows_in, int shift, float u_x, float u_y) {
      float best = kt.big_r2;
      auto scanRow = [&](int i, std::uint32_t row) {
        // Sentinel bits make both scans branch-free: with no candidate right of e, right =
        // 31 (d > R as r ≤ 14); with none left, left = −1 − centre.
        const int right = detail::lowestBit((row >> centre) | 0x80000000u);           // dx ≥ 0
        const int left = detail::highestBit(((row & below) << 1) | 1u) - 1 - centre;  // dx < 0
        const float ry = u_y - offset[i - r];
        const float rr = u_x - offset[right];
        const float rl = u_x - offset[left];
        best = std::min(best, std::min(rr * rr + ry * ry, rl * rl + ry * ry));
      };
      // Most rows of a window are empty (walls are thin), so only non-empty ones are scanned.
      std::uint32_t rows[2 * kMaxBitRadius + 1];
      std::uint32_t nonempty = 0;
      for (int i = 0; i <= 2 * r; ++i) {
        rows[i] = (rows_in[i] >> shift) & window;
        nonempty |= static_cast<std::uint32_t>(rows[i] != 0) << i;
      }
      for (; nonempty != 0; nonempty &= nonempty - 1) {
        const int i = std::countr_zero(nonempty);
        scanRow(i, rows[i]);
      }
      return best;
    };
    float best[kMaxGroup];
    // Clusters: from the first pose left, every remaining pose whose window keeps the cluster's
    // rows within 32 bits (window and border) and kMaxRows rows. A pose's window starts
    // cell_x − min_x bits and cell_y − min_y rows into the cluster's.
    for (std::uint32_t left = all; left != 0;) {
      const int seed = std::countr_zero(left);
      int min_x = cell_x[seed], max_x = min_x, min_y = cell_y[seed], max_y = min_y;
      std::uint32_t members = 0;
      for (std::uint32_t rest = left; rest != 0; rest &= rest - 1) {
        const int p = std::countr_zero(rest);
        const int x0 = std::min(min_x, cell_x[p]), x1 = std::max(max_x, cell_x[p]);
        const int y0 = std::min(min_y, cell_y[p]), y1 = std::max(max_y, cell_y[p]);
        if (x1 - x0 + 2 * r + 3 > 32 || y1 - y0 + 2 * r + 1 > kMaxRows) continue;
        min_x = x0, max_x = x1, min_y = y0, max_y = y1;
        members |= std::uint32_t{1} << p;
      }
      left &= ~members;
      const int height = max_y - min_y + 2 * r + 1;
      grid.occupancyRows(min_x - r - 1, min_y - r - 1, height + 2, threshold, occ);
      int cand_back = -1;
      for (; members != 0; members &= members - 1) {
        const int p = std::countr_zero(members);
        if (back[p] != cand_back) {
          cand_back = back[p];
          // Branch-free: a cell is blocked when its free-check cell, one row up/down and one
          // bit right/left, is occupied.
          const int back_x = cand_back % 3 - 1, back_y = cand_back / 3 - 1;
          const int back_right = back_x > 0, back_left = back_x < 0;
          const std::uint32_t back_mask = cand_back != 4 ? ~std::uint32_t{0} : 0u;
          for (int i = 0; i < height; ++i) {
            const std::uint32_t behind = occ[i + 1 + back_y];
            const std::uint32_t blocked = ((behind >> back_right) << back_left) & back_mask;
            cand[i] = occ[i + 1] & ~blocked;
          }
        }
        best[p] = nearest(cand + (cell_y[p] - min_y), cell_x[p] - min_x, ux[p], uy[p]);
      }
    }
    for (int p = 0; p < n; ++p) {
      if (best[p] < kt.big_r2) ++matched[p];
      d2_sum[p] += best[p];
      // An unmatched beam adds exactly 0 to the score, so its exp() is skipped.
      if constexpr (kScore)
        if (best[p] < kt.big_r2)
          score_sum[p] +=
              (std::exp(-best[p] * kt.inv_two_sigma2) - kt.kernel_floor) * kt.kernel_scale;
    }
  }
  for (int p = 0; p < n; ++p) {
    Eval& e = out[order[p]];
    e.score = score_sum[p];
    const double unmatched = static_cast<double>(points.endpoints.size()) - matched[p];
    e.log_likelihood =
        -(d2_sum[p] + unmatched * kt.no_hit_extra) /
        (2.0 * options_.likelihood_sigma * options_.likelihood_sigma * options_.likelihood_gain);
    e.matched = matched[p];
  }
}

template <class Grid, bool kScore, bool kHitPoints, bool kBits>
ScanMatcher::Eval ScanMatcher::evaluateBeams(const Grid& grid, const ScanPoints& points,
                                             const Pose2& pose) const {
  Eval out;
  if (points.empty() || !pose.isFinite()) return out;
  const double res = grid.resolution();
  const int r = options_.kernel_radius;
  const KernelTerms kt = kernelTerms(res, r);
  const float threshold = options_.occupied_threshold;

  // The lattice is regular, so cells are found by arithmetic from one reference centre instead
  // of a worldToCell/cellCenter call pair per beam.
  const Eigen::Vector2d centre0 = grid.cellCenter(Eigen::Vector2i::Zero());
  const double inv_res = 1.0 / res;
  const double c = std::cos(pose.theta), s = std::sin(pose.theta);
  const Eigen::Vector2f o = points.origin;
  double d2_sum = 0.0, score_sum = 0.0;
  for (const Eigen::Vector2f& e : points.endpoints) {
    const double ex = e.x(), ey = e.y();
    // Endpoint in cell units relative to the reference centre; its cell is the nearest lattice
    // point, and the remainder is the (small, so float is plenty) offset from that cell centre.
    const double px = pose.x + c * ex - s * ey, py = pose.y + s * ex + c * ey;  // map [m]
    const double qx = (px - centre0.x()) * inv_res;
    const double qy = (py - centre0.y()) * inv_res;
    const double fx = std::floor(qx + 0.5), fy = std::floor(qy + 0.5);
    const Eigen::Vector2i cell(static_cast<int>(fx), static_cast<int>(fy));
    const float ux = static_cast<float>((qx - fx) * res);
    const float uy = static_cast<float>((qy - fy) * res);
    Eigen::Vector2i back(0, 0);
    if constexpr (kBits) {
      // Here free_cells < 1.5, so each component of back = round(−free_cells·d/|b|) is −1, 0
      // or 1, decided by comparing squares: no square root or division per beam.
      if (kt.free_check) {
        const double bx = ex - o.x(), by = ey - o.y();
        const double limit = (bx * bx + by * by) * kt.quarter_inv_free2;  // (½·|b|/free_cells)²
        auto component = [limit](double d) {  // floor(x + ½) for x = −free_cells·d/|b|
          // Branch-free: the signs of beam directions do not follow a pattern.
          const double d2 = d * d;
          return static_cast<int>((d < 0.0) & (d2 >= limit)) -
                 static_cast<int>(!(d < 0.0) & (d2 > limit));
        };
        if (limit > 0.0) back = {component(c * bx - s * by), component(s * bx + c * by)};
      }
    } else if (kt.free_check) {
      const double bx = ex - o.x(), by = ey - o.y();
      const double norm = std::sqrt(bx * bx + by * by);
      if (norm > 0.0) {
        const double k = -kt.free_cells / norm;  // against the beam
        back = {static_cast<int>(std::floor(k * (c * bx - s * by) + 0.5)),
                static_cast<int>(std::floor(k * (s * bx + c * by) + 0.5))};
      }
    }
    const bool check_back = kt.free_check && back != Eigen::Vector2i::Zero();
    // kBits: candidate bits of the window, row dy + r, bit dx + r + 1 (bit 0 is the border).
    std::uint32_t occ[kBits ? 2 * kMaxBitRadius + 3 : 1];
    std::uint32_t cand_rows[kBits && kHitPoints ? 2 * kMaxBitRadius + 1 : 1];
    std::uint32_t any_candidate = 1;
    const std::uint32_t window = ((std::uint32_t{1} << (2 * r + 1)) - 1) << 1;
    // Branch-free (back varies from beam to beam): a cell is blocked when its free-check cell,
    // one row up/down and one bit right/left, is occupied.
    const int back_right = back.x() > 0, back_left = back.x() < 0;
    const std::uint32_t back_mask = check_back ? ~std::uint32_t{0} : 0u;
    auto candidateRow = [&](int i) {
      const std::uint32_t behind = occ[i + 1 + back.y()];
      const std::uint32_t blocked = ((behind >> back_right) << back_left) & back_mask;
      return occ[i + 1] & ~blocked & window;
    };
    if constexpr (kBits) {
      // Rows of the window plus a one-cell border, where the free-check cells of the window's
      // edge lie (|back| ≤ 1 per axis here).
      grid.occupancyRows(cell.x() - r - 1, cell.y() - r - 1, 2 * r + 3, threshold, occ);
      if constexpr (kHitPoints) {
        any_candidate = 0;
        for (int i = 0; i <= 2 * r; ++i) any_candidate |= cand_rows[i] = candidateRow(i);
      }
    }
    auto candidate = [&](int dx, int dy) {
      if constexpr (kBits) {
        return ((cand_rows[dy + r] >> (dx + r + 1)) & 1u) != 0;
      } else {
        const Eigen::Vector2i cand(cell.x() + dx, cell.y() + dy);
        return grid.logOdds(cand) > threshold &&
               !(check_back && grid.logOdds(Eigen::Vector2i(cand + back)) > threshold);
      }
    };
    // Nearest offsets first (the endpoint's own cell leads): at a good pose the first few
    // cells hold the answer, and the lower bound then ends the walk without touching the rest.
    float best = kt.big_r2;
    const float u_norm = std::sqrt(ux * ux + uy * uy);
    if (any_candidate == 0) {
      // Nothing in the window: d = R without a walk.
    } else if constexpr (kHitPoints) {
      // A hit point may lie anywhere in its cell, so the bound is the distance to the nearest
      // remaining cell square rather than centre (at most √½ cell less).
      const float half = 0.5f * kt.resf;
      for (const KernelOffset& k : kernel_) {
        const float lower = k.square_floor * kt.resf - u_norm;
        if (lower > 0.0f && lower * lower >= best) break;
        // Distance from e to the cell's square: no hit point of the cell can be nearer, so a
        // cell that cannot improve on best is skipped before any lookup.
        const float bx = std::max(std::abs(ux - static_cast<float>(k.dx) * kt.resf) - half, 0.0f);
        const float by = std::max(std::abs(uy - static_cast<float>(k.dy) * kt.resf) - half, 0.0f);
        if (bx * bx + by * by >= best || !candidate(k.dx, k.dy)) continue;
        const Eigen::Vector2d h = grid.hitPoint(Eigen::Vector2i(cell.x() + k.dx, cell.y() + k.dy));
        const float rx = static_cast<float>(px - h.x()), ry = static_cast<float>(py - h.y());
        best = std::min(best, rx * rx + ry * ry);
      }
    } else {
      for (const KernelOffset& k : kernel_) {
        const float lower = k.distance * kt.resf - u_norm;
        if (lower > 0.0f && lower * lower >= best) break;
        const float rx = ux - static_cast<float>(k.dx) * kt.resf;
        const float ry = uy - static_cast<float>(k.dy) * kt.resf;
        const float d2 = rx * rx + ry * ry;
        if (d2 < best && candidate(k.dx, k.dy)) best = d2;
      }
    }
    if (best < kt.big_r2) ++out.matched;
    d2_sum += best;
    // An unmatched beam adds exactly 0 to the score, so its exp() is skipped.
    if constexpr (kScore)
      if (best < kt.big_r2)
        score_sum += (std::exp(-best * kt.inv_two_sigma2) - kt.kernel_floor) * kt.kernel_scale;
  }
  out.score = score_sum;
  const double unmatched = static_cast<double>(points.endpoints.size()) - out.matched;
  out.log_likelihood =
      -(d2_sum + unmatched * kt.no_hit_extra) /
      (2.0 * options_.likelihood_sigma * options_.likelihood_sigma * options_.likelihood_gain);
  return out;
}

template <class Grid>
std::vector<double> ScanMatcher::sampleLogLikelihood(const Grid& grid, const ScanPoints& points,
                                                     const Pose2& centre,
                                                     const detail::SampleGrid& g) const {
  const std::size_t n = static_cast<std::size_t>(g.size());
  std::vector<Pose2> poses(n);
  for (std::size_t k = 0; k < n; ++k) poses[k] = g.at(centre, static_cast<int>(k));
  std::vector<Eval> evals(n);
  evaluateMany<Grid, false>(grid, points, poses, evals.data());
  std::vector<double> ll(n);
  for (std::size_t k = 0; k < n; ++k) ll[k] = evals[k].log_likelihood;
  return ll;
}

template <class Grid>
MatchResult ScanMatcher::match(const Grid& grid, const ScanPoints& points,
                               const Pose2& initial) const {
  MatchResult result;
  result.pose = initial;
  if (points.empty() || !initial.isFinite()) return result;

  Pose2 pose = initial;
  // The score pass also yields the likelihood and matched count, kept for the best pose so
  // the result needs no extra pass.
  Eval best = evaluate<Grid, true>(grid, points, pose);
  int evaluations = 1;
  double linear = options_.linear_step, angular = options_.angular_step;
  int halvings = 0;
  int back_move = -1;
  // The last poses scored. One of them can never be chosen again: it scored no higher than
  // the best of its round, and best only grows while a move must beat it strictly. After a
  // halving, two half steps the same way often land exactly on a pose of the level before, so
  // such moves are skipped like the move back (and still counted).
  constexpr int kRecent = 32;
  Pose2 recent[kRecent];
  int recent_count = 0;
  auto seen = [&](const Pose2& q) {
    for (int k = 0; k < std::min(recent_count, kRecent); ++k)
      if (recent[k].x == q.x && recent[k].y == q.y && recent[k].theta == q.theta) return true;
    return false;
  };
  while (evaluations < options_.max_iterations) {
    const Pose2 moves[6] = {
        {pose.x + linear, pose.y, pose.theta},  {pose.x - linear, pose.y, pose.theta},
        {pose.x, pose.y + linear, pose.theta},  {pose.x, pose.y - linear, pose.theta},
        {pose.x, pose.y, pose.theta + angular}, {pose.x, pose.y, pose.theta - angular}};
    // The moves within the evaluation cap, scored together (evaluateMany() shares the map
    // reads of nearby poses), then compared in order.
    Pose2 tried[6];
    int tried_move[6];
    int count = 0;
    for (int m = 0; m < 6 && evaluations < options_.max_iterations; ++m) {
      ++evaluations;
      // The move back to where the last step came from scored below the current best, so it
      // cannot be chosen and is not recomputed (it still counts, keeping max_iterations' cap
      // where it was).
      if (m == back_move || seen(moves[m])) continue;
      tried[count] = moves[m];
      tried_move[count++] = m;
    }
    Eval evals[6];
    evaluateMany<Grid, true>(grid, points, std::span<const Pose2>(tried, count), evals);
    for (int k = 0; k < count; ++k) recent[recent_count++ % kRecent] = tried[k];
    int chosen = -1;
    for (int k = 0; k < count; ++k) {
      if (evals[k].score > best.score) {
        best = evals[k];
        chosen = tried_move[k];
      }
    }
    back_move = -1;
    if (chosen >= 0) {
      pose = moves[chosen];
      back_move = chosen ^ 1;  // moves come in ± pairs
    } else {
      if (++halvings > options_.refinements) break;
      linear *= 0.5;
      angular *= 0.5;
    }
  }

  result.pose = pose;
  result.score = best.score;
  result.evaluations = evaluations;
  result.log_likelihood = best.log_likelihood;
  result.matched_beams = best.matched;
  result.success =
      result.matched_beams > 0 &&
      result.matched_beams >= options_.min_score_fraction * static_cast<double>(points.size());
  if (options_.compute_covariance)
    result.covariance = detail::laplaceCovariance(
        detail::covarianceGrid(options_),
        sampleLogLikelihood(grid, points, pose, detail::covarianceGrid(options_)));
  return result;
}

template <class Grid>
ProposalFit ScanMatcher::fitProposal(const Grid& grid, const ScanPoints& points, const Pose2& mode,
                                     const Pose2& prior_mean,
                                     const Eigen::Matrix3d& prior_cov) const {
  if (!mode.isFinite())
    throw std::invalid_argument("ScanMatcher::fitProposal: non-finite mode pose");
  return detail::fitProposalFromSamples(
      options_, sampleLogLikelihood(grid, points, mode, detail::proposalGrid(options_)), mode,
      prior_mean, prior_cov);
}

}  // namespace tessera::scan_matching
