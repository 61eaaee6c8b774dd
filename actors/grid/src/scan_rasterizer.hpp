// Internal to tessera_actors_common: turns one range scan into the deduplicated list of cell
// updates that OccupancyGrid and TiledGrid apply, so both grids rasterise rays the same way and
// produce the same cells. Also the other pieces the two grids share: option checks, the growth
// policy and the ROS export.
//
// Units: the pose is in the grid's frame [m, rad]; cells are absolute indices at `resolution`
// (cell (i, j) covers [i·res, (i+1)·res) × [j·res, (j+1)·res)).
// Ownership: the rasterizer owns reusable scratch buffers: the updates and a bitmap of one bit
// per cell of the scan's box within the grid's storage (180 KB for 30 m beams at 5 cm; never
// per grid or per particle). updates() is a view into them, valid until the next classify() on
// the same object. forThisThread() hands out one
// instance per thread, so particles rasterised in parallel never share scratch.
#pragma once

#include <tessera/grid/occupancy_grid.hpp>

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::grid::detail {

/// One cell a scan updates; `hit` wins over misses from other beams (the cell was an
/// endpoint).
struct CellUpdate {
  Eigen::Vector2i cell;
  bool hit = false;
};

/// One beam endpoint inside the storage, for grids that keep per-cell hit positions. Unlike
/// updates(), every hit beam gives one, even when several end in the same cell.
struct HitPoint {
  Eigen::Vector2i cell;
  Eigen::Vector2f offset;  ///< endpoint − cell centre [cells], each coordinate in [−½, ½)
};

/// Use: classify() → the grid grows its storage towards need() → collect(storage) → apply
/// updates(). Splitting at the growth step lets clipped cells be counted per visit, exactly
/// like a grid touching cells one by one, and bounds the dedupe bitmap by the storage.
class ScanRasterizer {
 public:
  /// Pass 1: classifies the beams (every count of the result except clipped_cells) and sets
  /// need() and originCell().
  ScanInsertResult classify(const RangeScan& scan, const Pose2& sensor_pose,
                            const ScanInsertOptions& insert_options, double resolution);
  /// True when some beam will touch cells (the grid may need to grow).
  bool hasBeams() const { return !beams_.empty(); }
  /// Box of the sensor's cell and the endpoint cells of the contributing beams: every cell a
  /// beam crosses lies inside it. Empty when no beam contributes.
  const CellBox& need() const { return need_; }
  /// The sensor's cell: where a size-limited grid centres its first window.
  const Eigen::Vector2i& originCell() const { return origin_cell_; }

  /// Pass 2: walks every beam; visits outside `storage` are added to result.clipped_cells, the
  /// rest become updates(): each cell once, endpoint (hit) cells first, then in ray order.
  /// With `with_hit_points`, also fills hitPoints() (left empty otherwise, so grids that do not
  /// need them pay nothing).
  void collect(const CellBox& storage, ScanInsertResult& result, bool with_hit_points = false);
  std::span<const CellUpdate> updates() const { return updates_; }
  /// The exact endpoints of the hit beams that collect() kept, in beam order.
  std::span<const HitPoint> hitPoints() const { return hit_points_; }

  /// The calling thread's instance.
  static ScanRasterizer& forThisThread();

 private:
  struct Beam {
    Eigen::Vector2d end;  // grid units (cells), not metres
    bool hit;
  };
  std::vector<Beam> beams_;
  Eigen::Vector2d origin_{0.0, 0.0};  // grid units
  Eigen::Vector2i origin_cell_{0, 0};
  CellBox need_;
  std::vector<std::uint64_t> seen_;  // one bit per cell of the collect() window
  std::vector<CellUpdate> updates_;
  std::vector<HitPoint> hit_points_;
};

/// The storage box a grid grows `current` to so that `need` fits: aligned to `chunk` per axis
/// and at most `limit` wide. Past the limit, a first box is centred on `anchor` (the sensor)
/// and a later one keeps all of `current`, sharing the remaining room between the sides that
/// need it. Returns `current` when it already holds `need`.
CellBox growBox(const CellBox& current, const CellBox& need, const Eigen::Vector2i& anchor,
                int chunk, int limit);

/// The grids' shared cell convention: cell (i, j) covers [i·res, (i+1)·res) × [j·res, (j+1)·res).
inline Eigen::Vector2i cellOf(const Eigen::Vector2d& p, double res) {
  return {static_cast<int>(std::floor(p.x() / res)), static_cast<int>(std::floor(p.y() / res))};
}
inline Eigen::Vector2d cellCenterOf(const Eigen::Vector2i& c, double res) {
  return (c.cast<double>() + Eigen::Vector2d(0.5, 0.5)) * res;
}
inline Eigen::Vector2d cellCornerOf(const Eigen::Vector2i& c, double res) {
  return c.cast<double>() * res;
}
/// Occupancy probability of a log-odds: p = 1 − 1/(1 + e^L).
inline double probabilityOf(float log_odds) {
  return 1.0 - 1.0 / (1.0 + std::exp(static_cast<double>(log_odds)));
}

/// Option rules shared by the grids; throws std::invalid_argument prefixed with `who`.
void checkGridOptions(double resolution, const LogOddsModel& log_odds, int max_side_cells,
                      const std::string& who);

/// Grid::exportInt8 for any grid with isKnown() and logOdds(): ROS int8 cells of `box`,
/// row-major from box.min.y, −1 where unknown.
template <typename Grid>
void exportInt8(const Grid& grid, const CellBox& box, std::span<std::int8_t> out,
                const std::string& who) {
  const std::size_t w = static_cast<std::size_t>(box.width());
  if (out.size() != w * static_cast<std::size_t>(box.height()))
    throw std::invalid_argument(who + "::exportInt8: output holds " + std::to_string(out.size()) +
                                " cells, box needs " + std::to_string(w * box.height()));
  std::size_t o = 0;
  for (int j = box.min.y(); j <= box.max.y(); ++j) {
    for (int i = box.min.x(); i <= box.max.x(); ++i, ++o) {
      const Eigen::Vector2i c(i, j);
      out[o] = grid.isKnown(c) ? OccupancyGrid::rosValue(grid.logOdds(c)) : OccupancyMap::kUnknown;
    }
  }
}

/// Grid::toOccupancyMap: `box` of the grid as a ROS-convention map (empty for an empty box).
template <typename Grid>
OccupancyMap toOccupancyMap(const Grid& grid, const CellBox& box) {
  OccupancyMap map;
  map.resolution = grid.resolution();
  if (box.empty()) return map;
  map.width = box.width();
  map.height = box.height();
  const Eigen::Vector2d corner = grid.cellCorner(box.min);
  map.origin = Pose2(corner.x(), corner.y(), 0.0);
  map.cells.resize(static_cast<std::size_t>(map.width) * static_cast<std::size_t>(map.height));
  grid.exportInt8(box, map.cells);
  return map;
}

}  // namespace tessera::grid::detail
