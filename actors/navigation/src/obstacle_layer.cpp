// ObstacleLayer: 3D ray clearing and marking of laser and depth observations in height slices.
#include <tessera/navigation/obstacle_layer.hpp>

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::navigation {

void ObstacleLayerOptions::validate() const {
  ConfigCheck()
      .nonNegative("mark_range", mark_range)
      .nonNegative("clear_range", clear_range)
      .require(std::isfinite(min_height), "min_height", "must be finite", min_height)
      .require(std::isfinite(max_height) && max_height > min_height, "max_height",
               "must be > min_height", max_height)
      .throwIfBad("obstacle layer");
}

ObstacleLayer::ObstacleLayer(const Costmap& geometry, const ObstacleLayerOptions& options)
    : geometry_(geometry), options_(options) {
  options_.validate();
  geometry_.cells.clear();
  geometry_.cells.shrink_to_fit();
  const std::size_t n =
      static_cast<std::size_t>(geometry.width) * static_cast<std::size_t>(geometry.height);
  slices_.assign(n, 0);
  seen_.assign(n, 0);
}

void ObstacleLayer::clear() {
  std::fill(slices_.begin(), slices_.end(), 0);
  std::fill(seen_.begin(), seen_.end(), 0);
}

int ObstacleLayer::slice(double z) const {
  if (!(z >= options_.min_height && z <= options_.max_height)) return -1;
  const double f = (z - options_.min_height) / (options_.max_height - options_.min_height);
  return std::min(kSlices - 1, static_cast<int>(f * kSlices));
}

void ObstacleLayer::mark(const Eigen::Vector3d& sensor, const Eigen::Vector3d& p) {
  const int s = slice(p.z());
  if (s < 0 || (p.head<2>() - sensor.head<2>()).norm() > options_.mark_range) return;
  const Eigen::Vector2i c = geometry_.cellOf(p.head<2>());
  if (!geometry_.contains(c)) return;
  const std::size_t i = index(c.x(), c.y());
  slices_[i] = static_cast<std::uint16_t>(slices_[i] | (1u << s));
  seen_[i] = 1;
}

void ObstacleLayer::clearRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  const Eigen::Vector2d a = from.head<2>(), b = to.head<2>();
  const double length = (b - a).norm();
  const double reach = std::min(length, options_.clear_range);
  const Eigen::Vector2i last = geometry_.cellOf(b);
  // Samples every half cell: each crossed cell is visited at least once; a cell clipped only
  // at a corner may be missed, and the next observation settles it.
  const double step = 0.5 * geometry_.resolution;
  const int n = static_cast<int>(std::ceil(reach / step));
  for (int i = 0; i < n; ++i) {
    const double t = length > 0 ? (i * step) / length : 0.0;
    const Eigen::Vector2i c = geometry_.cellOf(a + (b - a) * t);
    if (c == last) break;
    if (!geometry_.contains(c)) continue;
    const int s = slice(from.z() + (to.z() - from.z()) * t);
    if (s < 0) continue;
    const std::size_t k = index(c.x(), c.y());
    slices_[k] = static_cast<std::uint16_t>(slices_[k] & ~(1u << s));
    seen_[k] = 1;
  }
}

void ObstacleLayer::addScan(const Eigen::Vector3d& sensor,
                            std::span<const Eigen::Vector2d> endpoints,
                            std::span<const std::uint8_t> no_return) {
  if (!sensor.allFinite()) return;
  for (std::size_t i = 0; i < endpoints.size(); ++i) {
    if (!endpoints[i].allFinite()) continue;
    const Eigen::Vector3d p(endpoints[i].x(), endpoints[i].y(), sensor.z());
    clearRay(sensor, p);
    if (i >= no_return.size() || !no_return[i]) mark(sensor, p);
  }
}

void ObstacleLayer::addPoints(const Eigen::Vector3d& sensor,
                              std::span<const Eigen::Vector3d> points) {
  if (!sensor.allFinite()) return;
  // Clear first, then mark, so that one frame's rays never wipe that frame's own obstacles.
  for (const Eigen::Vector3d& p : points)
    if (p.allFinite()) clearRay(sensor, p);
  for (const Eigen::Vector3d& p : points)
    if (p.allFinite()) mark(sensor, p);
}

ObstacleLayer::Cell ObstacleLayer::at(int col, int row) const {
  const std::size_t i = index(col, row);
  if (slices_[i]) return Cell::kObstacle;
  return seen_[i] ? Cell::kFree : Cell::kUnknown;
}

void ObstacleLayer::applyTo(Costmap& map) const {
  if (map.width != geometry_.width || map.height != geometry_.height)
    throw std::invalid_argument("obstacle layer: costmap is " + std::to_string(map.width) + " x " +
                                std::to_string(map.height) + ", the layer " +
                                std::to_string(geometry_.width) + " x " +
                                std::to_string(geometry_.height));
  for (std::size_t i = 0; i < slices_.size(); ++i) {
    if (slices_[i])
      map.cells[i] = cost::kLethal;
    else if (seen_[i] && map.cells[i] == cost::kUnknown)
      map.cells[i] = cost::kFree;
  }
}

std::size_t ObstacleLayer::obstacleCount() const {
  return static_cast<std::size_t>(
      std::count_if(slices_.begin(), slices_.end(), [](std::uint16_t s) { return s != 0; }));
}

}  // namespace tessera::navigation
