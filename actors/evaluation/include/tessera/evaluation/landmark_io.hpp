// Landmark maps as text files, for evaluation: an estimated map written by a SLAM run and a
// reference map (surveyed or simulated) in the same format.
//
// Format: one landmark per line, `id x y` — id an integer, x and y in metres in the map frame.
// Lines starting with '#' and blank lines are comments. Ids are unique within a file; the order
// of lines does not matter. Example:
//   # id x y
//   7 12.5 -3.25
//   12 4 0.5
//
// Errors throw LandmarkFileError naming file:line and what was expected.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::evaluation {

class LandmarkFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Landmark {
  std::int64_t id = 0;
  Eigen::Vector2d position = Eigen::Vector2d::Zero();  ///< [m], map frame
};

/// Parses landmark lines from `text` as if it were the file `name` (for tests). Throws on
/// malformed lines, non-finite coordinates and duplicate ids.
std::vector<Landmark> parseLandmarks(std::string_view text, const std::string& name);
/// Reads a landmark file (in file order). Throws LandmarkFileError.
std::vector<Landmark> readLandmarks(const std::filesystem::path& path);
/// Writes `id x y` lines with a comment header; coordinates round-trip exactly.
void writeLandmarks(const std::filesystem::path& path, const std::vector<Landmark>& landmarks);

}  // namespace tessera::evaluation
