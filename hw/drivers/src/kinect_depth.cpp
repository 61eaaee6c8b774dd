#include <tessera/drivers/kinect_depth.hpp>

#include <tessera/drivers/session_text.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::drivers {

namespace kinect_depth_detail {

void requirePositive(const char* name, double v) {
  if (!std::isfinite(v) || v <= 0)
    throw std::invalid_argument(std::string("depth model: ") + name +
                                " must be finite and > 0, not " + decimal(v));
}

}  // namespace kinect_depth_detail

void KinectDepthModel::validate() const {
  using kinect_depth_detail::requirePositive;
  requirePositive("baseline_m", baseline_m);
  requirePositive("focal_px", focal_px);
  requirePositive("disparity_offset", disparity_offset);
  requirePositive("min_depth_m", min_depth_m);
  requirePositive("max_depth_m", max_depth_m);
  if (max_depth_m <= min_depth_m)
    throw std::invalid_argument("depth model: max_depth_m (" + decimal(max_depth_m) +
                                ") must exceed min_depth_m (" + decimal(min_depth_m) + ")");
  if (disparity_offset > kNoReading)
    throw std::invalid_argument("depth model: disparity_offset " + decimal(disparity_offset) +
                                " is beyond the 11-bit range (at most 2047)");
}

std::optional<double> KinectDepthModel::metres(int d) const {
  if (d < 0 || d >= kNoReading) return std::nullopt;
  const double denominator = disparity_offset - d;
  if (denominator <= 0) return std::nullopt;  // "beyond infinity": a bad reading
  const double z = 8.0 * baseline_m * focal_px / denominator;
  if (z < min_depth_m || z > max_depth_m) return std::nullopt;
  return z;
}

int KinectDepthModel::disparity(double z) const {
  if (!std::isfinite(z) || z < min_depth_m || z > max_depth_m) return kNoReading;
  const long d = std::lround(disparity_offset - 8.0 * baseline_m * focal_px / z);
  // Rounding at the range's ends can step just outside it: keep the nearest value inside.
  for (const long c : {d, d + 1, d - 1})
    if (c >= 0 && c < kNoReading && metres(static_cast<int>(c))) return static_cast<int>(c);
  return kNoReading;
}

KinectDepthConverter::KinectDepthConverter(const KinectDepthModel& model, double units_per_metre)
    : table_(KinectDepthModel::kNoReading + 1, 0) {
  model.validate();
  if (!std::isfinite(units_per_metre) || units_per_metre <= 0)
    throw std::invalid_argument("depth scale must be finite and > 0, not " +
                                decimal(units_per_metre));
  if (model.max_depth_m * units_per_metre >= std::numeric_limits<std::uint16_t>::max())
    throw std::invalid_argument("depth model: max_depth_m " + decimal(model.max_depth_m) +
                                " m does not fit 16 bits at " + decimal(units_per_metre) +
                                " units per metre");
  for (int d = 0; d < KinectDepthModel::kNoReading; ++d)
    if (const auto z = model.metres(d))
      table_[static_cast<std::size_t>(d)] =
          static_cast<std::uint16_t>(std::lround(*z * units_per_metre));
}

std::size_t KinectDepthConverter::convert(std::span<const std::uint16_t> raw,
                                          std::span<std::uint16_t> out) const {
  if (raw.size() != out.size())
    throw std::invalid_argument("KinectDepthConverter: " + std::to_string(raw.size()) +
                                " raw pixels for " + std::to_string(out.size()) + " outputs");
  std::size_t corrupt = 0;
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const std::uint16_t d = raw[i];
    if (d > KinectDepthModel::kNoReading) {
      ++corrupt;
      out[i] = 0;
    } else {
      out[i] = table_[d];
    }
  }
  return corrupt;
}

RgbdPairer::RgbdPairer(std::int64_t max_gap_ns) : max_gap_ns_(max_gap_ns) {
  if (max_gap_ns <= 0) throw std::invalid_argument("RgbdPairer: max_gap must be > 0");
}

std::optional<RgbdPairer::Pair> RgbdPairer::addColor(KinectImage image) {
  return add(std::move(image), color_, depth_, true);
}

std::optional<RgbdPairer::Pair> RgbdPairer::addDepth(KinectImage image) {
  return add(std::move(image), depth_, color_, false);
}

std::optional<RgbdPairer::Pair> RgbdPairer::add(KinectImage image, std::optional<KinectImage>& mine,
                                                std::optional<KinectImage>& other, bool is_color) {
  if (other && std::llabs(image.stamp_ns - other->stamp_ns) <= max_gap_ns_) {
    if (mine) {
      ++dropped_;  // an older frame of this stream never found a partner
      mine.reset();
    }
    Pair p;
    if (is_color) {
      p.color = std::move(image);
      p.depth = std::move(*other);
    } else {
      p.depth = std::move(image);
      p.color = std::move(*other);
    }
    other.reset();
    ++paired_;
    return p;
  }
  if (other) {
    ++dropped_;  // too old to pair with anything that comes later
    other.reset();
  }
  if (mine) ++dropped_;
  mine = std::move(image);
  return std::nullopt;
}

void RgbdPairer::reset() {
  color_.reset();
  depth_.reset();
}

}  // namespace tessera::drivers
