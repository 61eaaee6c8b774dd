#include <tessera/laser_slam/submap_trimmer.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

namespace tessera::laser_slam {
namespace {

/// A coarse cell as one 64-bit key: the two signed 32-bit indices side by side.
std::uint64_t cellKey(const Eigen::Vector2d& p, double cell_size) {
  const auto ix = static_cast<std::int32_t>(std::floor(p.x() / cell_size));
  const auto iy = static_cast<std::int32_t>(std::floor(p.y() / cell_size));
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(ix)) << 32) |
         static_cast<std::uint32_t>(iy);
}

}  // namespace

SubmapTrimmer::SubmapTrimmer(SubmapTrimmerOptions options) : options_(options) {
  if (!(options_.cell_size > 0.0) || !std::isfinite(options_.cell_size))
    throw std::invalid_argument("cell_size: must be > 0 m, got " +
                                std::to_string(options_.cell_size));
  if (!(options_.min_own_fraction >= 0.0 && options_.min_own_fraction <= 1.0))
    throw std::invalid_argument("min_own_fraction: must be in [0, 1], got " +
                                std::to_string(options_.min_own_fraction));
  if (options_.keep_newest < 1)
    throw std::invalid_argument("keep_newest: must be >= 1, got " +
                                std::to_string(options_.keep_newest));
}

std::vector<Eigen::Vector2d> SubmapTrimmer::footprint(const tessera::grid::OccupancyMap& g) const {
  std::unordered_set<std::uint64_t> seen;
  std::vector<Eigen::Vector2d> out;
  if (g.empty() || g.cells.size() != static_cast<std::size_t>(g.width) * g.height) return out;
  for (int row = 0; row < g.height; ++row) {
    for (int col = 0; col < g.width; ++col) {
      if (g.at(col, row) == tessera::grid::OccupancyMap::kUnknown) continue;
      const Eigen::Vector2d p = g.cellCenter(col, row);
      const std::uint64_t key = cellKey(p, options_.cell_size);
      if (!seen.insert(key).second) continue;
      out.push_back({(std::floor(p.x() / options_.cell_size) + 0.5) * options_.cell_size,
                     (std::floor(p.y() / options_.cell_size) + 0.5) * options_.cell_size});
    }
  }
  return out;
}

void SubmapTrimmer::addSubmap(int id, std::vector<Eigen::Vector2d> footprint) {
  footprints_[id] = std::move(footprint);
}

std::vector<int> SubmapTrimmer::trim(const std::map<int, tessera::Pose2>& poses,
                                     const std::set<int>& keep) {
  // Newest first: a cell's owner is the first submap to claim it.
  std::unordered_map<std::uint64_t, int> owner;
  std::map<int, std::pair<std::size_t, std::size_t>> counts;  // id -> (owned, footprint)
  for (auto it = footprints_.rbegin(); it != footprints_.rend(); ++it) {
    const auto pose = poses.find(it->first);
    if (pose == poses.end() || !pose->second.isFinite()) continue;
    std::unordered_set<std::uint64_t> mine;
    for (const auto& p : it->second) mine.insert(cellKey(pose->second * p, options_.cell_size));
    std::size_t owned = 0;
    for (const auto key : mine)
      if (owner.emplace(key, it->first).second) ++owned;
    counts[it->first] = {owned, mine.size()};
  }
  std::vector<int> trimmed;
  int newer = 0;  // placed submaps newer than the one looked at
  for (auto it = counts.rbegin(); it != counts.rend(); ++it, ++newer) {
    const auto [owned, total] = it->second;
    if (newer < options_.keep_newest || keep.count(it->first) || total == 0) continue;
    if (static_cast<double>(owned) < options_.min_own_fraction * static_cast<double>(total))
      trimmed.push_back(it->first);
  }
  std::sort(trimmed.begin(), trimmed.end());
  for (const int id : trimmed) footprints_.erase(id);
  return trimmed;
}

std::size_t SubmapTrimmer::points() const {
  std::size_t n = 0;
  for (const auto& [id, f] : footprints_) n += f.size();
  return n;
}

}  // namespace tessera::laser_slam
