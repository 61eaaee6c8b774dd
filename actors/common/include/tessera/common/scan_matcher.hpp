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
//                    (an unmatched beam costs −R²/(2·likelihood_sigma²)/likelihood_gain)
// A beam is "matched" when d < R.
//
// Grid: any type providing `double resolution() const`, `Eigen::Vector2i worldToCell(const
// Eigen::Vector2d&) const`, `Eigen::Vector2d cellCenter(const Eigen::Vector2i&) const` and
// `float logOdds(const Eigen::Vector2i&) const` (0 = unknown) on a regular lattice of that
// resolution (OccupancyGrid; the copy-on-write tiled grid). The inner loop locates cells by
// lattice arithmetic from cellCenter({0, 0}) and the resolution, so only logOdds() is called per
// cell; worldToCell() must agree with that lattice. The templates live in this header.
//
// Hit points. A Grid that also provides `bool tracksHitPoints() const` and `Eigen::Vector2d
// hitPoint(const Eigen::Vector2i&) const` (TiledGrid with track_hit_points) and reports true
// is matched GMapping-style: d is measured to the candidate's hitPoint() (the mean endpoint
// that hit it, anywhere inside the cell) instead of its centre, which removes the cell-size
// quantisation of walls. Everything else (candidates, free check, window, R, score and
// likelihood) is unchanged. One difference: a hit point in a cell just outside the window can
// lie closer than R, so d may jump as such a cell enters or leaves the window (at d between
// r·resolution and R); centres never do.
//
// Occupancy rows. A Grid that also provides `void occupancyRows(int x0, int y0, int height,
// float threshold, std::uint32_t* rows) const` (bit j of rows[i] set iff logOdds({x0 + j, y0 +
// i}) > threshold; TiledGrid, which caches these bits per tile) is read a window at a time: the
// candidates of a beam's window are found with a few word operations on 2r+3 rows instead of up
// to 2·(2r+1)² logOdds() calls, and a beam whose window holds no candidate skips the walk. The
// result is the same, bit for bit, except that the free-check direction is found by comparing
// squares rather than rounding a quotient, which could differ only for a beam exactly on a
// rounding boundary. Used when r ≤ kMaxBitRadius and the free-check offset is under 1.5 cells
// (the default √2 cells is), so the free-check cell is a neighbour.
//
// A ScanMatcher holds only its options: all methods are const, allocate nothing per score
// evaluation and may be called concurrently on grids nobody is writing.
#pragma once

#include <tessera/common/occupancy_grid.hpp>
#include <tessera/common/pose2.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <span>
#include <stdexcept>
#include <vector>

namespace tessera::common {

struct ScanMatcherOptions {
  double max_range = 30.0;  ///< [m] returns farther than this are not used for matching
  int beam_step = 1;        ///< use every n-th valid beam (≥ 1)
  int kernel_radius = 1;    ///< [cells] r: the search window is (2r+1)² cells around an endpoint
  double sigma = 0.05;  ///< [m] σ of the score kernel exp(−d²/2σ²) (see the header comment)
  double likelihood_sigma = 0.075;  ///< [m] σ of the per-beam log-likelihood −d²/2σ²
  /// The log-likelihood is divided by this (GMapping's lgain): beams are not independent, so
  /// their product is overconfident; flattening it keeps particle weights from collapsing.
  double likelihood_gain = 3.0;
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
  /// Score evaluations spent hill climbing (not covariance), counting the move back to the
  /// previous pose that is skipped rather than recomputed.
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

  /// Throws std::invalid_argument naming the first bad option.
  explicit ScanMatcher(ScanMatcherOptions o = {});

  const ScanMatcherOptions& options() const { return options_; }

