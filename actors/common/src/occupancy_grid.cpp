#include <tessera/common/occupancy_grid.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::common {
namespace {

// Cell indices are ints; points farther than this many cells from the origin are rejected
// before any floor() so that the conversion can never overflow.
constexpr double kMaxAbsCells = 1e9;

int floorDiv(int a, int b) {
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}

/// Visits the cells a segment from a to b (in cell units) crosses, in order, starting with
/// a's cell and ending with b's cell (included only when include_end). Exact traversal
/// (Amanatides & Woo): every cell the segment touches, one axis step at a time. The step count
/// is fixed up front so rounding can never make the walk miss b's cell or run past it.
template <typename Visit>
void traverse(const Eigen::Vector2d& a, const Eigen::Vector2d& b, bool include_end, Visit&& visit) {
  Eigen::Vector2i cell(static_cast<int>(std::floor(a.x())), static_cast<int>(std::floor(a.y())));
  const Eigen::Vector2i end(static_cast<int>(std::floor(b.x())),
                            static_cast<int>(std::floor(b.y())));
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
  while (left_x + left_y > 0) {
    visit(cell);
    if (left_y == 0 || (left_x > 0 && t_max_x < t_max_y)) {
      cell.x() += step_x;
      t_max_x += t_delta_x;
      --left_x;
    } else {
      cell.y() += step_y;
      t_max_y += t_delta_y;
      --left_y;
    }
  }
  if (include_end) visit(cell);
}

void check(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("OccupancyGrid: " + what);
}

}  // namespace

OccupancyGrid::OccupancyGrid(Options options) : options_(options) {
  const auto& l = options_.log_odds;
  check(std::isfinite(options_.resolution) && options_.resolution > 0,
        "resolution must be > 0 m (got " + std::to_string(options_.resolution) + ")");
  check(l.hit > 0, "log-odds hit (l_occ) must be > 0 (got " + std::to_string(l.hit) + ")");
  check(l.miss < 0, "log-odds miss (l_free) must be < 0 (got " + std::to_string(l.miss) + ")");
  check(l.min < 0 && l.max > 0, "log-odds clamp must satisfy l_min < 0 < l_max (got [" +
                                    std::to_string(l.min) + ", " + std::to_string(l.max) + "])");
  check(options_.chunk_cells > 0, "chunk_cells must be > 0");
  check(options_.max_side_cells > 0, "max_side_cells must be > 0");
}

Eigen::Vector2i OccupancyGrid::worldToCell(const Eigen::Vector2d& p) const {
  return {static_cast<int>(std::floor(p.x() / options_.resolution)),
          static_cast<int>(std::floor(p.y() / options_.resolution))};
}

Eigen::Vector2d OccupancyGrid::cellCenter(const Eigen::Vector2i& c) const {
  return (c.cast<double>() + Eigen::Vector2d(0.5, 0.5)) * options_.resolution;
}

Eigen::Vector2d OccupancyGrid::cellCorner(const Eigen::Vector2i& c) const {
  return c.cast<double>() * options_.resolution;
}

std::size_t OccupancyGrid::indexOf(const Eigen::Vector2i& c) const {
  return static_cast<std::size_t>(c.y() - allocated_.min.y()) *
             static_cast<std::size_t>(allocated_.width()) +
         static_cast<std::size_t>(c.x() - allocated_.min.x());
}

bool OccupancyGrid::isKnown(const Eigen::Vector2i& c) const {
  return allocated_.contains(c) && stamp_[indexOf(c)] != 0;
}

float OccupancyGrid::logOdds(const Eigen::Vector2i& c) const {
  return isKnown(c) ? log_odds_[indexOf(c)] : 0.0f;
}

double OccupancyGrid::probability(const Eigen::Vector2i& c) const {
  return 1.0 - 1.0 / (1.0 + std::exp(static_cast<double>(logOdds(c))));
}

std::int8_t OccupancyGrid::rosValue(float log_odds) {
  const double p = 1.0 - 1.0 / (1.0 + std::exp(static_cast<double>(log_odds)));
  return static_cast<std::int8_t>(std::clamp(std::lround(100.0 * p), 0L, 100L));
}

