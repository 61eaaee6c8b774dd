// A synthetic 20 x 16 m floor for the multi-robot tests: submaps of it as a robot in its own
// frame would build them (walls occupied, what it saw free, the rest unknown) and straight drives
// through it.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/laser_slam/map_merger.hpp>

#include <Eigen/Core>

#include <cmath>
#include <vector>

namespace tessera::test {

struct FloorBox {
  double x0, y0, x1, y1;
};

/// A 20 x 16 m floor: outer walls, an inner wall with a door, and furniture placed so that no
/// turn or mirror maps the floor onto itself.
inline std::vector<FloorBox> floorBoxes(bool moved_cabinet = false) {
  std::vector<FloorBox> b = {{0, 0, 20, 0.2},      {0, 15.8, 20, 16},   {0, 0, 0.2, 16},
                             {19.8, 0, 20, 16},    {8, 0, 8.2, 6},      {8, 7.2, 8.2, 16},
                             {2, 11, 4, 12},       {14, 3, 14.6, 6},    {11, 12, 12.5, 12.8},
                             {16.5, 10, 18, 10.4}, {4.5, 3.5, 5.3, 4.3}};
  if (moved_cabinet) b.back() = {3.0, 6.0, 3.8, 6.8};
  return b;
}

inline bool inside(const std::vector<FloorBox>& boxes, const Eigen::Vector2d& p) {
  for (const auto& b : boxes)
    if (p.x() >= b.x0 && p.x() <= b.x1 && p.y() >= b.y0 && p.y() <= b.y1) return true;
  return false;
}

/// A submap whose frame sits at `frame` in the floor (the robot's own frame, origin = its
/// start): walls occupied, the floor within `seen` metres of `centre` (floor coordinates) free,
/// the rest unknown. `turn`: the floor turned half a turn about its centre (a look-alike).
inline grid::OccupancyMap submap(const tessera::Pose2& frame, const Eigen::Vector2d& centre,
                                 double seen, const std::vector<FloorBox>& boxes,
                                 bool turn = false) {
  grid::OccupancyMap m;
  m.resolution = 0.05;
  m.width = m.height = 520;
  const tessera::Pose2 centre_local = frame.inverse() * tessera::Pose2(centre, 0.0);
  m.origin = tessera::Pose2(centre_local.x - 13, centre_local.y - 13, 0);
  m.cells.assign(static_cast<std::size_t>(m.width) * m.height, grid::OccupancyMap::kUnknown);
  for (int row = 0; row < m.height; ++row)
    for (int col = 0; col < m.width; ++col) {
      Eigen::Vector2d p = frame * m.cellCenter(col, row);
      if ((p - centre).norm() > seen) continue;
      if (turn) p = Eigen::Vector2d(20, 16) - p;
      if (p.x() < 0 || p.y() < 0 || p.x() > 20 || p.y() > 16) continue;
      m.at(col, row) = inside(boxes, p) ? 100 : 0;
    }
  return m;
}

/// A straight drive from `a` to `b` (floor coordinates) in the robot's frame `frame`.
inline std::vector<laser_slam::SubmapTrajectoryPose> drive(const tessera::Pose2& frame,
                                                           const Eigen::Vector2d& a,
                                                           const Eigen::Vector2d& b) {
  std::vector<laser_slam::SubmapTrajectoryPose> out;
  const double heading = std::atan2(b.y() - a.y(), b.x() - a.x());
  for (int k = 0; k <= 40; ++k) {
    const Eigen::Vector2d p = a + (b - a) * (k / 40.0);
    out.push_back({k * 100'000'000LL, frame.inverse() * tessera::Pose2(p, heading)});
  }
  return out;
}

}  // namespace tessera::test
