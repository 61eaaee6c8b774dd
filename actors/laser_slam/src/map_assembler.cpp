#include <tessera/laser_slam/map_assembler.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace tessera::laser_slam {
namespace {

// Log-odds of a ROS percentage, kept away from ±inf at 0 and 100.
// Sums of log-odds in fixed point, 2 bytes per global cell (a float sum held the largest
// buffer of a run): 1/1024 resolution, saturating at ±32, where p is 1 to 14 digits anyway.
constexpr double kFixedScale = 1024.0;
constexpr std::int16_t kUnknownSum = std::numeric_limits<std::int16_t>::min();
constexpr int kMaxSum = std::numeric_limits<std::int16_t>::max();

std::int16_t logOddsOf(std::int8_t v) {
  const double p = std::clamp(v / 100.0, 0.01, 0.99);
  return static_cast<std::int16_t>(std::lround(std::log(p / (1.0 - p)) * kFixedScale));
}

}  // namespace

MapAssembler::MapAssembler(double resolution) : resolution_(resolution) {
  if (!(std::isfinite(resolution) && resolution >= 0))
    throw std::invalid_argument("map_assembler: resolution must be >= 0 [m] (0 = the submaps')");
}

void MapAssembler::setSubmap(int id, tessera::grid::OccupancyMap grid) {
  if (!(grid.resolution > 0) || !std::isfinite(grid.resolution) || !grid.origin.isFinite() ||
      grid.width < 0 || grid.height < 0 ||
      grid.cells.size() !=
          static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height))
    throw std::invalid_argument("map_assembler: submap " + std::to_string(id) +
                                " has an inconsistent grid (resolution, origin, width x height "
                                "= cells expected)");
  submaps_[id].grid = tessera::grid::PackedOccupancyMap(grid);
}

void MapAssembler::setPose(int id, const tessera::Pose2& global_pose) {
  if (!global_pose.isFinite())
    throw std::invalid_argument("map_assembler: submap " + std::to_string(id) +
                                " has a non-finite global pose");
  Entry& e = submaps_[id];
  e.pose = global_pose;
  e.placed = true;
}

bool MapAssembler::hasPose(int id) const {
  const auto it = submaps_.find(id);
  return it != submaps_.end() && it->second.placed;
}

tessera::Pose2 MapAssembler::pose(int id) const {
  const auto it = submaps_.find(id);
  return it == submaps_.end() ? tessera::Pose2{} : it->second.pose;
}

std::optional<tessera::grid::OccupancyMap> MapAssembler::grid(int id) const {
  const auto it = submaps_.find(id);
  if (it == submaps_.end() || it->second.grid.empty()) return std::nullopt;
  return it->second.grid.unpack();
}

std::size_t MapAssembler::bytes() const {
  std::size_t total = 0;
  for (const auto& [id, e] : submaps_) total += e.grid.bytes();
  return total;
}

tessera::grid::OccupancyMap MapAssembler::assemble() const {
  double res = resolution_;
  Eigen::Vector2d lo(std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  std::vector<const Entry*> drawn;
  for (const auto& [id, e] : submaps_) {
    if (!e.placed || e.grid.empty()) continue;
    drawn.push_back(&e);
    if (resolution_ == 0) res = res == 0 ? e.grid.resolution() : std::min(res, e.grid.resolution());
    const tessera::Pose2 to_map = e.pose * e.grid.origin();
    for (const auto& corner :
         {Eigen::Vector2d(0, 0), Eigen::Vector2d(e.grid.width(), 0),
          Eigen::Vector2d(0, e.grid.height()), Eigen::Vector2d(e.grid.width(), e.grid.height())}) {
      const Eigen::Vector2d p = to_map * (corner * e.grid.resolution());
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  tessera::grid::OccupancyMap out;
  if (drawn.empty()) return out;
  out.resolution = res;
  const Eigen::Vector2d corner = (lo / res).array().floor() * res;
  out.origin = tessera::Pose2(corner, 0.0);
  out.width = static_cast<int>(std::ceil((hi.x() - corner.x()) / res));
  out.height = static_cast<int>(std::ceil((hi.y() - corner.y()) / res));
  const std::size_t n = static_cast<std::size_t>(out.width) * static_cast<std::size_t>(out.height);
  std::vector<std::int16_t> sum(n, kUnknownSum);
  std::array<std::int16_t, 101> log_odds{};
  for (int v = 0; v <= 100; ++v)
    log_odds[static_cast<std::size_t>(v)] = logOddsOf(static_cast<std::int8_t>(v));
  for (const Entry* e : drawn) {
    // One submap unpacked at a time.
    const tessera::grid::OccupancyMap grid = e->grid.unpack();
    // Walk the global cells under this submap's footprint; sample the submap at each centre.
    const tessera::Pose2 to_map = e->pose * grid.origin;
    const tessera::Pose2 to_grid = to_map.inverse();
    Eigen::Vector2d a(std::numeric_limits<double>::infinity(),
                      std::numeric_limits<double>::infinity());
    Eigen::Vector2d b = -a;
    for (const auto& c :
         {Eigen::Vector2d(0, 0), Eigen::Vector2d(grid.width, 0), Eigen::Vector2d(0, grid.height),
          Eigen::Vector2d(grid.width, grid.height)}) {
      const Eigen::Vector2d p = to_map * (c * grid.resolution);
      a = a.cwiseMin(p);
      b = b.cwiseMax(p);
    }
    const int c0 = std::max(0, static_cast<int>(std::floor((a.x() - corner.x()) / res)));
    const int r0 = std::max(0, static_cast<int>(std::floor((a.y() - corner.y()) / res)));
    const int c1 =
        std::min(out.width - 1, static_cast<int>(std::floor((b.x() - corner.x()) / res)));
    const int r1 =
        std::min(out.height - 1, static_cast<int>(std::floor((b.y() - corner.y()) / res)));
    const double inv = 1.0 / grid.resolution;
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) {
        const Eigen::Vector2d local =
            to_grid * Eigen::Vector2d(corner.x() + (c + 0.5) * res, corner.y() + (r + 0.5) * res);
        const int gc = static_cast<int>(std::floor(local.x() * inv));
        const int gr = static_cast<int>(std::floor(local.y() * inv));
        if (!grid.contains(gc, gr)) continue;
        const std::int8_t v = grid.at(gc, gr);
        if (v < 0) continue;
        const std::size_t k = static_cast<std::size_t>(r) * out.width + c;
        const int add = log_odds[static_cast<std::size_t>(std::min<int>(v, 100))];
        const int before = sum[k] == kUnknownSum ? 0 : sum[k];
        sum[k] = static_cast<std::int16_t>(std::clamp(before + add, -kMaxSum, kMaxSum));
      }
    }
  }
  out.cells.assign(n, tessera::grid::OccupancyMap::kUnknown);
  for (std::size_t k = 0; k < n; ++k) {
    if (sum[k] == kUnknownSum) continue;
    const double p = 1.0 - 1.0 / (1.0 + std::exp(static_cast<double>(sum[k]) / kFixedScale));
    out.cells[k] = static_cast<std::int8_t>(std::lround(100.0 * p));
  }
  return out;
}

}  // namespace tessera::laser_slam
