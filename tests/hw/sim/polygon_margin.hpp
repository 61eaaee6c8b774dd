// A test helper for floor polygons (camera footprints): how far a point lies inside one.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <limits>
#include <vector>

namespace tessera::test {

/// > 0 inside a counter-clockwise convex polygon, < 0 outside: the distance to the nearest
/// edge's line (signed), so points near the border can be told apart from clear cases.
inline double insideMargin(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  double m = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d e = poly[(i + 1) % poly.size()] - poly[i];
    const Eigen::Vector2d r = p - poly[i];
    m = std::min(m, (e.x() * r.y() - e.y() * r.x()) / e.norm());
  }
  return m;
}

}  // namespace tessera::test
