// The runtime clock. Time is int64 nanoseconds. On a robot it is wall time (CLOCK_REALTIME, so
// stamps match other machines); in simulation and replay it is simulated time that the executor
// advances from timer to timer once every actor is idle, which makes runs deterministic and as
// fast as the CPU allows. A paced clock is simulated time that runs at a fixed multiple of the
// wall clock and never waits for the actors, as a robot's sensors do not: what cannot keep up is
// evicted from keep_latest mailboxes (overload tests; `clock: paced` with sim_rate).
#pragma once

#include <atomic>
#include <cstdint>

namespace tessera {

using Nanos = std::int64_t;

constexpr Nanos kNanosPerSecond = 1'000'000'000;
constexpr Nanos secondsToNanos(double s) {
  return static_cast<Nanos>(s * 1e9);
}
constexpr double nanosToSeconds(Nanos ns) {
  return static_cast<double>(ns) * 1e-9;
}

enum class ClockKind { kSimulated, kWall, kPaced };

class Clock {
 public:
  /// `rate`: for kPaced, simulated seconds per wall second (> 0), counted from construction.
  explicit Clock(ClockKind kind, Nanos sim_start = 0, double rate = 1.0);
  ClockKind kind() const { return kind_; }
  Nanos now() const;
  /// Simulated clocks only: moves time forward (never backwards).
  void advanceTo(Nanos t);

 private:
  ClockKind kind_;
  std::atomic<Nanos> sim_now_;
  double rate_ = 1.0;
  Nanos origin_ = 0;  // kPaced: steady time at sim_now_
};

/// Monotonic wall time for measuring durations (never goes into messages).
Nanos steadyNow();

}  // namespace tessera
