// Worlds made of straight wall segments, ray cast exactly: the ground truth for scan matcher
// tests, where only the map should be discretised. Units: metres and radians in the world frame.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <limits>
#include <vector>

namespace tessera::test {

struct Segment {
  Eigen::Vector2d a, b;
};
using SegmentWorld = std::vector<Segment>;

/// Distance along the ray from o at `angle` to the nearest segment, +inf when none is hit.
inline double castRay(const SegmentWorld& world, const Eigen::Vector2d& o, double angle) {
  const Eigen::Vector2d d(std::cos(angle), std::sin(angle));
  double best = std::numeric_limits<double>::infinity();
  for (const Segment& s : world) {
    const Eigen::Vector2d e = s.b - s.a;
    const double den = d.x() * e.y() - d.y() * e.x();
    if (std::abs(den) < 1e-12) continue;  // parallel
    const Eigen::Vector2d w = s.a - o;
    const double t = (w.x() * e.y() - w.y() * e.x()) / den;
    const double u = (w.x() * d.y() - w.y() * d.x()) / den;
    if (t > 0 && u >= 0 && u <= 1) best = std::min(best, t);
  }
  return best;
}

}  // namespace tessera::test
