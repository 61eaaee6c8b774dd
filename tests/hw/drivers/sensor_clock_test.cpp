// SensorClock: a wrapping millisecond counter mapped to host time through the fastest
// transfers.
#include <tessera/drivers/sensor_clock.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <random>

namespace sensor_clock_test {

using tessera::drivers::SensorClock;
constexpr std::int64_t kMs = 1'000'000;

TEST_CASE("sensor clock stamps follow the sensor's timing, not the host's jitter",
          "[drivers][sensor_clock]") {
  SensorClock clock(24, kMs, 10'000 * kMs);
  std::mt19937 rng(3);
  std::uniform_int_distribution<std::int64_t> jitter(0, 20 * kMs);
  const std::int64_t host_zero = 1'700'000'000'000 * kMs;  // host time of sensor tick 0
  const std::uint32_t start = 5'000'000;
  double worst_late = 0;
  for (int k = 0; k < 300; ++k) {
    const std::uint32_t ticks = start + static_cast<std::uint32_t>(100 * k);
    const std::int64_t taken = host_zero + static_cast<std::int64_t>(ticks) * kMs;
    const std::int64_t received = taken + 2 * kMs + jitter(rng);  // 2 ms transfer + 0..20 ms
    const std::int64_t stamp = clock.stamp(ticks, received);
    CHECK(stamp <= received);
    if (k >= 50) worst_late = std::max(worst_late, double(stamp - taken) / kMs);
  }
  // After a few seconds the offset holds only the transfer time and the smallest jitter seen.
  CHECK(worst_late >= 2.0);
  CHECK(worst_late < 3.0);
}

TEST_CASE("sensor clock unwraps its 24-bit counter", "[drivers][sensor_clock]") {
  SensorClock clock(24, kMs);
  const std::uint32_t near_end = (1u << 24) - 150;
  const std::int64_t t0 = clock.stamp(near_end, 1000 * kMs);
  const std::int64_t t1 = clock.stamp(near_end + 100, 1100 * kMs);
  const std::int64_t t2 = clock.stamp(50, 1200 * kMs);  // wrapped
  CHECK(t1 - t0 == 100 * kMs);
  CHECK(t2 - t1 == 100 * kMs);
  CHECK(clock.wraps() == 1);
  clock.reset();
  CHECK_FALSE(clock.offset());
  CHECK(clock.stamp(7, 5000 * kMs) == 5000 * kMs);  // a new session starts a new offset
}

TEST_CASE("sensor clock follows drift through its window", "[drivers][sensor_clock]") {
  SensorClock clock(24, kMs, 2'000 * kMs);
  // The sensor's clock runs 100 ppm slow: after 100 s it is 10 ms behind.
  std::int64_t last_error = 0;
  for (int k = 0; k <= 1000; ++k) {
    const std::int64_t host = 100 * kMs * k;
    const auto ticks = static_cast<std::uint32_t>(std::llround(100.0 * k * (1 - 1e-4)));
    last_error = clock.stamp(ticks, host + kMs) - host;
  }
  CHECK(std::abs(last_error) <= 2 * kMs);
}

TEST_CASE("sensor clock refuses a nonsense configuration", "[drivers][sensor_clock]") {
  CHECK_THROWS_WITH(SensorClock(4), Catch::Contains("bits"));
  CHECK_THROWS(SensorClock(24, 0));
}

TEST_CASE("a 60 MHz 32-bit counter (Kinect v1) maps to host time across its wrap",
          "[drivers][sensor_clock]") {
  auto clock = SensorClock::withTickRate(32, 60'000'000);
  // 30 Hz frames = 2'000'000 ticks each, starting just before the 71.6 s wrap; the host sees
  // them 5 ms late, one of them 4 ms later still.
  std::uint32_t ticks = 0xffffffffu - 3'000'000u;
  const std::int64_t host0 = 1'000'000'000'000;
  std::int64_t first = 0;
  for (int k = 0; k < 6; ++k) {
    const std::int64_t host = host0 + k * 33'333'333 + (k == 3 ? 4'000'000 : 0);
    const std::int64_t s = clock.stamp(ticks, host);
    if (k == 0) first = s;
    // Every stamp keeps the sensor's spacing (2'000'000 ticks = 33.33 ms), whatever the delay.
    CHECK(std::llabs(s - first - k * 33'333'333) <= 1);
    ticks += 2'000'000u;  // wraps after the second frame
  }
  CHECK(clock.wraps() == 1);
}

TEST_CASE(
    "one clock for two streams of one counter: a reading a little behind is earlier, "
    "not a wrap",
    "[drivers][sensor_clock]") {
  // The Kinect's colour and depth frames carry one 60 MHz counter, but the host may get a
  // frame after a later-taken frame of the other stream.
  auto clock = SensorClock::withTickRate(32, 60'000'000);
  clock.allowBackSteps(60'000'000);  // up to 1 s
  const std::int64_t host0 = 1'000'000'000'000;
  const std::int64_t color = clock.stamp(1'120'000, host0);  // taken 2 ms after the depth
  const std::int64_t depth = clock.stamp(1'000'000, host0 + 1'000'000);
  CHECK(color - depth == 2'000'000);
  CHECK(clock.wraps() == 0);
  // The next frame steps on from the newest reading, not from the late one.
  CHECK(std::llabs(clock.stamp(3'000'000, host0 + 33'000'000) - depth - 33'333'333) <= 1);
  // A step back beyond the allowance is a wrap, as without it.
  clock.stamp(60'000'000u * 2, host0 + 2'000'000'000);
  clock.stamp(1'000, host0 + 2'100'000'000);
  CHECK(clock.wraps() == 1);
  // Nonsense allowances are refused: none, or half the counter's range or more.
  CHECK_THROWS_WITH(clock.allowBackSteps(0x80000000u), Catch::Contains("half"));
  CHECK_THROWS_WITH(SensorClock(24, kMs).allowBackSteps(1u << 23), Catch::Contains("half"));
}

}  // namespace sensor_clock_test
