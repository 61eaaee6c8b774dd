// OccupancyGrid: a growing 2D log-odds occupancy grid
// (docs/algorithms.md#occupancy-grid-log-odds: S⁺ = clamp(S⁻ + l_meas, l_min, l_max), S_init = 0).
//
// Frames and units: everything is in one planar frame (normally "map"), metres and radians.
// Cells are addressed by absolute integer indices: cell (i, j) covers
//   [i·res, (i+1)·res) × [j·res, (j+1)·res)
// so a cell's index and position never change when the grid grows. Storage covers an allocated
// box of cells that grows in chunks to fit what is inserted, up to max_side_cells per axis
// (a guard against a wild pose allocating gigabytes); cells beyond it are dropped and counted.
//
// Scan insertion: each valid return marks its endpoint cell occupied (l_occ) and the cells a
// ray from the sensor crosses before it free (l_free, exact grid traversal). Within one scan a
// cell is updated at most once and a hit wins over a miss, so grazing beams do not erase thin
// walls and cells near the sensor are not over-counted by the many beams that cross them.
// Beams with no return clear free space up to a configured length without marking anything.
//
// Export: ROS int8 (−1 unknown, 0..100 percent), probabilities, the box of known cells.
// Not thread-safe for writing; const methods may be called concurrently.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera::grid {

/// An inclusive box of absolute cell indices; empty when max < min on either axis.
struct CellBox {
  Eigen::Vector2i min{0, 0};
  Eigen::Vector2i max{-1, -1};

  bool empty() const { return max.x() < min.x() || max.y() < min.y(); }
  int width() const { return empty() ? 0 : max.x() - min.x() + 1; }
  int height() const { return empty() ? 0 : max.y() - min.y() + 1; }
  bool contains(const Eigen::Vector2i& c) const {
    return c.x() >= min.x() && c.y() >= min.y() && c.x() <= max.x() && c.y() <= max.y();
  }
  /// Grows the box to include c.
  void extend(const Eigen::Vector2i& c) {
    if (empty()) {
      min = max = c;
    } else {
      min = min.cwiseMin(c);
      max = max.cwiseMax(c);
    }
  }
};

/// Log-odds increments and clamping bounds (natural log of odds).
struct LogOddsModel {
  float hit = 0.85f;   ///< l_occ added at a beam endpoint (> 0)
  float miss = -0.4f;  ///< l_free added to cells a beam crosses (< 0)
  float min = -2.0f;   ///< lower clamp (< 0); keeps free cells able to turn occupied again
  float max = 3.5f;    ///< upper clamp (> 0)

  template <class V>
  void visit(V& v) {
    v("hit", hit, "log-odds added at a beam endpoint (> 0)");
    v("miss", miss, "log-odds added to cells a beam crosses (< 0)");
    v("min", min, "lower log-odds clamp (< 0)");
    v("max", max, "upper log-odds clamp (> 0)");
  }
};

/// One planar sweep in the sensor frame (ROS LaserScan semantics). Borrowed, not owned.
/// Beam k points at angle_min + k·angle_increment [rad]; ranges in metres. +inf or ≥ range_max
/// means no return; NaN and values < range_min are invalid.
struct RangeScan {
  std::span<const float> ranges;
  double angle_min = 0.0;
  double angle_increment = 0.0;
  double range_min = 0.0;
  double range_max = 0.0;
};

/// How a scan's beams turn into cell updates.
struct ScanInsertOptions {
  /// [m] returns farther than this are not trusted as obstacles: the beam clears free space
  /// up to max_range and marks no endpoint.
  double max_range = 30.0;
  /// [m] beams with no return (+inf or ≥ range_max) clear free space this far; 0 disables.
  double max_free_range = 10.0;

  template <class V>
  void visit(V& v) {
    v("max_range", max_range,
      "returns farther than this [m] are not obstacles: the beam clears free space up to it");
    v("max_free_range", max_free_range,
      "no-return beams clear free space this far [m]; 0 disables");
  }
};

