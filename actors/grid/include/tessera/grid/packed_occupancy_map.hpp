// PackedOccupancyMap: an OccupancyMap whose cells are kept zstd-compressed, for holders of many
// finished grids that read only one at a time (the loop detector's submaps, rebuilt into a
// matcher pyramid on a cache miss; the map assembler's submaps, drawn one by one).
//
// It keeps the map's geometry as given — resolution [m/cell], width × height [cells] and origin
// (pose of cell (0,0)'s outer corner in the map's parent frame; metres, radians), so the same
// frames as OccupancyMap — and one zstd frame of its width·height int8 cells (row-major, ROS
// values: −1 unknown, 0..100 %). unpack() gives back the exact cells: lossless, so anything
// computed from the unpacked grid (a pyramid, an assembled map) is unchanged.
//
// Ownership: the object owns its compressed bytes; it borrows nothing, and unpack() returns a
// new OccupancyMap the caller owns. Immutable after construction, so const use (unpack) is
// thread-safe; copying copies the compressed bytes.
//
// Ratio: finished submaps are mostly unknown with runs of free space, so they compress very
// well. Measured on the 25 submaps of the Intel log (carmen_global, seed 1): 6.77 MB of cells →
// 0.49 MB at level 1 (13.8×, 11–26× per submap), compressing at ~1 GB/s and decompressing at
// ~2.9 GB/s (one core).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tessera::grid {

class PackedOccupancyMap {
 public:
  /// An empty map: 0 × 0 cells, nothing held.
  PackedOccupancyMap() = default;
  /// Compresses `map`'s cells. Throws std::invalid_argument when width or height is negative or
  /// cells.size() != width·height, and std::runtime_error if zstd fails.
  explicit PackedOccupancyMap(const OccupancyMap& map);

  /// The map with its exact cells. Throws std::runtime_error naming the problem when the
  /// compressed bytes do not decompress to exactly width·height cells (it never returns a
  /// grid of the wrong size).
  OccupancyMap unpack() const;

  /// Heap bytes held: the compressed cells (capacity).
  std::size_t bytes() const { return packed_.capacity(); }
  /// Cells the map has (width·height), i.e. the bytes unpack() allocates for them.
  std::size_t cellCount() const {
    return static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  }
  bool empty() const { return width_ <= 0 || height_ <= 0; }
  int width() const { return width_; }
  int height() const { return height_; }
  double resolution() const { return resolution_; }  ///< [m/cell]
  const Pose2& origin() const { return origin_; }    ///< outer corner of cell (0,0)

 private:
  double resolution_ = 0.05;
  int width_ = 0;
  int height_ = 0;
  Pose2 origin_;
  std::vector<std::uint8_t> packed_;  // one zstd frame; none when the map has no cells
};

}  // namespace tessera::grid
