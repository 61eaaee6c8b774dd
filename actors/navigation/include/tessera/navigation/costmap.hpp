// Costmap: a planar grid of traversal costs that planners search (docs/algorithms.md#costmaps).
//
// Same geometry as grid::OccupancyMap: cells row-major from the origin row, `origin` the pose of
// cell (0,0)'s outer corner in the map frame, `resolution` [m/cell]. Costs are bytes:
//   0 free … 252 (kMaxTraversable) increasingly close to obstacles,
//   253 kInscribed: the robot's centre here puts its footprint (a circle of the inscribed radius)
//       on an obstacle, 254 kLethal: an obstacle, 255 kUnknown: never observed.
// Layers (static, obstacle, 3D) write lethal / free / unknown cells; inflate() then raises the
// cells around lethal ones. The struct owns its cells.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <vector>

namespace tessera::navigation {

namespace cost {
inline constexpr std::uint8_t kFree = 0;
inline constexpr std::uint8_t kMaxTraversable = 252;
inline constexpr std::uint8_t kInscribed = 253;
inline constexpr std::uint8_t kLethal = 254;
inline constexpr std::uint8_t kUnknown = 255;
}  // namespace cost

struct Costmap {
  double resolution = 0.05;  ///< [m/cell]
  int width = 0;             ///< cells along x
  int height = 0;            ///< cells along y
  Pose2 origin;              ///< outer corner of cell (0,0) in the map frame
  std::vector<std::uint8_t> cells;

  Costmap() = default;
  /// A width x height map of `fill`; throws std::invalid_argument on a bad size or resolution.
  Costmap(int width, int height, double resolution, const Pose2& origin = {},
          std::uint8_t fill = cost::kFree);

  bool empty() const { return width <= 0 || height <= 0; }
  bool contains(int col, int row) const {
    return col >= 0 && row >= 0 && col < width && row < height;
  }
  bool contains(const Eigen::Vector2i& c) const { return contains(c.x(), c.y()); }
  std::size_t index(int col, int row) const {
    return static_cast<std::size_t>(row) * static_cast<std::size_t>(width) +
           static_cast<std::size_t>(col);
  }
  std::uint8_t at(int col, int row) const { return cells[index(col, row)]; }
  std::uint8_t& at(int col, int row) { return cells[index(col, row)]; }
  std::uint8_t at(const Eigen::Vector2i& c) const { return at(c.x(), c.y()); }

  /// Centre of cell (col, row) in the map frame.
  Eigen::Vector2d cellCenter(int col, int row) const {
    return origin * Eigen::Vector2d((col + 0.5) * resolution, (row + 0.5) * resolution);
  }
  Eigen::Vector2d cellCenter(const Eigen::Vector2i& c) const { return cellCenter(c.x(), c.y()); }
  /// The cell containing map-frame point p (may lie outside the map; check contains()).
  Eigen::Vector2i cellOf(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d local = origin.inverse() * p;
    return {static_cast<int>(std::floor(local.x() / resolution)),
            static_cast<int>(std::floor(local.y() / resolution))};
  }
};

/// Whether two costmaps lie on the same cells: size, resolution and origin equal.
inline bool sameGeometry(const Costmap& a, const Costmap& b) {
  return a.width == b.width && a.height == b.height && a.resolution == b.resolution &&
         a.origin.x == b.origin.x && a.origin.y == b.origin.y && a.origin.theta == b.origin.theta;
}

/// How an occupancy map (percent, -1 unknown) becomes costs: >= occupied_threshold lethal,
/// <= free_threshold free, between them and unknown cells `unknown` (free when
/// unknown_is_free, e.g. to plan through unexplored space while mapping).
struct StaticLayerOptions {
  int occupied_threshold = 65;  ///< [%] like map_server's occupied_thresh 0.65
  int free_threshold = 25;      ///< [%] like map_server's free_thresh 0.25
  bool unknown_is_free = false;

  template <class V>
  void visit(V& v) {
    v("occupied_threshold", occupied_threshold,
      "[%] occupancy at and above which a cell is lethal");
    v("free_threshold", free_threshold, "[%] occupancy at and below which a cell is free");
    v("unknown_is_free", unknown_is_free, "plan through unknown cells");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

/// The static layer: costs of an occupancy map (same geometry).
Costmap fromOccupancy(const grid::OccupancyMap& map, const StaticLayerOptions& options = {});

/// `map`'s costs on the geometry of `frame` (its cells are overwritten): each cell takes the cost
/// of `map` at its centre, kUnknown outside `map`. Lets a growing SLAM map fill a fixed costmap,
/// so that what the robot saw before the map grew (the obstacle layer) stays in place.
void paste(const Costmap& map, Costmap& frame);

/// Inflation: cells within inscribed_radius of a lethal cell become kInscribed; beyond it, up to
/// inflation_radius, cost 252 · exp(−cost_scaling · (d − inscribed_radius)) (d = distance between
/// cell centres [m]). Inflation never lowers a cost; unknown cells stay unknown.
struct InflationOptions {
  double inscribed_radius = 0.20;  ///< [m] the robot's inscribed radius
  double inflation_radius = 0.55;  ///< [m] where the decay stops
  double cost_scaling = 10.0;      ///< [1/m] decay rate

  template <class V>
  void visit(V& v) {
    v("inscribed_radius", inscribed_radius, "[m] robot's inscribed radius");
    v("inflation_radius", inflation_radius, "[m] distance from obstacles where costs reach 0");
    v("cost_scaling", cost_scaling, "[1/m] exponential decay of cost with distance");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

/// Distance [m] from each cell centre to the nearest lethal cell centre (exact Euclidean
/// transform; +inf when the map has no lethal cell). Row-major like the costmap.
std::vector<float> obstacleDistance(const Costmap& map);

void inflate(Costmap& map, const InflationOptions& options);

}  // namespace tessera::navigation