void OccupancyGrid::growToInclude(const CellBox& need, const Eigen::Vector2i& anchor) {
  CellBox target = allocated_;
  target.extend(need.min);
  target.extend(need.max);
  if (!allocated_.empty() && allocated_.contains(target.min) && allocated_.contains(target.max))
    return;
  const int chunk = options_.chunk_cells, limit = options_.max_side_cells;
  for (int axis = 0; axis < 2; ++axis) {
    // Align to the chunk lattice so repeated small growth amortises to few reallocations.
    int lo = floorDiv(target.min[axis], chunk) * chunk;
    int hi = (floorDiv(target.max[axis], chunk) + 1) * chunk - 1;
    if (static_cast<long>(hi) - lo + 1 > limit) {
      if (allocated_.empty()) {
        // Centre the window on the sensor: that is where the nearest (most useful) cells are.
        lo = anchor[axis] - limit / 2;
        hi = lo + limit - 1;
      } else {
        // Keep everything already mapped; share the remaining room between the two sides,
        // giving a side the other does not need.
        const int alo = allocated_.min[axis], ahi = allocated_.max[axis];
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
  if (!allocated_.empty() && target.min == allocated_.min && target.max == allocated_.max) return;

  const std::size_t w = static_cast<std::size_t>(target.width());
  std::vector<float> log_odds(w * static_cast<std::size_t>(target.height()), 0.0f);
  std::vector<std::uint32_t> stamp(log_odds.size(), 0);
  if (!allocated_.empty()) {
    const int old_w = allocated_.width();
    for (int j = allocated_.min.y(); j <= allocated_.max.y(); ++j) {
      const std::size_t src = indexOf({allocated_.min.x(), j});
      const std::size_t dst = static_cast<std::size_t>(j - target.min.y()) * w +
                              static_cast<std::size_t>(allocated_.min.x() - target.min.x());
      std::copy_n(log_odds_.begin() + src, old_w, log_odds.begin() + dst);
      std::copy_n(stamp_.begin() + src, old_w, stamp.begin() + dst);
    }
  }
  allocated_ = target;
  log_odds_ = std::move(log_odds);
  stamp_ = std::move(stamp);
}

bool OccupancyGrid::touch(const Eigen::Vector2i& c, float delta) {
  if (!allocated_.contains(c)) return false;
  const std::size_t i = indexOf(c);
  if (stamp_[i] == scan_stamp_) return true;  // already updated by this scan
  if (stamp_[i] == 0) {
    ++known_count_;
    known_bounds_.extend(c);
  }
  stamp_[i] = scan_stamp_;
  const auto& l = options_.log_odds;
  log_odds_[i] = std::clamp(log_odds_[i] + delta, l.min, l.max);
  return true;
}

ScanInsertResult OccupancyGrid::insertScan(const RangeScan& scan, const Pose2& sensor_pose,
                                           const ScanInsertOptions& insert_options) {
  ScanInsertResult result;
  const double res = options_.resolution;
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
  const Eigen::Vector2i origin_cell(static_cast<int>(std::floor(origin.x())),
                                    static_cast<int>(std::floor(origin.y())));
  CellBox need;
  need.extend(origin_cell);
  beams_.clear();
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
    const bool hit = kind == Kind::kHit;
    beams_.push_back({end, hit});
    need.extend({static_cast<int>(std::floor(end.x())), static_cast<int>(std::floor(end.y()))});
  }
  if (beams_.empty()) return result;
  growToInclude(need, origin_cell);

  if (++scan_stamp_ == 0) {
    // 2^32 scans later: restart numbering, keeping "known" (non-zero) stamps non-zero.
    for (auto& s : stamp_) s = s != 0 ? 1 : 0;
    scan_stamp_ = 2;
  }

  // Pass 2: hits first, so that within this scan a hit always wins over a miss.
  const auto& l = options_.log_odds;
  for (const Beam& b : beams_) {
    if (!b.hit) continue;
    const Eigen::Vector2i c(static_cast<int>(std::floor(b.end.x())),
                            static_cast<int>(std::floor(b.end.y())));
    if (!touch(c, l.hit)) ++result.clipped_cells;
  }
  // Pass 3: free space along every beam, up to the endpoint cell (excluded for hits).
  for (const Beam& b : beams_) {
    traverse(origin, b.end, /*include_end=*/!b.hit, [&](const Eigen::Vector2i& c) {
      if (!touch(c, l.miss)) ++result.clipped_cells;
    });
  }
  return result;
}

void OccupancyGrid::exportInt8(const CellBox& box, std::span<std::int8_t> out) const {
  const std::size_t w = static_cast<std::size_t>(box.width());
  if (out.size() != w * static_cast<std::size_t>(box.height()))
    throw std::invalid_argument("OccupancyGrid::exportInt8: output holds " +
                                std::to_string(out.size()) + " cells, box needs " +
                                std::to_string(w * box.height()));
  std::size_t o = 0;
  for (int j = box.min.y(); j <= box.max.y(); ++j) {
    for (int i = box.min.x(); i <= box.max.x(); ++i, ++o) {
      const Eigen::Vector2i c(i, j);
      if (!allocated_.contains(c)) {
        out[o] = OccupancyMap::kUnknown;
        continue;
      }
      const std::size_t idx = indexOf(c);
      out[o] = stamp_[idx] == 0 ? OccupancyMap::kUnknown : rosValue(log_odds_[idx]);
    }
  }
}

OccupancyMap OccupancyGrid::toOccupancyMap(const CellBox& box) const {
  OccupancyMap map;
  map.resolution = options_.resolution;
  if (box.empty()) return map;
  map.width = box.width();
  map.height = box.height();
  const Eigen::Vector2d corner = cellCorner(box.min);
  map.origin = Pose2(corner.x(), corner.y(), 0.0);
  map.cells.resize(static_cast<std::size_t>(map.width) * static_cast<std::size_t>(map.height));
  exportInt8(box, map.cells);
  return map;
}

}  // namespace tessera::common
