// A toy world for the localisation tests: a 12 x 9 m room with inner walls and boxes, a simulated
// 360° range finder over it, and a route through its three bays.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace tessera::test {

/// A 12 x 9 m room (5 cm cells) with an asymmetric set of inner walls and boxes.
inline grid::OccupancyMap toyRoom() {
  grid::OccupancyMap m;
  m.resolution = 0.05;
  m.width = 240;
  m.height = 180;
  m.cells.assign(static_cast<std::size_t>(m.width * m.height), 0);
  auto box = [&](double x0, double y0, double x1, double y1) {
    for (int r = 0; r < m.height; ++r)
      for (int c = 0; c < m.width; ++c) {
        const Eigen::Vector2d p = m.cellCenter(c, r);
        if (p.x() >= x0 && p.x() <= x1 && p.y() >= y0 && p.y() <= y1) m.at(c, r) = 100;
      }
  };
  box(0, 0, 12, 0.1);
  box(0, 8.9, 12, 9);
  box(0, 0, 0.1, 9);
  box(11.9, 0, 12, 9);
  box(4, 0, 4.1, 5);  // a wall from the bottom
  box(8, 4, 8.1, 9);  // a wall from the top
  box(1.5, 6.5, 2.5, 7.2);
  box(9.5, 1.0, 10.0, 2.5);
  box(5.5, 7.0, 6.0, 7.5);
  return m;
}

/// The bearing of beam b of `beams` spread over 360°, starting at −π.
inline double toyBeamAngle(int b, int beams) {
  return -std::numbers::pi + 2 * std::numbers::pi * b / beams;
}

/// Ranges of `beams` rays over 360° (toyBeamAngle) from pose, by marching the map, with 2 cm
/// Gaussian noise; +inf where nothing is hit within range_max.
inline std::vector<double> toyRanges(const grid::OccupancyMap& m, const Pose2& pose, int beams,
                                     double range_max, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, 0.02);
  std::vector<double> out(static_cast<std::size_t>(beams), std::numeric_limits<double>::infinity());
  for (int b = 0; b < beams; ++b) {
    const double a = toyBeamAngle(b, beams);
    const Eigen::Vector2d dir(std::cos(pose.theta + a), std::sin(pose.theta + a));
    for (double r = 0.05; r < range_max; r += 0.02) {
      const Eigen::Vector2i c = m.cellOf(Eigen::Vector2d(pose.x, pose.y) + r * dir);
      if (!m.contains(c.x(), c.y())) break;
      if (m.at(c.x(), c.y()) >= 65) {
        out[static_cast<std::size_t>(b)] = r + noise(rng);
        break;
      }
    }
  }
  return out;
}

/// The endpoints (robot frame) of toyRanges' hits.
inline std::vector<Eigen::Vector2d> toyScan(const grid::OccupancyMap& m, const Pose2& pose,
                                            int beams, double range_max, std::mt19937_64& rng) {
  const std::vector<double> ranges = toyRanges(m, pose, beams, range_max, rng);
  std::vector<Eigen::Vector2d> out;
  for (int b = 0; b < beams; ++b) {
    const double r = ranges[static_cast<std::size_t>(b)], a = toyBeamAngle(b, beams);
    if (std::isfinite(r)) out.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  return out;
}

/// A loop through the room's three bays, as poses every 10 cm.
inline std::vector<Pose2> toyRoute() {
  const std::vector<Eigen::Vector2d> corners = {{2, 2},   {2, 5.5},  {3.2, 8.0},  {6.5, 8.2},
                                                {6.5, 2}, {10.8, 3}, {10.8, 7.5}, {9, 8.2}};
  std::vector<Pose2> out;
  for (std::size_t i = 0; i + 1 < corners.size(); ++i) {
    const Eigen::Vector2d a = corners[i], b = corners[i + 1];
    const double heading = std::atan2(b.y() - a.y(), b.x() - a.x());
    const int n = static_cast<int>((b - a).norm() / 0.1);
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector2d p = a + (b - a) * (double(k) / n);
      out.emplace_back(p.x(), p.y(), heading);
    }
  }
  return out;
}

}  // namespace tessera::test
