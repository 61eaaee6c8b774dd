// MapAssembler: draws submaps (occupancy grids, each in its own frame) into one global grid at
// their global poses. When the graph optimiser moves a submap, only its pose changes; the next
// assemble() redraws from the submaps' own cells.
//
// Memory: each submap's cells are kept zstd-compressed (grid::PackedOccupancyMap, lossless;
// ~14x smaller on the Intel submaps); assemble() and grid() unpack one submap at a time, so
// besides the packed bytes (bytes()) only one submap's cells and the global map are held.
//
// Combination: every global cell samples each submap at the cell's centre (nearest submap cell)
// and sums the log-odds of the known values, as if the submaps were independent evidence, then
// turns the sum back into a ROS int8 value. Unknown everywhere stays unknown (-1).
// Frames: submap grids in their submap frame (OccupancyMap.origin there), global poses = submap
// origin in the map frame; metres, radians. Plain C++, not thread-safe.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/grid/packed_occupancy_map.hpp>

#include <cstddef>
#include <map>
#include <optional>

namespace tessera::laser_slam {

class MapAssembler {
 public:
  /// resolution [m/cell] of the assembled map; 0 = the finest submap resolution.
  explicit MapAssembler(double resolution = 0.0);

  /// Adds or replaces submap `id` (its cells and their frame).
  void setSubmap(int id, tessera::grid::OccupancyMap grid);
  /// Places submap `id` (pose of its origin in the map frame). Submaps without a pose are not
  /// drawn.
  void setPose(int id, const tessera::Pose2& global_pose);
  /// Forgets submap `id` (lifelong mapping trimmed it); false when there was none.
  bool removeSubmap(int id) { return submaps_.erase(id) > 0; }
  bool hasPose(int id) const;
  tessera::Pose2 pose(int id) const;
  /// Submap `id`'s grid (unpacked: a copy the caller owns), or nullopt when it has no cells.
  std::optional<tessera::grid::OccupancyMap> grid(int id) const;
  std::size_t size() const { return submaps_.size(); }
  /// Heap bytes of the packed cells of every submap.
  std::size_t bytes() const;

  /// The global map covering every placed submap (empty when none).
  tessera::grid::OccupancyMap assemble() const;

 private:
  struct Entry {
    tessera::grid::PackedOccupancyMap grid;
    tessera::Pose2 pose;
    bool placed = false;
  };
  double resolution_;
  std::map<int, Entry> submaps_;
};

}  // namespace tessera::laser_slam