  /// Endpoints of the usable beams of `scan` in the base frame; `mount` is the laser pose in the
  /// base frame. Drops NaN, < range_min, ≤ 0, no-return (+inf or ≥ range_max) and > max_range
  /// beams, then keeps every beam_step-th of the rest. A scan with non-finite angles or mount
  /// gives no endpoints.
  ScanPoints prepare(const RangeScan& scan, const Pose2& mount) const;

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
  /// evaluate() with d measured to cell centres or (kHitPoints) to the grid's hit points, and
  /// candidates read from occupancy rows (kBits) or cell by cell. kRadius > 0 fixes the kernel
  /// radius at compile time (it must equal the option), so the row loops unroll.
  template <class Grid, bool kScore, bool kHitPoints, bool kBits, int kRadius = 0>
  Eval evaluateBeams(const Grid& grid, const ScanPoints& points, const Pose2& pose) const;
  template <class Grid>
  std::vector<double> sampleLogLikelihood(const Grid& grid, const ScanPoints& points,
                                          const Pose2& centre, const detail::SampleGrid& g) const;

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

template <class Grid, bool kScore>
ScanMatcher::Eval ScanMatcher::evaluate(const Grid& grid, const ScanPoints& points,
                                        const Pose2& pose) const {
  if constexpr (detail::OccupancyRowGrid<Grid>) {
    const bool near_free_check =
        options_.free_check_offset < 0.0 || options_.free_check_offset / grid.resolution() < 1.5;
    if (options_.kernel_radius <= kMaxBitRadius && near_free_check) {
      if constexpr (detail::HitPointGrid<Grid>) {
        if (grid.tracksHitPoints())
          return evaluateBeams<Grid, kScore, true, true>(grid, points, pose);
      }
      // The RBPF's fine and coarse radii, unrolled: the bulk of its time.
      switch (options_.kernel_radius) {
        case 1:
          return evaluateBeams<Grid, kScore, false, true, 1>(grid, points, pose);
        case 4:
          return evaluateBeams<Grid, kScore, false, true, 4>(grid, points, pose);
        default:
          return evaluateBeams<Grid, kScore, false, true>(grid, points, pose);
      }
    }
  }
  if constexpr (detail::HitPointGrid<Grid>) {
    if (grid.tracksHitPoints()) return evaluateBeams<Grid, kScore, true, false>(grid, points, pose);
  }
  return evaluateBeams<Grid, kScore, false, false>(grid, points, pose);
}

template <class Grid, bool kScore, bool kHitPoints, bool kBits, int kRadius>
ScanMatcher::Eval ScanMatcher::evaluateBeams(const Grid& grid, const ScanPoints& points,
                                             const Pose2& pose) const {
  Eval out;
  if (points.empty() || !pose.isFinite()) return out;
  const double res = grid.resolution();
  const int r = kRadius > 0 ? kRadius : options_.kernel_radius;
  const float resf = static_cast<float>(res);
  const float big_r = (static_cast<float>(r) + 0.5f) * resf;
  const float big_r2 = big_r * big_r;
  const float threshold = options_.occupied_threshold;
  const bool free_check = options_.free_check_offset >= 0.0;
  const double free_cells =
      std::max(options_.free_check_offset / res, std::numbers::sqrt2);  // in cells
  const double quarter_inv_free2 = 0.25 / (free_cells * free_cells);
  // Score kernel rescaled so that d = 0 gives 1 and d = R gives 0.
  const float inv_two_sigma2 = static_cast<float>(1.0 / (2.0 * options_.sigma * options_.sigma));
  const float kernel_floor = std::exp(-big_r2 * inv_two_sigma2);
  const float kernel_scale = 1.0f / (1.0f - kernel_floor);

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
      if (free_check) {
        const double bx = ex - o.x(), by = ey - o.y();
        const double limit = (bx * bx + by * by) * quarter_inv_free2;  // (½·|b|/free_cells)²
        auto component = [limit](double d) {  // floor(x + ½) for x = −free_cells·d/|b|
          return d < 0.0 ? (d * d >= limit ? 1 : 0) : (d * d > limit ? -1 : 0);
        };
        if (limit > 0.0) back = {component(c * bx - s * by), component(s * bx + c * by)};
      }
    } else if (free_check) {
      const double bx = ex - o.x(), by = ey - o.y();
      const double norm = std::sqrt(bx * bx + by * by);
      if (norm > 0.0) {
        const double k = -free_cells / norm;  // against the beam
        back = {static_cast<int>(std::floor(k * (c * bx - s * by) + 0.5)),
                static_cast<int>(std::floor(k * (s * bx + c * by) + 0.5))};
      }
    }
    const bool check_back = free_check && back != Eigen::Vector2i::Zero();
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
    float best = big_r2;
    const float u_norm = std::sqrt(ux * ux + uy * uy);
    if (any_candidate == 0) {
      // Nothing in the window: d = R without a walk.
    } else if constexpr (kHitPoints) {
      // A hit point may lie anywhere in its cell, so the bound is the distance to the nearest
      // remaining cell square rather than centre (at most √½ cell less).
      const float half = 0.5f * resf;
      for (const KernelOffset& k : kernel_) {
        const float lower = k.square_floor * resf - u_norm;
        if (lower > 0.0f && lower * lower >= best) break;
        // Distance from e to the cell's square: no hit point of the cell can be nearer, so a
        // cell that cannot improve on best is skipped before any lookup.
        const float bx = std::max(std::abs(ux - static_cast<float>(k.dx) * resf) - half, 0.0f);
        const float by = std::max(std::abs(uy - static_cast<float>(k.dy) * resf) - half, 0.0f);
        if (bx * bx + by * by >= best || !candidate(k.dx, k.dy)) continue;
        const Eigen::Vector2d h = grid.hitPoint(Eigen::Vector2i(cell.x() + k.dx, cell.y() + k.dy));
        const float rx = static_cast<float>(px - h.x()), ry = static_cast<float>(py - h.y());
        best = std::min(best, rx * rx + ry * ry);
      }
    } else if constexpr (kBits) {
      // Per window row the nearest candidate to e is the one nearest in x, i.e. the first set
      // bit on either side of e's column; taking it from bit scans instead of walking offsets
      // avoids the walk's unpredictable branches. A side without candidates yields an offset
      // beyond the window (d > R), which the minimum ignores. Same d² expression as the walk,
      // so the same minimum.
      const int centre = r + 1;  // bit of dx = 0
      const std::uint32_t below = (std::uint32_t{1} << centre) - 1;
      // Most rows of a window are empty (walls are thin), so only non-empty ones are scanned.
      std::uint32_t rows[2 * kMaxBitRadius + 1];
      std::uint32_t nonempty = 0;
      for (int i = 0; i <= 2 * r; ++i) {
        rows[i] = candidateRow(i);
        nonempty |= static_cast<std::uint32_t>(rows[i] != 0) << i;
      }
      for (; nonempty != 0; nonempty &= nonempty - 1) {
        const int i = std::countr_zero(nonempty);
        const std::uint32_t row = rows[i];
        const int right = std::countr_zero(row >> centre);             // dx ≥ 0
        const int left = 31 - std::countl_zero(row & below) - centre;  // dx < 0; −1−centre if none
        const float ry = uy - static_cast<float>(i - r) * resf;
        const float rr = ux - static_cast<float>(right) * resf;
        const float rl = ux - static_cast<float>(left) * resf;
        best = std::min(best, std::min(rr * rr + ry * ry, rl * rl + ry * ry));
      }
    } else {
      for (const KernelOffset& k : kernel_) {
        const float lower = k.distance * resf - u_norm;
        if (lower > 0.0f && lower * lower >= best) break;
        const float rx = ux - static_cast<float>(k.dx) * resf;
        const float ry = uy - static_cast<float>(k.dy) * resf;
        const float d2 = rx * rx + ry * ry;
        if (d2 < best && candidate(k.dx, k.dy)) best = d2;
      }
    }
    if (best < big_r2) ++out.matched;
    d2_sum += best;
    // An unmatched beam adds exactly 0 to the score, so its exp() is skipped.
    if constexpr (kScore)
      if (best < big_r2)
        score_sum += (std::exp(-best * inv_two_sigma2) - kernel_floor) * kernel_scale;
  }
  out.score = score_sum;
  out.log_likelihood = -d2_sum / (2.0 * options_.likelihood_sigma * options_.likelihood_sigma *
                                  options_.likelihood_gain);
  return out;
}