/// What one insertScan() did with its beams.
struct ScanInsertResult {
  std::size_t hits = 0;           ///< endpoint marked occupied
  std::size_t no_return = 0;      ///< +inf / ≥ range_max: cleared up to max_free_range
  std::size_t beyond_range = 0;   ///< return past max_range: cleared up to max_range
  std::size_t invalid = 0;        ///< NaN, < range_min, or the whole scan/pose was unusable
  std::size_t clipped_cells = 0;  ///< cell updates dropped outside the max_side_cells limit
  /// True when at least one beam contributed (the scan changed the grid or could have).
  bool used() const { return hits + no_return + beyond_range > 0; }
};

struct OccupancyGridOptions {
  double resolution = 0.05;  ///< [m/cell]
  LogOddsModel log_odds;
  int chunk_cells = 64;        ///< growth granularity per axis [cells]
  int max_side_cells = 16384;  ///< hard limit per axis [cells]
};

class OccupancyGrid {
 public:
  using Options = OccupancyGridOptions;

  /// Throws std::invalid_argument for non-positive resolution, inconsistent log-odds signs, or
  /// non-positive chunk/limit sizes.
  explicit OccupancyGrid(Options options = {});

  const Options& options() const { return options_; }
  double resolution() const { return options_.resolution; }

  /// The cell containing map-frame point p.
  Eigen::Vector2i worldToCell(const Eigen::Vector2d& p) const;
  /// Centre of cell c [m].
  Eigen::Vector2d cellCenter(const Eigen::Vector2i& c) const;
  /// Lower-left (outer) corner of cell c [m].
  Eigen::Vector2d cellCorner(const Eigen::Vector2i& c) const;

  /// Cells that have storage (known or not).
  const CellBox& allocated() const { return allocated_; }
  /// Smallest box holding every cell updated at least once (empty before the first update).
  const CellBox& knownBounds() const { return known_bounds_; }
  /// Number of cells updated at least once.
  std::size_t knownCount() const { return known_count_; }

  bool isKnown(const Eigen::Vector2i& c) const;
  /// Log-odds of c; 0 (S_init) for unknown cells and cells outside the grid.
  float logOdds(const Eigen::Vector2i& c) const;
  /// Occupancy probability of c; 0.5 when unknown.
  double probability(const Eigen::Vector2i& c) const;

  /// Integrates one scan taken from `sensor_pose` (laser frame in the grid's frame).
  /// Never throws on bad data: NaN/negative ranges, an empty scan, or a non-finite pose are
  /// counted in the result (see ScanInsertResult) and leave the grid untouched.
  ScanInsertResult insertScan(const RangeScan& scan, const Pose2& sensor_pose,
                              const ScanInsertOptions& insert_options = {});

  /// ROS int8 value of a log-odds: round(100·p), p = 1 − 1/(1 + e^L).
  static std::int8_t rosValue(float log_odds);
  /// Writes ROS int8 cells for `box` into `out` (box.width()·box.height() values, row-major,
  /// row 0 = box.min.y). Cells never updated or outside the grid are −1.
  void exportInt8(const CellBox& box, std::span<std::int8_t> out) const;
  /// The grid as a ROS-convention map cropped to `box` (default: the known cells).
  OccupancyMap toOccupancyMap() const { return toOccupancyMap(known_bounds_); }
  OccupancyMap toOccupancyMap(const CellBox& box) const;

 private:
  std::size_t indexOf(const Eigen::Vector2i& c) const;
  /// Grows storage (in chunks, up to the per-axis limit) so that `need` fits where possible.
  void growToInclude(const CellBox& need, const Eigen::Vector2i& anchor);

  Options options_;
  CellBox allocated_;
  CellBox known_bounds_;
  std::size_t known_count_ = 0;
  std::vector<float> log_odds_;
  std::vector<std::uint8_t> known_;  // per cell: updated at least once
};

}  // namespace tessera::grid
