// Costmap construction: the static layer from an occupancy map, the obstacle distance transform
// and inflation.
#include <tessera/navigation/costmap.hpp>

#include <tessera/config/config_check.hpp>
#include <tessera/grid/distance_transform.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::navigation {

Costmap::Costmap(int w, int h, double res, const Pose2& o, std::uint8_t fill)
    : resolution(res), width(w), height(h), origin(o) {
  if (w <= 0 || h <= 0)
    throw std::invalid_argument("costmap: size must be positive, got " + std::to_string(w) + " x " +
                                std::to_string(h));
  if (!(std::isfinite(res) && res > 0))
    throw std::invalid_argument("costmap: resolution must be positive, got " + std::to_string(res));
  cells.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), fill);
}

void StaticLayerOptions::validate() const {
  ConfigCheck()
      .require(occupied_threshold >= 0 && occupied_threshold <= 100, "occupied_threshold",
               "must be in [0, 100]", occupied_threshold)
      .require(free_threshold >= 0 && free_threshold < occupied_threshold, "free_threshold",
               "must be in [0, occupied_threshold)", free_threshold)
      .throwIfBad("static layer");
}

void paste(const Costmap& map, Costmap& frame) {
  for (int r = 0; r < frame.height; ++r)
    for (int c = 0; c < frame.width; ++c) {
      const Eigen::Vector2i m = map.cellOf(frame.cellCenter(c, r));
      frame.at(c, r) = map.contains(m) ? map.at(m) : cost::kUnknown;
    }
}

Costmap fromOccupancy(const grid::OccupancyMap& map, const StaticLayerOptions& options) {
  options.validate();
  if (map.empty() || map.cells.size() != static_cast<std::size_t>(map.width) * map.height)
    throw std::invalid_argument("static layer: occupancy map is empty or its cells (" +
                                std::to_string(map.cells.size()) + ") are not width x height");
  Costmap out(map.width, map.height, map.resolution, map.origin);
  const std::uint8_t unknown = options.unknown_is_free ? cost::kFree : cost::kUnknown;
  for (std::size_t i = 0; i < map.cells.size(); ++i) {
    const int v = map.cells[i];
    if (v < 0)
      out.cells[i] = unknown;
    else if (v >= options.occupied_threshold)
      out.cells[i] = cost::kLethal;
    else if (v <= options.free_threshold)
      out.cells[i] = cost::kFree;
    else
      out.cells[i] = unknown;
  }
  return out;
}

void InflationOptions::validate() const {
  ConfigCheck()
      .nonNegative("inscribed_radius", inscribed_radius)
      .require(std::isfinite(inflation_radius) && inflation_radius >= inscribed_radius,
               "inflation_radius", "must be >= inscribed_radius", inflation_radius)
      .nonNegative("cost_scaling", cost_scaling)
      .throwIfBad("inflation");
}

std::vector<float> obstacleDistance(const Costmap& map) {
  std::vector<std::uint8_t> lethal(map.cells.size());
  for (std::size_t i = 0; i < lethal.size(); ++i) lethal[i] = map.cells[i] == cost::kLethal;
  std::vector<float> d = grid::distanceTransform(lethal, map.width, map.height);
  for (float& x : d) x = static_cast<float>(x * map.resolution);  // inf stays inf
  return d;
}

void inflate(Costmap& map, const InflationOptions& options) {
  options.validate();
  const std::vector<float> distance = obstacleDistance(map);
  for (std::size_t i = 0; i < map.cells.size(); ++i) {
    std::uint8_t& c = map.cells[i];
    if (c == cost::kLethal || c == cost::kUnknown) continue;
    // Distances are floats: a cell exactly at a radius must not fall out of it by rounding.
    const double d = distance[i] - 1e-4 * map.resolution;
    std::uint8_t inflated = cost::kFree;
    if (d <= options.inscribed_radius)
      inflated = cost::kInscribed;
    else if (d <= options.inflation_radius)
      inflated = static_cast<std::uint8_t>(
          std::lround(cost::kMaxTraversable *
                      std::exp(-options.cost_scaling * (d - options.inscribed_radius))));
    c = std::max(c, inflated);
  }
}

}  // namespace tessera::navigation
