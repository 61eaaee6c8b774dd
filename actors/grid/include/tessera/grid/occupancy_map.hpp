// OccupancyMap: a finished occupancy grid in the ROS nav_msgs/OccupancyGrid convention, the form
// maps take when they leave a mapper (messages, PGM/YAML files) and when a localiser loads them.
//
// Cells are row-major, row 0 at the origin's y (the bottom of the map when drawn), column 0 at
// the origin's x. Values: -1 unknown, 0..100 occupancy probability in percent. `origin` is the
// pose of cell (0,0)'s outer corner in the map frame (x, y [m], yaw [rad]); `resolution` is the
// cell size [m/cell]. The struct owns its cells.
#pragma once

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <vector>

namespace tessera::grid {

struct OccupancyMap {
  static constexpr std::int8_t kUnknown = -1;

  double resolution = 0.05;        ///< [m/cell]
  int width = 0;                   ///< cells along x
  int height = 0;                  ///< cells along y
  Pose2 origin;                    ///< outer corner of cell (0,0) in the map frame
  std::vector<std::int8_t> cells;  ///< width*height values, row-major from the origin row

  bool empty() const { return width <= 0 || height <= 0; }
  bool contains(int col, int row) const {
    return col >= 0 && row >= 0 && col < width && row < height;
  }
  std::int8_t at(int col, int row) const {
    return cells[static_cast<std::size_t>(row) * width + col];
  }
  std::int8_t& at(int col, int row) { return cells[static_cast<std::size_t>(row) * width + col]; }

  /// Centre of cell (col, row) in the map frame.
  Eigen::Vector2d cellCenter(int col, int row) const {
    return origin * Eigen::Vector2d((col + 0.5) * resolution, (row + 0.5) * resolution);
  }
  /// The cell containing map-frame point p (may lie outside the map; check contains()).
  Eigen::Vector2i cellOf(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d local = origin.inverse() * p;
    return {static_cast<int>(std::floor(local.x() / resolution)),
            static_cast<int>(std::floor(local.y() / resolution))};
  }
};

}  // namespace tessera::grid
