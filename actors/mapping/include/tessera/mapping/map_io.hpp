// Occupancy maps on disk in the ROS map_server format: an image (PGM, or anything OpenCV reads)
// plus a YAML file with image, resolution [m/cell], origin [x, y, yaw] (pose of the lower-left
// pixel's outer corner in the map frame), negate, occupied_thresh and free_thresh.
//
// Writing is trinary: occupied → 0 (black), free → 254 (white), unknown → 205 (grey), with a
// cell's class taken the way map_server reads it back (p = value/100; p > occupied_thresh is
// occupied, p < free_thresh is free), so save → load gives the same classes. map.png is the same
// picture for people. Image row 0 is the top of the map (largest y); grid::OccupancyMap row 0 is
// the bottom, and the functions here flip between the two.
//
// Errors (unreadable, malformed or inconsistent files) throw MapIoError naming the file and
// what was expected.
#pragma once

#include <tessera/grid/occupancy_map.hpp>
#include <tessera/io/image_file.hpp>

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <vector>

namespace tessera::mapping {

class MapIoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// An 8-bit grey image, row 0 at the top (pixels: width*height, row-major).
using GrayImage = io::Gray8;

struct MapSaveOptions {
  double occupied_thresh = 0.65;  ///< cells with p > this are drawn black
  double free_thresh = 0.196;     ///< cells with p < this are drawn white
  bool write_png = true;          ///< also write <base>.png
};

/// Paths written by saveMap().
struct SavedMap {
  std::filesystem::path yaml, pgm, png;  ///< png is empty when not written
};

/// Writes <base>.pgm, <base>.yaml and (optionally) <base>.png, e.g. base = "out/map".
/// The YAML names the image relative to itself. Throws MapIoError on an empty map or a write
/// failure.
SavedMap saveMap(const grid::OccupancyMap& map, const std::filesystem::path& base,
                 const MapSaveOptions& options = {});

/// Loads a map from its YAML (as written by saveMap or by ROS map_saver). Supports the
/// map_server modes trinary (default), scale and raw, and negate. Cells: 100 occupied, 0 free,
/// −1 unknown (scale mode: 0..100 in between). Throws MapIoError.
grid::OccupancyMap loadMap(const std::filesystem::path& yaml_path);

/// Trinary picture of a map (row 0 at the top).
GrayImage renderTrinary(const grid::OccupancyMap& map, const MapSaveOptions& options = {});

/// Binary PGM (P5, maxval 255) writer and P5/P2 reader (maxval up to 255, scaled to 0..255).
void writePgm(const GrayImage& image, const std::filesystem::path& path);
GrayImage readPgm(const std::filesystem::path& path);

}  // namespace tessera::mapping
