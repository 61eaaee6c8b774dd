#include "scan_rasterizer.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tessera::grid::detail {
namespace {

// Cell indices are ints; points farther than this many cells from the origin are rejected
// before any floor() so that the conversion can never overflow.
constexpr double kMaxAbsCells = 1e9;

Eigen::Vector2i floorCell(const Eigen::Vector2d& p) {
  return {static_cast<int>(std::floor(p.x())), static_cast<int>(std::floor(p.y()))};
}

/// Visits the cells a segment from a to b (in cell units) crosses, in order, starting with
/// a's cell and ending with b's cell (included only when include_end). Exact traversal
/// (Amanatides & Woo): every cell the segment touches, one axis step at a time. The step count
/// is fixed up front so rounding can never make the walk miss b's cell or run past it.
template <typename Visit>
void traverse(const Eigen::Vector2d& a, const Eigen::Vector2d& b, bool include_end, Visit&& visit) {
  Eigen::Vector2i cell = floorCell(a);
  const Eigen::Vector2i end = floorCell(b);
  const Eigen::Vector2d d = b - a;
  const int step_x = end.x() > cell.x() ? 1 : -1;
  const int step_y = end.y() > cell.y() ? 1 : -1;
  int left_x = std::abs(end.x() - cell.x());
  int left_y = std::abs(end.y() - cell.y());
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Parameter t in [0, 1] along the segment at which the next x / y cell boundary is crossed.
  double t_max_x = kInf, t_max_y = kInf, t_delta_x = kInf, t_delta_y = kInf;
  if (left_x > 0) {
    const double boundary = step_x > 0 ? cell.x() + 1.0 : cell.x();
    t_max_x = (boundary - a.x()) / d.x();
    t_delta_x = 1.0 / std::abs(d.x());
  }
  if (left_y > 0) {
    const double boundary = step_y > 0 ? cell.y() + 1.0 : cell.y();
    t_max_y = (boundary - a.y()) / d.y();
    t_delta_y = 1.0 / std::abs(d.y());
  }
  // Branch-free steps: whether a diagonal ray steps in x or y next follows no pattern the
  // branch predictor could learn. An axis that does not step adds 0 (its t_max is ≥ 0 or +inf,
  // so its comparisons are unchanged).
  while (left_x + left_y > 0) {
    visit(cell);
    const int sx = static_cast<int>(left_y == 0 || (left_x > 0 && t_max_x < t_max_y));
    const int sy = 1 - sx;
    cell.x() += sx * step_x;
    cell.y() += sy * step_y;
    t_max_x += sx != 0 ? t_delta_x : 0.0;
    t_max_y += sy != 0 ? t_delta_y : 0.0;
    left_x -= sx;
    left_y -= sy;
  }
  if (include_end) visit(cell);
}

void check(bool ok, const std::string& who, const std::string& what) {
  if (!ok) throw std::invalid_argument(who + ": " + what);
}

int floorDiv(int a, int b) {
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}

}  // namespace

void checkGridOptions(double resolution, const LogOddsModel& l, int max_side_cells,
                      const std::string& who) {
  check(std::isfinite(resolution) && resolution > 0, who,
        "resolution must be > 0 m (got " + std::to_string(resolution) + ")");
  check(l.hit > 0, who, "log-odds hit (l_occ) must be > 0 (got " + std::to_string(l.hit) + ")");
  check(l.miss < 0, who, "log-odds miss (l_free) must be < 0 (got " + std::to_string(l.miss) + ")");
  check(l.min < 0 && l.max > 0, who,
        "log-odds clamp must satisfy l_min < 0 < l_max (got [" + std::to_string(l.min) + ", " +
            std::to_string(l.max) + "])");
  check(max_side_cells > 0, who, "max_side_cells must be > 0");
}

CellBox growBox(const CellBox& current, const CellBox& need, const Eigen::Vector2i& anchor,
                int chunk, int limit) {
  CellBox target = current;
  target.extend(need.min);
  target.extend(need.max);
  if (!current.empty() && current.contains(target.min) && current.contains(target.max))
    return current;
  for (int axis = 0; axis < 2; ++axis) {
    // Align to the chunk lattice so repeated small growth amortises to few reallocations.
    int lo = floorDiv(target.min[axis], chunk) * chunk;
    int hi = (floorDiv(target.max[axis], chunk) + 1) * chunk - 1;
    if (static_cast<long>(hi) - lo + 1 > limit) {
      if (current.empty()) {
        // Centre the window on the sensor: that is where the nearest (most useful) cells are.
        lo = anchor[axis] - limit / 2;
        hi = lo + limit - 1;
      } else {
        // Keep everything already mapped; share the remaining room between the two sides,
        // giving a side the other does not need.
        const int alo = current.min[axis], ahi = current.max[axis];
        const int extra = limit - (ahi - alo + 1);
        const int need_lo = std::max(0, alo - lo), need_hi = std::max(0, hi - ahi);
        const int grow_lo = std::min(need_lo, std::max(extra / 2, extra - need_hi));
        const int grow_hi = std::min(need_hi, extra - grow_lo);
        lo = alo - grow_lo;
        hi = ahi + grow_hi;
      }
    }
    target.min[axis] = lo;
    target.max[axis] = hi;
  }
  return target;
}

ScanRasterizer& ScanRasterizer::forThisThread() {
  thread_local ScanRasterizer rasterizer;
  return rasterizer;
}

