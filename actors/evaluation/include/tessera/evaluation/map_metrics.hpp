// Occupancy-grid map quality against the true walls (docs/algorithms.md#evaluation-metrics).
//
// The walls are line segments in the map's frame [m] (a simulator's walls.txt moved by the pose
// of the SLAM's map frame in the world). Figures:
//  * wall_cells_found: of the true wall points (sampled every half cell along each wall) whose
//    neighbourhood the map observed (a known cell within `tolerance_m`), the fraction with an
//    occupied cell within `tolerance_m`;
//  * false_wall_cells: occupied cells farther than `tolerance_m` from every true wall (walls drawn
//    where there are none);
//  * doubled_wall_cells: the false wall cells within `doubled_range_m` of a true wall that is also
//    drawn where it is (an occupied cell within `tolerance_m` of the wall point nearest the
//    cell): a wall drawn a second time beside itself by a misaligned pass;
//  * displaced_wall_cells: the other false wall cells within `doubled_range_m` of a true wall:
//    a wall drawn once, beside its place (a map bent or scaled there, or an unseen wall end).
// Occupied = cell value >= occupied_threshold (ROS percent).
#pragma once

#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <utility>
#include <vector>

namespace tessera::evaluation {

struct WallSegment {
  Eigen::Vector2d a = Eigen::Vector2d::Zero(), b = Eigen::Vector2d::Zero();  ///< [m]
};

struct MapWallOptions {
  double tolerance_m = 0.15;     ///< a cell this close to a wall is on it
  double doubled_range_m = 1.0;  ///< false wall cells this close to a wall: doubled or displaced
  int occupied_threshold = 65;   ///< ROS percent
};

struct MapWallScore {
  std::size_t wall_points_seen = 0;   ///< true wall points in observed area
  std::size_t wall_points_found = 0;  ///< of those, with an occupied cell near
  double wall_cells_found = 0;        ///< found / seen, 0 when none seen
  std::size_t occupied_cells = 0;
  std::size_t false_wall_cells = 0;
  std::size_t doubled_wall_cells = 0;
  std::size_t displaced_wall_cells = 0;
};

/// Throws std::invalid_argument for an empty map or non-positive tolerances.
MapWallScore scoreMapAgainstWalls(const grid::OccupancyMap& map,
                                  const std::vector<WallSegment>& walls,
                                  const MapWallOptions& options = {});

/// Reads a walls file of "x0 y0 x1 y1" lines ('#' comments). Throws std::runtime_error naming the
/// file and line for a malformed or non-finite line, or when the file cannot be read.
std::vector<WallSegment> readWalls(const std::string& path);

}  // namespace tessera::evaluation
