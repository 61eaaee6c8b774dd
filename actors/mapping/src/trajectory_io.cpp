#include <tessera/mapping/trajectory_io.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>

namespace tessera::mapping {
namespace fs = std::filesystem;

namespace {

constexpr std::int64_t kNsPerSecond = 1'000'000'000;

std::string shortest(double v) {
  std::array<char, 64> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), res.ptr);
}

/// Seconds text → nanoseconds. Plain decimals ("-12.000000001") are converted exactly;
/// anything else (exponents) goes through double. Returns false when it is not a number.
bool parseStamp(std::string_view t, std::int64_t& ns) {
  std::size_t i = 0;
  const bool negative = !t.empty() && t[0] == '-';
  if (!t.empty() && (t[0] == '-' || t[0] == '+')) i = 1;
  std::int64_t secs = 0, frac = 0;
  int frac_digits = 0;
  bool digits = false, exact = true;
  for (; i < t.size() && t[i] >= '0' && t[i] <= '9'; ++i, digits = true) {
    if (secs > std::numeric_limits<std::int64_t>::max() / kNsPerSecond / 10) exact = false;
    secs = secs * 10 + (t[i] - '0');
  }
  if (i < t.size() && t[i] == '.') {
    for (++i; i < t.size() && t[i] >= '0' && t[i] <= '9'; ++i, digits = true) {
      if (frac_digits < 9) {
        frac = frac * 10 + (t[i] - '0');
        ++frac_digits;
      }  // digits past ns resolution are dropped (truncation toward zero)
    }
  }
  if (exact && digits && i == t.size()) {
    for (; frac_digits < 9; ++frac_digits) frac *= 10;
    ns = secs * kNsPerSecond + frac;
    if (negative) ns = -ns;
    return true;
  }
  double s = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), s);
  if (ec != std::errc() || ptr != t.data() + t.size() || !std::isfinite(s) || std::abs(s) > 9.2e9)
    return false;
  ns = std::llround(s * 1e9);
  return true;
}

}  // namespace

TumPose TumPose::fromPlanar(std::int64_t stamp_ns, const Pose2& pose) {
  TumPose p;
  p.stamp_ns = stamp_ns;
  p.position = {pose.x, pose.y, 0.0};
  p.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(pose.theta, Eigen::Vector3d::UnitZ()));
  return p;
}

Pose2 TumPose::planar() const {
  const Eigen::Quaterniond& q = orientation;
  // Yaw of the ZYX Euler decomposition: the heading of the body x axis projected on the plane.
  const double yaw = std::atan2(2.0 * (q.w() * q.z() + q.x() * q.y()),
                                1.0 - 2.0 * (q.y() * q.y() + q.z() * q.z()));
  return {position.x(), position.y(), yaw};
}

std::string formatTumLine(const TumPose& p) {
  const std::int64_t ns = p.stamp_ns;
  const std::uint64_t mag =
      ns < 0 ? 0 - static_cast<std::uint64_t>(ns) : static_cast<std::uint64_t>(ns);
  std::array<char, 16> frac{};
  std::snprintf(frac.data(), frac.size(), "%09llu",
                static_cast<unsigned long long>(mag % 1'000'000'000ULL));
  std::string line = ns < 0 ? "-" : "";
  line += std::to_string(mag / 1'000'000'000ULL);
  line += '.';
  line += frac.data();
  for (double v : {p.position.x(), p.position.y(), p.position.z(), p.orientation.x(),
                   p.orientation.y(), p.orientation.z(), p.orientation.w()}) {
    line += ' ';
    line += shortest(v);
  }
  return line;
}

TumPose parseTumLine(std::string_view line, const std::string& where) {
  std::array<std::string_view, 8> fields;
  std::size_t n = 0, i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    if (i >= line.size()) break;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (n == fields.size())
      throw TrajectoryError(where + ": expected 8 fields 't x y z qx qy qz qw', found more");
    fields[n++] = line.substr(start, i - start);
  }
  if (n != fields.size())
    throw TrajectoryError(where + ": expected 8 fields 't x y z qx qy qz qw', found " +
                          std::to_string(n));
  TumPose p;
  if (!parseStamp(fields[0], p.stamp_ns))
    throw TrajectoryError(where + ": expected a time stamp in seconds, found '" +
                          std::string(fields[0]) + "'");
  static constexpr std::array<const char*, 7> kNames{"x", "y", "z", "qx", "qy", "qz", "qw"};
  std::array<double, 7> v{};
  for (std::size_t k = 0; k < v.size(); ++k) {
    const std::string_view f = fields[k + 1];
    const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v[k]);
    if (ec != std::errc() || ptr != f.data() + f.size() || !std::isfinite(v[k]))
      throw TrajectoryError(where + ": expected a finite number for " + kNames[k] + ", found '" +
                            std::string(f) + "'");
  }
  p.position = {v[0], v[1], v[2]};
  p.orientation = Eigen::Quaterniond(v[6], v[3], v[4], v[5]);
  const double norm = p.orientation.norm();
  // Files carry ~6-9 digits; anything far from unit length is a broken line, not rounding.
  if (std::abs(norm - 1.0) > 1e-3)
    throw TrajectoryError(where + ": quaternion (qx qy qz qw) has norm " + shortest(norm) +
                          ", expected 1");
  p.orientation.normalize();
  return p;
}

namespace {
template <typename F>
void asTrajectoryError(F&& f) {
  try {
    f();
  } catch (const io::FileWriteError& e) {
    throw TrajectoryError(e.what());
  }
}
}  // namespace

TumWriter::TumWriter(const fs::path& path) : path_(path) {
  if (path.has_parent_path()) {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
  }
  asTrajectoryError([&] { out_ = std::make_unique<io::AtomicFile>(path); });
  out_->stream() << "# timestamp tx ty tz qx qy qz qw\n";
}

void TumWriter::write(const TumPose& pose) {
  if (!out_) throw TrajectoryError(path_.string() + ": write after close");
  out_->stream() << formatTumLine(pose) << '\n';
  ++count_;
}

void TumWriter::flush() {
  if (!out_) return;
  asTrajectoryError([&] { out_->flush(); });
}

void TumWriter::close() {
  if (!out_) return;
  const std::unique_ptr<io::AtomicFile> file = std::move(out_);
  asTrajectoryError([&] { file->commit(); });
}

void writeTum(const fs::path& path, const std::vector<TumPose>& poses) {
  TumWriter w(path);
  for (const auto& p : poses) w.write(p);
  w.close();
}

std::vector<TumPose> readTum(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw TrajectoryError(path.string() + ": cannot open for reading");
  std::vector<TumPose> poses;
  std::string line;
  for (std::size_t number = 1; std::getline(in, line); ++number) {
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    poses.push_back(parseTumLine(line, path.string() + ":" + std::to_string(number)));
  }
  if (in.bad()) throw TrajectoryError(path.string() + ": read error");
  return poses;
}

}  // namespace tessera::mapping
