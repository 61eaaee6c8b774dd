// SensorClock: see sensor_clock.hpp.
#include <tessera/drivers/sensor_clock.hpp>

#include <stdexcept>
#include <string>

namespace tessera::drivers {

SensorClock::SensorClock(int bits, std::int64_t tick_ns, std::int64_t window_ns)
    : bits_(bits), tick_ns_(tick_ns), window_ns_(window_ns) {
  if (bits < 8 || bits > 32)
    throw std::invalid_argument("SensorClock: bits must be 8..32, got " + std::to_string(bits));
  if (tick_ns <= 0 || window_ns <= 0)
    throw std::invalid_argument("SensorClock: tick and window must be > 0");
}

SensorClock SensorClock::withTickRate(int bits, std::int64_t ticks_per_second,
                                      std::int64_t window_ns) {
  if (ticks_per_second <= 0) throw std::invalid_argument("SensorClock: the tick rate must be > 0");
  SensorClock c(bits, 1'000'000'000, window_ns);
  c.tick_den_ = ticks_per_second;
  return c;
}

std::int64_t SensorClock::stamp(std::uint32_t ticks, std::int64_t host_ns) {
  const std::uint64_t modulus = std::uint64_t{1} << bits_;
  ticks = static_cast<std::uint32_t>(ticks & (modulus - 1));
  std::int64_t reading = ticks;  // unwrapped
  if (last_ticks_) {
    const std::uint64_t step = (ticks + modulus - *last_ticks_) % modulus;
    const std::uint64_t back = (modulus - step) % modulus;
    if (back > 0 && back <= max_back_ticks_) {
      reading = unwrapped_ticks_ - static_cast<std::int64_t>(back);  // taken before the newest
    } else {
      if (ticks < *last_ticks_) ++wraps_;
      unwrapped_ticks_ += static_cast<std::int64_t>(step);
      last_ticks_ = ticks;
      reading = unwrapped_ticks_;
    }
  } else {
    unwrapped_ticks_ = ticks;
    last_ticks_ = ticks;
  }
  // Whole seconds' worth of ticks and the rest apart, so that the product cannot overflow.
  const std::int64_t sensor_ns =
      reading / tick_den_ * tick_ns_ + reading % tick_den_ * tick_ns_ / tick_den_;
  const std::int64_t offset = host_ns - sensor_ns;
  while (!lows_.empty() && lows_.back().offset_ns >= offset) lows_.pop_back();
  lows_.push_back({host_ns, offset});
  while (lows_.front().host_ns < host_ns - window_ns_) lows_.pop_front();
  return sensor_ns + lows_.front().offset_ns;
}

void SensorClock::allowBackSteps(std::uint32_t ticks) {
  if (std::uint64_t{ticks} >= (std::uint64_t{1} << (bits_ - 1)))
    throw std::invalid_argument("SensorClock: a back-step of " + std::to_string(ticks) +
                                " ticks is half the counter's range or more; it could not "
                                "tell a wrap");
  max_back_ticks_ = ticks;
}

void SensorClock::reset() {
  last_ticks_.reset();
  unwrapped_ticks_ = 0;
  wraps_ = 0;
  lows_.clear();
}

std::optional<std::int64_t> SensorClock::offset() const {
  if (lows_.empty()) return std::nullopt;
  return lows_.front().offset_ns;
}

}  // namespace tessera::drivers
