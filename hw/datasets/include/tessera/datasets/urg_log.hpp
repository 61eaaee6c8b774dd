// Reader for the MinesParisTech / BreezySLAM log format (CoreSLAM's exp1.dat / exp2.dat): one
// text line per Hokuyo URG-04LX scan, with the robot's cumulative wheel-encoder counts at that
// moment, plain or gzip. Plus the differential-drive model that turns those counts into poses.
//
// Line layout (whitespace separated; BreezySLAM examples/mines.py reads the same fields):
//   field 0        timestamp, integer microseconds
//   field 1        robot telemetry (ignored)
//   fields 2, 3    left, right wheel encoder counts (cumulative integers)
//   fields 4..23   robot telemetry (ignored, not checked)
//   fields 24..705 682 ranges, integer millimetres, in scan order (counter-clockwise)
//   field 706      ignored (optional)
//
// Ranges: a reading of 0 means no return (+inf); 1 .. min_valid_mm-1 are Hokuyo error codes
// (NaN, invalid); the rest are converted to metres. The scan covers fov_deg = 240 deg centred
// ahead, first and last beams on its edges (BreezySLAM's convention); beams at both ends are
// always 0 in these logs because the robot's body hides them.
//
// Errors: wrong field counts, non-integers, negative or absurd readings (> max_range_mm) throw
// io::DatasetError naming file:line and field, unless skip_malformed (then counted skips).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/io/text_reader.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tessera::datasets {

struct UrgScan {
  std::int64_t timestamp_us = 0;
  double timestamp = 0;         // [s] = timestamp_us * 1e-6
  std::int64_t left_ticks = 0;  // cumulative encoder counts
  std::int64_t right_ticks = 0;
  float angle_min = 0;        // [rad], first beam (rightmost), laser frame
  float angle_increment = 0;  // [rad]
  std::vector<float> ranges;  // [m]; +inf = no return, NaN = error code
};

struct UrgOptions {
  std::size_t beams = 682;             // range fields per line
  std::size_t first_range_field = 24;  // index of the first range field
  double fov_deg = 240;                // field of view spanned by the beams [deg]
  std::int64_t min_valid_mm = 20;      // readings 1 .. this-1 are error codes -> NaN
  bool zero_is_no_return = true;       // 0 -> +inf (else NaN)
  std::int64_t max_range_mm = 60000;   // larger readings are malformed
  bool skip_malformed = false;         // count bad lines as skips instead of throwing
};

class UrgReader {
 public:
  explicit UrgReader(const std::filesystem::path& path, UrgOptions options = {});
  explicit UrgReader(io::TextReader reader, UrgOptions options = {});

  // The next scan; false at the end. Throws io::DatasetError.
  bool next(UrgScan& scan);
  const io::ParseReport& report() const { return report_; }
  double progress() const { return reader_.progress(); }
  const std::filesystem::path& path() const { return reader_.path(); }

 private:
  io::TextReader reader_;
  UrgOptions options_;
  io::ParseReport report_;
  std::string line_;
};

struct UrgLog {
  std::vector<UrgScan> scans;
  io::ParseReport report;
};

UrgLog readUrgLog(const std::filesystem::path& path, const UrgOptions& options = {});
UrgLog parseUrgLog(const std::string& name, std::string text, const UrgOptions& options = {});

// Differential drive with wheel encoders. Defaults: the MinesParisTech robot as BreezySLAM models
// it (wheel radius 77 mm, half axle 165 mm). BreezySLAM converts counts to wheel degrees as
// counts * 180 / 2000 but then sums the two wheels without halving; that is the standard model
// with 2000 counts per wheel revolution, which the laser confirms on exp2 (an in-place turn of
// 8 deg by scan matching reads 8 deg; a 1.2 m advance towards a wall shortens the range 1.3 m).
struct DifferentialDriveModel {
  double wheel_radius = 0.077;  // [m]
  double half_axle = 0.165;     // [m] wheel to axle centre
  double ticks_per_revolution = 2000;
};

struct DriveIncrement {
  double distance = 0;  // [m] travelled by the axle centre
  double rotation = 0;  // [rad] counter-clockwise
};

// Motion between two encoder readings (count differences; right faster = turn left).
DriveIncrement wheelIncrement(double d_left_ticks, double d_right_ticks,
                              const DifferentialDriveModel& model);

// Applies an increment with the midpoint heading (exact for straight lines and turns in place).
Pose2 advancePose(const Pose2& pose, const DriveIncrement& inc);

// Dead-reckoned pose of the axle centre at each scan, the first at `start`.
std::vector<Pose2> urgOdometry(const std::vector<UrgScan>& scans,
                               const DifferentialDriveModel& model = {}, const Pose2& start = {});

}  // namespace tessera::datasets
