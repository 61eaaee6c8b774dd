// MapTiler: an occupancy grid as square tiles on the world's cell lattice, and which tiles
// changed since the last grid (docs/viewer.md#map-tiles). The live viewer sends a browser only
// the tiles that changed, so a growing SLAM map costs what changed, not the whole map.
//
// Tiles are anchored to the lattice of cells at integer multiples of the resolution (plus a
// fixed sub-cell offset), not to the grid's corner: a map that grows by cells keeps its old
// tiles. A new resolution, a rotated origin, another sub-cell offset, or a grid that no longer
// covers a tile it covered starts a new epoch (every tile is sent again).
//
// Bytes (little-endian), the server's parts-channel header and parts (foxglove_server.hpp):
//   header: f64 resolution [m] | f64 offset_x | f64 offset_y [m] | u32 tile_size [cells] |
//           i64 map stamp [ns] | i64 wall time the map was received [ns since the Unix epoch]
//   tile:   i32 tx | i32 ty | tile_size^2 x i8 cells, row-major from the tile's lowest-y row
//           (0..100 occupancy %, -1 unknown; cells outside the grid are -1)
// The cell (cx, cy) of tile (tx, ty) has its lower-left corner at
//   ((tx * tile_size + cx) * resolution + offset_x, (ty * tile_size + cy) * resolution + offset_y).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tessera::viewer {

/// A row-major occupancy grid (row 0 at origin_y), borrowed for one call.
struct GridView {
  double resolution = 0;               ///< [m/cell]
  int width = 0, height = 0;           ///< cells
  double origin_x = 0, origin_y = 0;   ///< [m] cell (0,0)'s outer corner
  double origin_theta = 0;             ///< [rad]
  const std::int8_t* cells = nullptr;  ///< width * height
  std::size_t cell_count = 0;          ///< cells held at `cells` (a message's byte count);
                                       ///< must equal width * height
};

class MapTiler {
 public:
  struct Update {
    std::uint64_t epoch = 0;
    bool new_epoch = false;
    std::string header;
    std::vector<std::pair<std::uint64_t, std::string>> tiles;  ///< key, bytes: changed only
  };
  explicit MapTiler(int tile_size = 64);

  /// The tiles of `grid` that differ from the last grid's. Throws std::invalid_argument for a
  /// grid that is not drawable (resolution <= 0 or not finite, negative size, no cells).
  Update update(const GridView& grid, std::int64_t stamp_ns, std::int64_t received_wall_ns);

  std::size_t tiles() const { return tiles_.size(); }

 private:
  int tile_size_;
  std::uint64_t epoch_ = 0;
  bool have_ = false;
  double resolution_ = 0, offset_x_ = 0, offset_y_ = 0;
  std::map<std::uint64_t, std::string> tiles_;  ///< key -> cells
};

/// The key of tile (tx, ty) (both in int32 range).
std::uint64_t tileKey(std::int32_t tx, std::int32_t ty);

}  // namespace tessera::viewer
