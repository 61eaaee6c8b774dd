// GyroBuffer: the yaw-rate samples of an integrating gyro, integrated over any interval they
// cover (docs/algorithms.md#wheel-and-gyro-odometry).
//
// Each sample is the sensor's mean rate over the interval since its previous sample (how
// msg::ImuSample defines it), so the angle turned over (t0, t1] is the sum of rate × overlap of
// each sample's interval with (t0, t1]: exact for any t0, t1 on sample stamps, pro rata in
// between. The first sample only marks where coverage starts. A sample skipped by the caller
// (NaN) leaves its interval to the next one, which then stands for both. Times are integer
// nanoseconds (the runtime's stamps), rates rad/s, angles rad.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <utility>

namespace tessera::localization {

class GyroBuffer {
 public:
  /// Adds the sample ending at `stamp_ns`. Returns false (ignored) for a non-finite rate or a
  /// stamp not after the last sample's.
  bool add(std::int64_t stamp_ns, double rate);

  /// Whether samples cover all of (t0, t1]: coverage starts at or before t0 and the last sample
  /// is at or after t1.
  bool covers(std::int64_t t0, std::int64_t t1) const;

  /// The angle turned over (t0, t1], or nullopt when not covered. Then drops the samples
  /// before t1 but the last one (it marks where coverage resumes): intervals are asked for in
  /// increasing order.
  std::optional<double> integrate(std::int64_t t0, std::int64_t t1);

  std::size_t size() const { return samples_.size(); }
  /// Stamp of the newest sample, nullopt when empty.
  std::optional<std::int64_t> lastStamp() const;

 private:
  std::deque<std::pair<std::int64_t, double>> samples_;  // (stamp, mean rate since previous)
};

}  // namespace tessera::localization
