// ScanMatcher's implementation (see scan_matcher.hpp for the model): the score/likelihood
// evaluation templates, hill climbing and proposal sampling (the inner loop's cell arithmetic is
// in matcher_cells.hpp). Internal to the scan-matching library; included by scan_matcher.cpp, by
// scan_matcher_grids.cpp (the instantiations for the repository's grids) and by tests that
// match on grids of their own. Metres, radians; cell arithmetic in cell units.
#pragma once

#include "matcher_cells.hpp"

#include <tessera/scan_matching/scan_matcher.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <stdexcept>
#include <vector>

namespace tessera::scan_matching {

namespace detail {
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

struct ScanMatcher::Eval {
  double score = 0;
  double log_likelihood = 0;
  int matched = 0;
};

/// Per-evaluation constants of the score kernel and free check, for grid resolution `res` and
/// kernel radius r [cells].
struct ScanMatcher::KernelTerms {
  float resf, big_r2;  // resolution; squared kernel reach R = (r + ½) cells [m²]
  bool free_check;
  double free_cells, quarter_inv_free2;  // free-check offset [cells]; ¼ / free_cells²
  // Score kernel rescaled so that d = 0 gives 1 and d = R gives 0.
  float inv_two_sigma2, kernel_floor, kernel_scale;
  double no_hit_extra;  // D² − R² [m²]: added to d² for each unmatched beam
};

inline ScanMatcher::KernelTerms ScanMatcher::kernelTerms(double res, int r) const {
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

template <class Grid>
double ScanMatcher::score(const Grid& grid, const ScanPoints& points,
                          const Pose2& robot_pose) const {
  return evaluate<Grid, true>(grid, points, robot_pose).score;
}

template <class Grid>
double ScanMatcher::logLikelihood(const Grid& grid, const ScanPoints& points,
                                  const Pose2& robot_pose, int* matched) const {
  const Eval e = evaluate<Grid, false>(grid, points, robot_pose);
  if (matched) *matched = e.matched;
  return e.log_likelihood;
}

/// True when `grid` is read as occupancy rows by evaluateRows() (see the header comment).
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

/// Score, log-likelihood and matched beams at one pose, by the fastest path `grid` allows.
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

/// evaluate() at every pose: out[k] for poses[k], the same values, bit for bit. On occupancy
/// row grids the poses are evaluated kMaxGroup at a time by evaluateRows().
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

/// evaluateRows() with the RBPF's fine and coarse radii unrolled (the bulk of its time).
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

/// evaluate() at n ≤ kMaxGroup finite poses in one pass over the beams, for occupancy row
/// grids without hit points. Poses a matcher compares (hill-climbing moves, proposal samples)
/// are close, so a beam's endpoints at them mostly fall within a few cells of each other:
/// per beam the poses are split into clusters whose windows fit one read of rows (kMaxRows),
/// and each cluster's rows are read once, and its free-check pass done once per free-check
/// direction, instead of once per pose. Each pose still gets exactly what a pass of its own
/// would. kRadius > 0 fixes the kernel radius at compile time (it must equal the option), so
/// the row loops unroll.
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

/// evaluate() with d measured to cell centres or (kHitPoints) to the grid's hit points, and
/// candidates read from occupancy rows (kBits, hit points only) or cell by cell.
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

/// logLikelihood() at every pose of the sample grid `g` around `centre`.
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