template <class Grid>
std::vector<double> ScanMatcher::sampleLogLikelihood(const Grid& grid, const ScanPoints& points,
                                                     const Pose2& centre,
                                                     const detail::SampleGrid& g) const {
  std::vector<double> ll(static_cast<std::size_t>(g.size()));
  for (int k = 0; k < g.size(); ++k)
    ll[static_cast<std::size_t>(k)] = logLikelihood(grid, points, g.at(centre, k));
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
  while (evaluations < options_.max_iterations) {
    const Pose2 moves[6] = {
        {pose.x + linear, pose.y, pose.theta},  {pose.x - linear, pose.y, pose.theta},
        {pose.x, pose.y + linear, pose.theta},  {pose.x, pose.y - linear, pose.theta},
        {pose.x, pose.y, pose.theta + angular}, {pose.x, pose.y, pose.theta - angular}};
    int chosen = -1;
    for (int m = 0; m < 6 && evaluations < options_.max_iterations; ++m) {
      ++evaluations;
      // The move back to where the last step came from scored below the current best, so it
      // cannot be chosen and is not recomputed (it still counts, keeping max_iterations' cap
      // where it was).
      if (m == back_move) continue;
      const Eval e = evaluate<Grid, true>(grid, points, moves[m]);
      if (e.score > best.score) {
        best = e;
        chosen = m;
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

}  // namespace tessera::common
