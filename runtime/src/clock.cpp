#include <tessera/runtime/clock.hpp>
#include <tessera/runtime/mailbox.hpp>

#include <time.h>

#include <stdexcept>
#include <string>

namespace tessera {

namespace {
Nanos readClock(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}
}  // namespace

Clock::Clock(ClockKind kind, Nanos sim_start, double rate)
    : kind_(kind), sim_now_(sim_start), rate_(rate > 0 ? rate : 1.0) {
  if (kind_ == ClockKind::kPaced) origin_ = readClock(CLOCK_MONOTONIC);
}

Nanos Clock::now() const {
  if (kind_ == ClockKind::kWall) return readClock(CLOCK_REALTIME);
  if (kind_ == ClockKind::kPaced) {
    const double elapsed = static_cast<double>(readClock(CLOCK_MONOTONIC) - origin_) * rate_;
    return sim_now_.load(std::memory_order_relaxed) + static_cast<Nanos>(elapsed);
  }
  return sim_now_.load(std::memory_order_acquire);
}

void Clock::advanceTo(Nanos t) {
  if (kind_ != ClockKind::kSimulated) throw std::logic_error("advanceTo on a wall clock");
  Nanos cur = sim_now_.load(std::memory_order_relaxed);
  if (t > cur) sim_now_.store(t, std::memory_order_release);
}

Nanos steadyNow() {
  return readClock(CLOCK_MONOTONIC);
}

std::string MailboxPolicy::describe() const {
  return (kind == Kind::kReliable ? "reliable(" : "keep_latest(") + std::to_string(capacity) + ")";
}

}  // namespace tessera
