#include <tessera/localization/gyro_buffer.hpp>

#include <algorithm>
#include <cmath>

namespace tessera::localization {

bool GyroBuffer::add(std::int64_t stamp_ns, double rate) {
  if (!std::isfinite(rate)) return false;
  if (!samples_.empty() && stamp_ns <= samples_.back().first) return false;
  samples_.emplace_back(stamp_ns, rate);
  return true;
}

bool GyroBuffer::covers(std::int64_t t0, std::int64_t t1) const {
  return !samples_.empty() && t0 <= t1 && samples_.front().first <= t0 &&
         samples_.back().first >= t1;
}

std::optional<std::int64_t> GyroBuffer::lastStamp() const {
  if (samples_.empty()) return std::nullopt;
  return samples_.back().first;
}

std::optional<double> GyroBuffer::integrate(std::int64_t t0, std::int64_t t1) {
  if (!covers(t0, t1)) return std::nullopt;
  double angle = 0;
  for (std::size_t i = 1; i < samples_.size(); ++i) {
    const std::int64_t a = samples_[i - 1].first, b = samples_[i].first;
    if (a >= t1) break;
    const std::int64_t lo = std::max(a, t0), hi = std::min(b, t1);
    if (hi > lo) angle += samples_[i].second * static_cast<double>(hi - lo) * 1e-9;
  }
  // Keep the last sample at or before t1 as the start of what follows.
  while (samples_.size() > 1 && samples_[1].first <= t1) samples_.pop_front();
  return angle;
}

}  // namespace tessera::localization