ScanInsertResult ScanRasterizer::classify(const RangeScan& scan, const Pose2& sensor_pose,
                                          const ScanInsertOptions& insert_options,
                                          double resolution) {
  ScanInsertResult result;
  beams_.clear();
  updates_.clear();
  hit_points_.clear();
  need_ = CellBox{};
  const double res = resolution;
  const Eigen::Vector2d origin = sensor_pose.translation() / res;  // in cell units
  const bool usable = sensor_pose.isFinite() && origin.cwiseAbs().maxCoeff() < kMaxAbsCells &&
                      std::isfinite(scan.angle_min) && std::isfinite(scan.angle_increment) &&
                      !std::isnan(scan.range_min) && !std::isnan(scan.range_max);
  if (!usable) {
    result.invalid = scan.ranges.size();
    return result;
  }

  // Pass 1: classify beams and find the box they need, so storage grows once per scan.
  const double max_range = std::max(0.0, insert_options.max_range);
  const double max_free = std::max(0.0, insert_options.max_free_range);
  origin_ = origin;
  origin_cell_ = floorCell(origin);
  CellBox need;
  need.extend(origin_cell_);
  for (std::size_t k = 0; k < scan.ranges.size(); ++k) {
    const double r = scan.ranges[k];
    if (std::isnan(r) || r < scan.range_min || r <= 0.0) {  // a return at 0 m is not physical
      ++result.invalid;
      continue;
    }
    enum class Kind { kHit, kNoReturn, kBeyond } kind;
    double length;
    if (r >= scan.range_max) {  // also +inf
      kind = Kind::kNoReturn;
      length = max_free;
    } else if (r > max_range) {
      kind = Kind::kBeyond;
      length = max_range;
    } else {
      kind = Kind::kHit;
      length = r;
    }
    const double a =
        sensor_pose.theta + scan.angle_min + static_cast<double>(k) * scan.angle_increment;
    const Eigen::Vector2d end = origin + (length / res) * Eigen::Vector2d(std::cos(a), std::sin(a));
    if (!(end.cwiseAbs().maxCoeff() < kMaxAbsCells)) {  // absurd range limits
      ++result.invalid;
      continue;
    }
    ++(kind == Kind::kHit        ? result.hits
       : kind == Kind::kNoReturn ? result.no_return
                                 : result.beyond_range);
    if (length <= 0.0) continue;  // nothing to clear (max_free_range = 0)
    beams_.push_back({end, kind == Kind::kHit});
    need.extend(floorCell(end));
  }
  if (beams_.empty()) return result;
  need_ = need;
  return result;
}

void ScanRasterizer::collect(const CellBox& storage, ScanInsertResult& result,
                             bool with_hit_points) {
  updates_.clear();
  hit_points_.clear();
  // Every visited cell lies in need_ (a ray stays within the box of its end cells), so one bit
  // per cell of the part of need_ the grid stores is enough to see each cell once. Unlike a
  // per-grid stamp it costs nothing per particle and is bounded by the scan's reach.
  CellBox window;
  window.min = need_.min.cwiseMax(storage.min);
  window.max = need_.max.cwiseMin(storage.max);
  const auto w = static_cast<std::uint64_t>(window.width());
  const std::uint64_t area = w * static_cast<std::uint64_t>(window.height());
  seen_.assign((area + 63) / 64, 0);
  // Every visited cell lies in need_, so when the grid stores all of it (the usual case) the
  // per-cell clipping test is skipped.
  const bool may_clip = window.min != need_.min || window.max != need_.max;
  auto visitIn = [&]<bool kClip>(const Eigen::Vector2i& c, bool hit) {
    if constexpr (kClip) {
      if (!window.contains(c)) {
        ++result.clipped_cells;
        return;
      }
    }
    const std::uint64_t index = static_cast<std::uint64_t>(c.y() - window.min.y()) * w +
                                static_cast<std::uint64_t>(c.x() - window.min.x());
    std::uint64_t& word = seen_[index >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (index & 63);
    if ((word & bit) != 0) return;
    word |= bit;
    updates_.push_back({c, hit});
  };
  auto visit = [&](const Eigen::Vector2i& c, bool hit) {
    may_clip ? visitIn.template operator()<true>(c, hit)
             : visitIn.template operator()<false>(c, hit);
  };
  // Hits first: a cell some beam ends in is occupied even if other beams cross it, so grazing
  // beams do not erase thin walls.
  for (const Beam& b : beams_)
    if (b.hit) visit(floorCell(b.end), true);
  if (with_hit_points) {
    for (const Beam& b : beams_) {
      if (!b.hit) continue;
      const Eigen::Vector2i cell = floorCell(b.end);
      if (!window.contains(cell)) continue;  // already counted as clipped above
      const Eigen::Vector2d offset = b.end - cell.cast<double>() - Eigen::Vector2d(0.5, 0.5);
      hit_points_.push_back({cell, offset.cast<float>()});
    }
  }
  // Free space along every beam, up to the endpoint cell (excluded for hits).
  auto freeSpace = [&]<bool kClip>() {
    for (const Beam& b : beams_)
      traverse(origin_, b.end, /*include_end=*/!b.hit,
               [&](const Eigen::Vector2i& c) { visitIn.template operator()<kClip>(c, false); });
  };
  may_clip ? freeSpace.template operator()<true>() : freeSpace.template operator()<false>();
}

}  // namespace tessera::grid::detail
