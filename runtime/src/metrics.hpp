// Handler-time histogram of the runtime's per-actor metrics (the rest of the metrics are
// counters in ActorSlot; the report is assembled in metrics.cpp). Internal to tessera_runtime.
#pragma once

#include <tessera/runtime/clock.hpp>

#include <array>
#include <cstdint>

namespace tessera::detail {

/// Log-linear histogram of durations (ns): 8 sub-buckets per power of two, ~6% resolution.
/// Not thread-safe: each actor's histogram is written under its strand.
class DurationHistogram {
 public:
  void add(Nanos ns);
  double percentileMicros(double q) const;
  std::uint64_t count() const { return count_; }
  double totalSeconds() const { return static_cast<double>(total_ns_) * 1e-9; }

 private:
  static constexpr int kBuckets = 16 + 60 * 8;
  std::array<std::uint64_t, kBuckets> counts_{};
  std::uint64_t count_ = 0;
  Nanos total_ns_ = 0;
};

}  // namespace tessera::detail
