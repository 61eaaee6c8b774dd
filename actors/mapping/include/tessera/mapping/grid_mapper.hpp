// GridMapper: occupancy grid mapping with known poses. Each laser scan is inserted into one
// log-odds grid (tessera::grid::TiledGrid: 2 bytes a cell, in tiles allocated where scans reach,
// so memory follows the mapped area) from the robot's pose in the map frame and the laser's
// mounting on the robot. Plain C++: no runtime or message types; the grid_mapper actor
// (grid_mapper_actor.hpp) feeds it from topics.
//
// Frames: robot_pose = base_link in map; mount = laser in base_link; both x forward, y left,
// theta counter-clockwise [rad]; lengths in metres.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/tiled_grid.hpp>

#include <cstdint>

namespace tessera::mapping {

/// Parameters of the mapper core; the grid_mapper actor reads them as its group `grid`.
struct GridMapperCoreOptions {
  double resolution = 0.05;      ///< [m/cell]
  double l_occ = 0.85;           ///< log-odds added at a beam endpoint
  double l_free = -0.4;          ///< log-odds added along a beam
  double l_min = -2.0;           ///< lower clamp
  double l_max = 3.5;            ///< upper clamp
  double max_range = 30.0;       ///< [m] returns beyond are not obstacles (clear up to here)
  double max_free_range = 10.0;  ///< [m] no-return beams clear this far (0: not at all)
  int max_side_cells = 16384;    ///< grid size limit per axis [cells]

  template <class V>
  void visit(V& v) {
    v("resolution", resolution, "grid cell size [m]");
    v("l_occ", l_occ, "log-odds added to a beam's endpoint cell (> 0)");
    v("l_free", l_free, "log-odds added to cells a beam crosses (< 0)");
    v("l_min", l_min, "lower log-odds clamp (< 0)");
    v("l_max", l_max, "upper log-odds clamp (> 0)");
    v("max_range", max_range, "returns farther than this [m] only clear free space up to it");
    v("max_free_range", max_free_range,
      "beams with no return (+inf or >= range_max) clear free space this far [m]; 0 disables");
    v("max_side_cells", max_side_cells,
      "the grid never exceeds this many cells per axis (guards against wild poses)");
  }
};

/// Running totals over all inserted scans.
struct GridMapperStats {
  std::uint64_t scans_inserted = 0;  ///< scans that contributed at least one beam
  std::uint64_t scans_skipped = 0;   ///< empty scans, all beams invalid, or unusable pose
  std::uint64_t beams_hit = 0;
  std::uint64_t beams_no_return = 0;
  std::uint64_t beams_beyond_range = 0;
  std::uint64_t beams_invalid = 0;  ///< NaN or < range_min
  std::uint64_t cells_clipped = 0;  ///< updates lost to the max_side_cells limit
};

class GridMapper {
 public:
  /// Throws std::invalid_argument naming the offending option.
  explicit GridMapper(const GridMapperCoreOptions& options = {});

  /// Inserts a scan taken with the robot at `robot_pose` (map frame) and the laser mounted at
  /// `mount` (base_link frame). Returns true when the scan contributed to the map.
  bool insert(const tessera::grid::RangeScan& scan, const tessera::Pose2& robot_pose,
              const tessera::Pose2& mount = {});
  /// Same with the laser's pose in the map frame given directly.
  bool insertFromSensorPose(const tessera::grid::RangeScan& scan,
                            const tessera::Pose2& sensor_pose);

  const tessera::grid::TiledGrid& grid() const { return grid_; }
  const GridMapperStats& stats() const { return stats_; }
  const GridMapperCoreOptions& options() const { return options_; }
  /// The map cropped to the known cells, in ROS int8 convention.
  tessera::grid::OccupancyMap map() const { return grid_.toOccupancyMap(); }

 private:
  GridMapperCoreOptions options_;
  tessera::grid::ScanInsertOptions insert_options_;
  tessera::grid::TiledGrid grid_;
  GridMapperStats stats_;
};

}  // namespace tessera::mapping
