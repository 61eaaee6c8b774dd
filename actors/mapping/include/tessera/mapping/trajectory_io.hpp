// Trajectories in the TUM RGB-D format: one pose per line, `t x y z qx qy qz qw`, t in seconds,
// position in metres, orientation as a unit quaternion (Hamilton, w last). Lines starting with
// '#' and blank lines are comments. Planar poses are written with z = 0 and a rotation about z.
//
// Time stamps are int64 nanoseconds in memory and are written with exactly 9 decimals, so a
// write/read round trip is exact (no double rounding). The reader accepts any decimal or
// exponent notation other tools produce.
//
// Errors throw TrajectoryError naming file:line and what was expected.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/io/atomic_file.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::mapping {

class TrajectoryError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One line of a TUM file.
struct TumPose {
  std::int64_t stamp_ns = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();

  static TumPose fromPlanar(std::int64_t stamp_ns, const Pose2& pose);
  /// Projection to the plane: (x, y) and the yaw of the orientation.
  Pose2 planar() const;
};

/// "t x y z qx qy qz qw" (no newline).
std::string formatTumLine(const TumPose& pose);
/// Parses one data line; throws TrajectoryError prefixed with `where` (e.g. "file:12").
TumPose parseTumLine(std::string_view line, const std::string& where);

/// Streams poses to a file as they come. They go to a temporary file next to `path`
/// (io::AtomicFile); close() renames it over `path`, so `path` only ever holds a complete
/// trajectory. Destroyed without close(), the temporary file is removed and `path` is untouched.
class TumWriter {
 public:
  /// Creates the folder and the temporary file and writes a comment header. Throws
  /// TrajectoryError.
  explicit TumWriter(const std::filesystem::path& path);
  void write(const TumPose& pose);
  void write(std::int64_t stamp_ns, const Pose2& pose) {
    write(TumPose::fromPlanar(stamp_ns, pose));
  }
  /// Hands the poses so far to the temporary file (what a crash then leaves behind there).
  /// Throws TrajectoryError if anything written so far failed to reach it.
  void flush();
  /// Completes the file: flushed, synced and renamed over path(). Throws TrajectoryError.
  void close();
  std::size_t count() const { return count_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  std::unique_ptr<io::AtomicFile> out_;
  std::size_t count_ = 0;
};

/// Writes a whole trajectory.
void writeTum(const std::filesystem::path& path, const std::vector<TumPose>& poses);
/// Reads a whole trajectory (in file order).
std::vector<TumPose> readTum(const std::filesystem::path& path);

}  // namespace tessera::mapping
