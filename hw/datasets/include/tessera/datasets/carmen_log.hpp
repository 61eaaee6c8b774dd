// Reader for CARMEN laser logs (the text format of the Radish / Freiburg 2D-laser datasets, e.g.
// intel.clf), plain or gzip.
//
// Records produced (one per line):
//   FLASER, RLASER                  -> CarmenLaser (front / rear laser with two poses)
//   ROBOTLASER1                     -> CarmenLaser (own angles and max range, two poses)
//   RAWLASER1 .. RAWLASER4          -> CarmenLaser (own angles and max range, no pose)
//   ODOM                            -> CarmenOdometry
// PARAM, NEFF, SYNC, TRUEPOS and any other message name are skipped and counted in the
// io::ParseReport under the message name; '#' comments and blank lines are ignored.
//
// Units and frames: metres, radians, seconds. Beam i points at angle_min + i * angle_increment in
// the laser frame (x forward, counter-clockwise positive). Poses are (x, y, theta) in the log's
// world frame. FLASER/RLASER carry no angles: the first beam is at -90 deg and the n beams span
// 180 deg; an even n divides 180 deg into n steps (180 -> 1 deg, -90..+89), an odd n includes
// both ends (181 -> 1 deg, 361 -> 0.5 deg, -90..+90), as CARMEN itself does.
// Time: `timestamp` is the ipc_timestamp field (absolute on most logs, relative on some GFS
// logs); the logger_timestamp is kept as well but may be negative (intel.clf).
//
// No return: readings at or above the max range become +infinity (LaserScan convention:
// +inf = no return, NaN = invalid). FLASER/RLASER lines have no max range field, so
// CarmenOptions::flaser_max_range applies; ROBOTLASER1/RAWLASER lines use their own field.
//
// Errors: a malformed known line (wrong field count, non-numbers, NaN/inf, negative range,
// counts larger than the line or than max_readings — checked before allocating) throws
// io::DatasetError "FILE:LINE: MESSAGE field N (label): ..." unless skip_malformed is set, in which
// case it is skipped and counted under "malformed MESSAGE". A truncated gzip file always throws.
#pragma once

#include <tessera/io/text_reader.hpp>

#include <cstddef>
#include <filesystem>
#include <string>
#include <variant>
#include <vector>

namespace tessera::datasets {

struct CarmenPose {
  double x = 0;      // m
  double y = 0;      // m
  double theta = 0;  // rad
};

// One laser scan line (FLASER, RLASER, ROBOTLASER1, RAWLASER1..4).
struct CarmenLaser {
  std::string message;            // "FLASER", "ROBOTLASER1", ...
  double timestamp = 0;           // ipc_timestamp [s]
  double logger_timestamp = 0;    // [s]
  float angle_min = 0;            // [rad], first beam, laser frame
  float angle_increment = 0;      // [rad]
  float max_range = 0;            // [m]; readings >= this were turned into +inf
  std::vector<float> ranges;      // [m]; +inf = no return
  std::vector<float> remissions;  // ROBOTLASER1/RAWLASER only (often empty)
  bool has_pose = false;          // false for RAWLASER
  // FLASER/RLASER: the `x y theta` fields; ROBOTLASER1: laser_pose. The laser's pose in the world.
  CarmenPose laser_pose;
  // FLASER/RLASER: the `odom_x odom_y odom_theta` fields; ROBOTLASER1: robot_pose. Odometry of
  // the robot. NB: what these poses mean depends on the log (raw odometry in intel.clf; the
  // GMapping-corrected pose, in both fields, in the *.gfs / *-corrected logs).
  CarmenPose robot_pose;
};

// One ODOM line: raw wheel odometry.
struct CarmenOdometry {
  double timestamp = 0;         // ipc_timestamp [s]
  double logger_timestamp = 0;  // [s]
  CarmenPose pose;
  double tv = 0;     // translational velocity [m/s]
  double rv = 0;     // rotational velocity [rad/s]
  double accel = 0;  // [m/s^2]
};

using CarmenRecord = std::variant<CarmenLaser, CarmenOdometry>;

struct CarmenOptions {
  // No-return threshold [m] for FLASER/RLASER (which have no max range field): readings >= this
  // become +inf. SICK LMS logs write 81.83 / 81.91 m for "no return" and no real reading there
  // reaches 80 m, hence 80. Set <= 0 to keep every reading as it is.
  double flaser_max_range = 80.0;
  // If > 0, replaces the max_range field of ROBOTLASER1/RAWLASER lines as the no-return
  // threshold (for logs whose max_range field is wrong).
  double max_range_override = 0.0;
  // Largest accepted reading / remission count per line; larger counts are errors.
  std::size_t max_readings = 100000;
  // Skip (and count) malformed lines of known messages instead of throwing io::DatasetError.
  bool skip_malformed = false;
  // GMapping's *.gfs logs follow each processed FLASER with an ODOM line holding the corrected
  // pose, zero velocities and a time of 0 (or a garbage denormal such as 1e-42): not odometry.
  // When set, ODOM lines stamped below 1 us after the log has reached 1 s are skipped and
  // counted as "ODOM stamped 0 (GFS pose echo)" (863 of the 14541 ODOM lines of intel-corrected).
  bool skip_zero_time_odom = true;
};

// Streaming reader: one record per next(), constant memory.
class CarmenReader {
 public:
  explicit CarmenReader(const std::filesystem::path& path, CarmenOptions options = {});
  explicit CarmenReader(io::TextReader reader, CarmenOptions options = {});

  // Reads up to the next record; false at the end of the file. Throws io::DatasetError.
  bool next(CarmenRecord& record);
  const io::ParseReport& report() const { return report_; }
  double progress() const { return reader_.progress(); }
  const std::filesystem::path& path() const { return reader_.path(); }

 private:
  io::TextReader reader_;
  CarmenOptions options_;
  io::ParseReport report_;
  std::string line_;
  double latest_time_ = 0;  // latest timestamp seen [s]
};

struct CarmenLog {
  std::vector<CarmenRecord> records;  // in file order
  io::ParseReport report;
};

// Reads a whole log. Throws io::DatasetError.
CarmenLog readCarmenLog(const std::filesystem::path& path, const CarmenOptions& options = {});
// Same for text in memory (tests, fuzzing); `name` is used in error messages.
CarmenLog parseCarmenLog(const std::string& name, std::string text,
                         const CarmenOptions& options = {});

// The odometry of a log as (timestamp, pose) records: its ODOM lines when it has any, else the
// robot_pose of its laser lines that carry a pose (FLASER/RLASER/ROBOTLASER1), in file order.
// For intel.clf this is the raw odometry at each scan.
std::vector<CarmenOdometry> carmenOdometry(const CarmenLog& log);

}  // namespace tessera::datasets
