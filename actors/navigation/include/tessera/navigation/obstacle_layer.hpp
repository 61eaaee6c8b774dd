// ObstacleLayer: obstacles the robot sees now, kept as height slices per cell and merged into a
// costmap (docs/algorithms.md#costmaps).
//
// Each cell of the costmap's geometry holds 16 height slices covering the robot's band
// [min_height, max_height] (a small voxel column). Laser scans (rays at the laser's height) and 3D
// points from a depth camera or an OctoMap share it. A point in the band marks its slice in the
// cell beneath it; every ray clears, in each cell it crosses before its endpoint, the slice at the
// height it crosses that cell (and only while in the band). So a table top at 0.75 m blocks the
// floor cells under it, a planar laser at 0.2 m passing beneath the table never clears it, and a
// camera ray to the floor behind the table crosses the table's cells above or below its top.
// A cell is an obstacle while any slice is marked, free once a ray crossed it with none marked,
// unknown before. Points outside the band never mark. Map-frame coordinates [m], z up from the
// floor. Not thread-safe: one owner.
#pragma once

#include <tessera/navigation/costmap.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <span>
#include <vector>

namespace tessera::navigation {

struct ObstacleLayerOptions {
  double mark_range =
      2.5;  ///< [m] points farther than this from the sensor (in the plane) do not mark
  double clear_range = 3.0;  ///< [m] clearing stops this far from the sensor (in the plane)
  double min_height = 0.05;  ///< [m] lowest obstacle height (above the floor's noise)
  double max_height = 1.0;   ///< [m] highest point the robot could hit

  template <class V>
  void visit(V& v) {
    v("mark_range", mark_range, "[m] farthest point that marks an obstacle");
    v("clear_range", clear_range, "[m] farthest distance cleared along a ray");
    v("min_height", min_height, "[m] lowest height that is an obstacle");
    v("max_height", max_height, "[m] highest height that is an obstacle (the robot's height)");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

class ObstacleLayer {
 public:
  enum class Cell : std::uint8_t { kUnknown, kFree, kObstacle };
  static constexpr int kSlices = 16;

  /// A layer over `geometry`'s cells (its costs are not used).
  explicit ObstacleLayer(const Costmap& geometry, const ObstacleLayerOptions& options = {});

  /// A planar scan taken at `sensor` (map frame; z = the laser's height): beam endpoints in the
  /// map plane; `no_return` flags (empty = none) beams that hit nothing, which only clear.
  /// Non-finite endpoints are skipped.
  void addScan(const Eigen::Vector3d& sensor, std::span<const Eigen::Vector2d> endpoints,
               std::span<const std::uint8_t> no_return = {});
  /// 3D points (map frame) seen from `sensor`.
  void addPoints(const Eigen::Vector3d& sensor, std::span<const Eigen::Vector3d> points);
  /// Obstacles become lethal in `map`; observed free cells turn kUnknown into kFree; other
  /// costs stay. Throws std::invalid_argument when `map` has another size.
  void applyTo(Costmap& map) const;
  void clear();

  Cell at(int col, int row) const;
  std::size_t obstacleCount() const;

 private:
  std::size_t index(int col, int row) const {
    return static_cast<std::size_t>(row) * static_cast<std::size_t>(geometry_.width) +
           static_cast<std::size_t>(col);
  }
  int slice(double z) const;  ///< -1 outside the band
  void clearRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to);
  void mark(const Eigen::Vector3d& sensor, const Eigen::Vector3d& p);

  Costmap geometry_;  // cells unused
  ObstacleLayerOptions options_;
  std::vector<std::uint16_t> slices_;  // marked slices per cell
  std::vector<std::uint8_t> seen_;     // a ray crossed the cell in the band
};

}  // namespace tessera::navigation
