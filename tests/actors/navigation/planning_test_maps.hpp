// Helpers for the planner tests: gentle inflation so costs vary between cells, and random
// traversable cells.
#pragma once

#include <tessera/navigation/costmap.hpp>

#include <Eigen/Core>

#include <random>

namespace tessera::navigation::planning_test {

/// Inflation without an inscribed core and with a slow decay: most free cells near obstacles
/// get distinct costs, so cost-aware paths differ from shortest ones.
inline void inflateGently(Costmap& map) {
  InflationOptions o;
  o.inscribed_radius = 0.0;
  o.inflation_radius = 0.25;
  o.cost_scaling = 4;
  inflate(map, o);
}

/// A uniformly random cell a path may enter (the map must have one).
inline Eigen::Vector2i randomTraversableCell(const Costmap& map, std::mt19937_64& rng) {
  std::uniform_int_distribution<int> col(0, map.width - 1), row(0, map.height - 1);
  while (true) {
    const Eigen::Vector2i c(col(rng), row(rng));
    if (map.at(c) <= cost::kMaxTraversable) return c;
  }
}

}  // namespace tessera::navigation::planning_test
