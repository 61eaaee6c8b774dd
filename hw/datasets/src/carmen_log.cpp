#include <tessera/datasets/carmen_log.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

namespace tessera::datasets {

using io::DatasetError;
using io::Fields;
using io::TextReader;
namespace {

constexpr float kNoReturn = std::numeric_limits<float>::infinity();

// Cursor over the fields of one line: reads them in order with labels for error messages.
class LineParser {
 public:
  LineParser(const Fields& fields, std::string message, const CarmenOptions& options)
      : f_(fields), message_(std::move(message)), options_(options) {}

  double real(const char* label) { return f_.real(next(label), label); }
  double nonNegative(const char* label) {
    const std::size_t i = next(label);
    const double v = f_.real(i, label);
    if (v < 0) fail(i, label, "expected a value >= 0, got " + std::string(f_[i]));
    return v;
  }
  std::int64_t integer(const char* label) { return f_.integer(next(label), label); }
  std::string token(const char* label) { return std::string(f_[next(label)]); }
  CarmenPose pose(const char* x, const char* y, const char* theta) {
    CarmenPose p;
    p.x = real(x);
    p.y = real(y);
    p.theta = real(theta);
    return p;
  }

  // A count of values that must fit in the line, `trailing` fields still following them.
  std::size_t count(const char* label, std::size_t trailing) {
    const std::size_t i = next(label);
    const std::int64_t n = f_.integer(i, label);
    if (n < 0) fail(i, label, "expected a count >= 0, got " + std::to_string(n));
    const std::size_t left = f_.size() - pos_;  // fields after the count
    if (static_cast<std::uint64_t>(n) > options_.max_readings)
      fail(i, label,
           std::to_string(n) + " exceeds the limit of " + std::to_string(options_.max_readings));
    if (static_cast<std::uint64_t>(n) + trailing > left)
      fail(i, label,
           std::to_string(n) + " values announced but the line has only " + std::to_string(left) +
               " fields after the count (" + std::to_string(trailing) + " of them trailing)");
    return static_cast<std::size_t>(n);
  }

  // n ranges: non-negative finite numbers; those >= max_range (when > 0) become +inf.
  std::vector<float> ranges(std::size_t n, double max_range) {
    std::vector<float> out(n);
    const double limit = max_range > 0
                             ? std::min<double>(max_range, std::numeric_limits<float>::max())
                             : std::numeric_limits<float>::max();
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = next("range");
      const double r = f_.real(i, "range");
      if (r < 0) fail(i, "range", "expected a range >= 0, got " + std::string(f_[i]));
      out[k] = r >= limit ? kNoReturn : static_cast<float>(r);
    }
    return out;
  }

  std::vector<float> values(std::size_t n, const char* label) {
    std::vector<float> out(n);
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = next(label);
      const double v = f_.real(i, label);
      if (std::abs(v) > std::numeric_limits<float>::max())
        fail(i, label, "out of float range, got " + std::string(f_[i]));
      out[k] = static_cast<float>(v);
    }
    return out;
  }

  // The line must end here.
  void end() {
    if (pos_ != f_.size())
      f_.fail(message_ + ": " + std::to_string(f_.size() - pos_) + " extra fields after field " +
              std::to_string(pos_));
  }

  std::size_t position() const { return pos_; }

 private:
  std::size_t next(const char* label) {
    if (pos_ >= f_.size())
      f_.fail(message_ + " field " + std::to_string(pos_ + 1) + " (" + label +
              "): missing, the line ends after " + std::to_string(f_.size()) + " fields");
    return pos_++;
  }
  [[noreturn]] void fail(std::size_t i, const char* label, const std::string& what) const {
    f_.fail(message_ + " field " + std::to_string(i + 1) + " (" + label + "): " + what);
  }

  const Fields& f_;
  std::string message_;
  const CarmenOptions& options_;
  std::size_t pos_ = 1;  // field 0 is the message name
};

// Shared trailer of every message: ipc_timestamp hostname logger_timestamp.
void readTimes(LineParser& p, double& timestamp, double& logger_timestamp) {
  timestamp = p.real("ipc_timestamp");
  p.token("hostname");
  logger_timestamp = p.real("logger_timestamp");
}

CarmenLaser parseOldLaser(const Fields& f, const std::string& message,
                          const CarmenOptions& options) {
  LineParser p(f, message, options);
  CarmenLaser scan;
  scan.message = message;
  // n ranges, then x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp.
  const std::size_t n = p.count("num_readings", 9);
  scan.max_range = options.flaser_max_range > 0 ? static_cast<float>(options.flaser_max_range)
                                                : std::numeric_limits<float>::max();
  scan.ranges = p.ranges(n, options.flaser_max_range);
  scan.has_pose = true;
  scan.laser_pose = p.pose("x", "y", "theta");
  scan.robot_pose = p.pose("odom_x", "odom_y", "odom_theta");
  readTimes(p, scan.timestamp, scan.logger_timestamp);
  p.end();
  const double span = std::numbers::pi;
  scan.angle_min = static_cast<float>(-span / 2);
  if (n >= 2)
    scan.angle_increment = static_cast<float>(n % 2 == 1 ? span / double(n - 1) : span / double(n));
  return scan;
}

