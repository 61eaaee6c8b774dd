#include <tessera/datasets/urg_log.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

namespace tessera::datasets {

using io::DatasetError;
using io::Fields;
using io::TextReader;
namespace {

UrgScan parseLine(const Fields& f, const UrgOptions& o) {
  const std::size_t end = o.first_range_field + o.beams;
  if (f.size() != end && f.size() != end + 1)
    f.fail("expected " + std::to_string(end) + " or " + std::to_string(end + 1) +
           " fields (timestamp, telemetry, encoders, " + std::to_string(o.beams) +
           " ranges), got " + std::to_string(f.size()));
  UrgScan s;
  s.timestamp_us = f.integerIn(0, "timestamp [us]", 0, std::numeric_limits<std::int64_t>::max());
  s.timestamp = static_cast<double>(s.timestamp_us) * 1e-6;
  s.left_ticks = f.integer(2, "left encoder");
  s.right_ticks = f.integer(3, "right encoder");
  const double fov = o.fov_deg * std::numbers::pi / 180.0;
  s.angle_min = static_cast<float>(-fov / 2);
  s.angle_increment = o.beams > 1 ? static_cast<float>(fov / double(o.beams - 1)) : 0.0f;
  s.ranges.resize(o.beams);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t k = 0; k < o.beams; ++k) {
    const std::int64_t mm = f.integerIn(o.first_range_field + k, "range [mm]", 0, o.max_range_mm);
    if (mm == 0)
      s.ranges[k] = o.zero_is_no_return ? kInf : kNaN;
    else if (mm < o.min_valid_mm)
      s.ranges[k] = kNaN;
    else
      s.ranges[k] = static_cast<float>(static_cast<double>(mm) * 1e-3);
  }
  return s;
}

}  // namespace

UrgReader::UrgReader(const std::filesystem::path& path, UrgOptions options)
    : UrgReader(TextReader(path), options) {}

UrgReader::UrgReader(TextReader reader, UrgOptions options)
    : reader_(std::move(reader)), options_(options) {
  // Bound the per-line allocation like the CARMEN reader bounds its counts.
  if (options_.beams == 0 || options_.beams > 100000)
    throw DatasetError(reader_.path(), 0,
                       "beams must be in 1..100000, got " + std::to_string(options_.beams));
}

bool UrgReader::next(UrgScan& scan) {
  while (reader_.next(line_)) {
    ++report_.lines;
    const Fields f(reader_, line_);
    if (f.empty() || f[0].front() == '#') continue;
    try {
      scan = parseLine(f, options_);
    } catch (const DatasetError&) {
      if (!options_.skip_malformed) throw;
      report_.skip(reader_, "malformed scan line");
      continue;
    }
    ++report_.records;
    return true;
  }
  return false;
}

UrgLog readUrgLog(const std::filesystem::path& path, const UrgOptions& options) {
  UrgReader reader(path, options);
  UrgLog log;
  UrgScan scan;
  while (reader.next(scan)) log.scans.push_back(std::move(scan));
  log.report = reader.report();
  return log;
}

UrgLog parseUrgLog(const std::string& name, std::string text, const UrgOptions& options) {
  UrgReader reader(TextReader::fromString(name, std::move(text)), options);
  UrgLog log;
  UrgScan scan;
  while (reader.next(scan)) log.scans.push_back(std::move(scan));
  log.report = reader.report();
  return log;
}

DriveIncrement wheelIncrement(double d_left, double d_right, const DifferentialDriveModel& m) {
  const double per_tick = 2.0 * std::numbers::pi * m.wheel_radius / m.ticks_per_revolution;
  const double left = d_left * per_tick;
  const double right = d_right * per_tick;
  return {0.5 * (left + right), (right - left) / (2.0 * m.half_axle)};
}

Pose2 advancePose(const Pose2& p, const DriveIncrement& inc) {
  const double mid = p.theta + 0.5 * inc.rotation;
  return {p.x + inc.distance * std::cos(mid), p.y + inc.distance * std::sin(mid),
          p.theta + inc.rotation};
}

std::vector<Pose2> urgOdometry(const std::vector<UrgScan>& scans,
                               const DifferentialDriveModel& model, const Pose2& start) {
  std::vector<Pose2> poses;
  poses.reserve(scans.size());
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (i == 0) {
      poses.push_back(start);
      continue;
    }
    // In double: differences of int64 counts overflow on absurd (corrupt) logs.
    const double dl =
        static_cast<double>(scans[i].left_ticks) - static_cast<double>(scans[i - 1].left_ticks);
    const double dr =
        static_cast<double>(scans[i].right_ticks) - static_cast<double>(scans[i - 1].right_ticks);
    poses.push_back(advancePose(poses.back(), wheelIncrement(dl, dr, model)));
  }
  return poses;
}

}  // namespace tessera::datasets
