// Helpers shared by the benchmarks: percentiles and medians of samples, and the yielding wait a
// messaging benchmark's measuring thread uses for a hand-off to complete.
#pragma once

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace tessera::app {

/// The q-quantile (0..1) of `v` by nearest rank; 0 for no samples.
inline double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

/// The median of `v` (the mean of the two middle values for an even count); 0 for no samples.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Waits until `value` reaches `target`, yielding the core: on a 2-core machine a pure spin
/// would compete with the threads being waited for.
template <typename Int>
void spinUntil(const std::atomic<Int>& value, Int target) {
  while (value.load(std::memory_order_acquire) < target) std::this_thread::yield();
}

}  // namespace tessera::app
