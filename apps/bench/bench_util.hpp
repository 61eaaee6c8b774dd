// Helpers shared by the messaging benchmarks (`bench runtime`, `bench ipc`): percentiles of
// latency samples and the yielding wait a measuring thread uses for a hand-off to complete.
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

/// Waits until `value` reaches `target`, yielding the core: on a 2-core machine a pure spin
/// would compete with the threads being waited for.
template <typename Int>
void spinUntil(const std::atomic<Int>& value, Int target) {
  while (value.load(std::memory_order_acquire) < target) std::this_thread::yield();
}

}  // namespace tessera::app
