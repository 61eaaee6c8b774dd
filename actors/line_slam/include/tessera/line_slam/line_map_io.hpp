// Line maps on disk and against ground truth: the lines CSV and SVG drawing written by
// line-feature SLAM runs, the `x0 y0 x1 y1` wall files the simulator's world_writer writes, and
// a score of a line map against those true walls. Coordinates in metres in the map frame.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tessera::line_slam {

/// A finite line segment of a map (estimate or ground truth).
struct MapSegment {
  std::int64_t id = -1;
  Eigen::Vector2d p0 = Eigen::Vector2d::Zero(), p1 = Eigen::Vector2d::Zero();
  double r = 0.0, phi = 0.0;                             ///< polar form (see line_extraction.hpp)
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  ///< over (r, φ); zero = unknown
  std::int64_t observations = 0;
};

/// Reads `x0 y0 x1 y1` lines ('#' comments, blank lines skipped). Throws std::runtime_error
/// naming the file and line on a malformed or non-finite row, or when the file cannot be read.
std::vector<MapSegment> readWallSegments(const std::filesystem::path& path);

/// CSV: id,r,phi,var_r,cov_r_phi,var_phi,x0,y0,x1,y1,observations. Throws on write failure.
void writeLinesCsv(const std::filesystem::path& path, const std::vector<MapSegment>& lines);

/// SVG drawing (1 m = `pixels_per_m` px, y up): `walls` in grey beneath, the map `lines` in
/// blue, and `trajectory` (may be empty) as a red polyline. Throws on write failure.
void writeLinesSvg(const std::filesystem::path& path, const std::vector<MapSegment>& lines,
                   const std::vector<MapSegment>& walls,
                   const std::vector<Eigen::Vector2d>& trajectory, double pixels_per_m = 60.0);

struct LineMapScoreOptions {
  double max_angle = 0.0873;  ///< [rad] a line and a wall within 5° ...
  double max_distance = 0.1;  ///< [m] ... the wall's end points this close to the line ...
  double min_coverage = 0.5;  ///< ... and the line covering this fraction of the wall
};

struct LineMapScore {
  int walls = 0;           ///< true walls
  int walls_matched = 0;   ///< walls covered by at least one map line
  int lines = 0;           ///< map lines
  int lines_on_walls = 0;  ///< map lines lying on some wall (the rest are spurious)
};

/// Compares a line map with true walls (both in the same frame).
LineMapScore scoreLineMap(const std::vector<MapSegment>& lines,
                          const std::vector<MapSegment>& walls,
                          const LineMapScoreOptions& options = {});

}  // namespace tessera::line_slam