// ROBOTLASER1 (with_poses) and RAWLASERn (without): they share the laser config header.
CarmenLaser parseNewLaser(const Fields& f, const std::string& message, bool with_poses,
                          const CarmenOptions& options) {
  LineParser p(f, message, options);
  CarmenLaser scan;
  scan.message = message;
  p.integer("laser_type");
  scan.angle_min = static_cast<float>(p.real("start_angle"));
  p.real("fov");
  scan.angle_increment = static_cast<float>(p.real("angular_res"));
  const double max_range = p.nonNegative("max_range");
  p.real("accuracy");
  p.integer("remission_mode");
  // After the ranges: num_remissions, the remissions, then 6 poses + 5 robot fields + 3 times.
  const std::size_t trailer = with_poses ? 14 : 3;
  const std::size_t n = p.count("num_readings", 1 + trailer);
  const double limit = options.max_range_override > 0 ? options.max_range_override : max_range;
  scan.max_range =
      limit > 0 ? static_cast<float>(std::min<double>(limit, std::numeric_limits<float>::max()))
                : std::numeric_limits<float>::max();
  scan.ranges = p.ranges(n, limit);
  const std::size_t m = p.count("num_remissions", trailer);
  scan.remissions = p.values(m, "remission");
  if (with_poses) {
    scan.has_pose = true;
    scan.laser_pose = p.pose("laser_pose_x", "laser_pose_y", "laser_pose_theta");
    scan.robot_pose = p.pose("robot_pose_x", "robot_pose_y", "robot_pose_theta");
    p.real("tv");
    p.real("rv");
    p.real("forward_safety_dist");
    p.real("side_safety_dist");
    p.real("turn_axis");
  }
  readTimes(p, scan.timestamp, scan.logger_timestamp);
  p.end();
  return scan;
}

CarmenOdometry parseOdom(const Fields& f, const CarmenOptions& options) {
  LineParser p(f, "ODOM", options);
  CarmenOdometry odom;
  odom.pose = p.pose("x", "y", "theta");
  odom.tv = p.real("tv");
  odom.rv = p.real("rv");
  odom.accel = p.real("accel");
  readTimes(p, odom.timestamp, odom.logger_timestamp);
  p.end();
  return odom;
}

bool isMessageName(std::string_view s) {
  if (s.empty() || s.size() > 64) return false;
  if (!((s[0] >= 'A' && s[0] <= 'Z') || (s[0] >= 'a' && s[0] <= 'z'))) return false;
  for (char c : s)
    if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
          c == '-'))
      return false;
  return true;
}

}  // namespace

CarmenReader::CarmenReader(const std::filesystem::path& path, CarmenOptions options)
    : CarmenReader(TextReader(path), options) {}

CarmenReader::CarmenReader(TextReader reader, CarmenOptions options)
    : reader_(std::move(reader)), options_(options) {}

bool CarmenReader::next(CarmenRecord& record) {
  while (reader_.next(line_)) {
    ++report_.lines;
    const Fields f(reader_, line_);
    if (f.empty() || f[0].front() == '#') continue;
    const std::string_view name = f[0];
    try {
      if (name == "FLASER" || name == "RLASER") {
        record = parseOldLaser(f, std::string(name), options_);
      } else if (name == "ROBOTLASER1") {
        record = parseNewLaser(f, std::string(name), true, options_);
      } else if (name == "RAWLASER1" || name == "RAWLASER2" || name == "RAWLASER3" ||
                 name == "RAWLASER4") {
        record = parseNewLaser(f, std::string(name), false, options_);
      } else if (name == "ODOM") {
        const CarmenOdometry odom = parseOdom(f, options_);
        if (options_.skip_zero_time_odom && std::abs(odom.timestamp) < 1e-6 &&
            latest_time_ >= 1.0) {
          report_.skip(reader_, "ODOM stamped 0 (GFS pose echo)");
          continue;
        }
        record = odom;
      } else if (isMessageName(name)) {
        report_.skip(reader_, std::string(name));
        continue;
      } else {
        reader_.fail("not a CARMEN message: line starts with '" + std::string(name.substr(0, 40)) +
                     "'");
      }
    } catch (const DatasetError&) {
      if (!options_.skip_malformed) throw;
      report_.skip(reader_, isMessageName(name) ? "malformed " + std::string(name) : "garbage");
      continue;
    }
    latest_time_ =
        std::max(latest_time_, std::visit([](const auto& r) { return r.timestamp; }, record));
    ++report_.records;
    return true;
  }
  return false;
}

CarmenLog readCarmenLog(const std::filesystem::path& path, const CarmenOptions& options) {
  CarmenReader reader(path, options);
  CarmenLog log;
  CarmenRecord record;
  while (reader.next(record)) log.records.push_back(std::move(record));
  log.report = reader.report();
  return log;
}

CarmenLog parseCarmenLog(const std::string& name, std::string text, const CarmenOptions& options) {
  CarmenReader reader(TextReader::fromString(name, std::move(text)), options);
  CarmenLog log;
  CarmenRecord record;
  while (reader.next(record)) log.records.push_back(std::move(record));
  log.report = reader.report();
  return log;
}

std::vector<CarmenOdometry> carmenOdometry(const CarmenLog& log) {
  std::vector<CarmenOdometry> out;
  for (const auto& r : log.records)
    if (const auto* o = std::get_if<CarmenOdometry>(&r)) out.push_back(*o);
  if (!out.empty()) return out;
  for (const auto& r : log.records) {
    const auto* l = std::get_if<CarmenLaser>(&r);
    if (!l || !l->has_pose) continue;
    CarmenOdometry o;
    o.timestamp = l->timestamp;
    o.logger_timestamp = l->logger_timestamp;
    o.pose = l->robot_pose;
    out.push_back(o);
  }
  return out;
}

}  // namespace tessera::datasets
