#include <tessera/mapping/packed_range_scan.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::mapping {
namespace {

// Codes 0 and 65535 are reserved, so every return in [0, range_max) maps to 1..65001.
constexpr std::uint16_t kInvalid = 0;       // NaN or negative: GridMapper skips it
constexpr std::uint16_t kNoReturn = 65535;  // +inf or >= range_max: clears free space
constexpr double kSteps = 65000.0;

}  // namespace

PackedRangeScan::PackedRangeScan(std::int64_t stamp_ns, const tessera::grid::RangeScan& scan,
                                 const tessera::Pose2& mount)
    : stamp_ns_(stamp_ns),
      mount_(mount),
      angle_min_(static_cast<float>(scan.angle_min)),
      angle_increment_(static_cast<float>(scan.angle_increment)),
      range_min_(static_cast<float>(scan.range_min)),
      range_max_(static_cast<float>(scan.range_max)) {
  if (!(std::isfinite(scan.range_max) && scan.range_max > 0))
    throw std::invalid_argument("PackedRangeScan: range_max must be finite and > 0 (got " +
                                std::to_string(scan.range_max) + ")");
  const double unit = scan.range_max / kSteps;
  codes_.reserve(scan.ranges.size());
  for (const float r : scan.ranges) {
    if (std::isnan(r) || r < 0) {
      codes_.push_back(kInvalid);
    } else if (r >= scan.range_max) {  // +inf included
      codes_.push_back(kNoReturn);
    } else {
      const double code = std::round(r / unit) + 1.0;
      codes_.push_back(static_cast<std::uint16_t>(std::min(code, kSteps + 1.0)));
    }
  }
}

tessera::grid::RangeScan PackedRangeScan::unpack(std::vector<float>& buffer) const {
  const double unit = static_cast<double>(range_max_) / kSteps;
  buffer.resize(codes_.size());
  for (std::size_t i = 0; i < codes_.size(); ++i) {
    const std::uint16_t c = codes_[i];
    buffer[i] = c == kInvalid    ? std::numeric_limits<float>::quiet_NaN()
                : c == kNoReturn ? std::numeric_limits<float>::infinity()
                                 : static_cast<float>((c - 1) * unit);
  }
  return {buffer, angle_min_, angle_increment_, range_min_, range_max_};
}

}  // namespace tessera::mapping
