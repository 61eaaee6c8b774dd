// GyroBuffer: integrating the mean-rate samples of an integrating gyro over tick intervals.
#include <tessera/localization/gyro_buffer.hpp>

#include <catch2/catch.hpp>

#include <limits>

using tessera::localization::GyroBuffer;

namespace {
constexpr std::int64_t kMs = 1'000'000;
}

TEST_CASE("GyroBuffer integrates rate x interval, pro rata at partial overlaps",
          "[localization][gyro]") {
  GyroBuffer g;
  CHECK_FALSE(g.integrate(0, 10 * kMs));  // empty
  REQUIRE(g.add(0, 5.0));                 // marks the start only
  REQUIRE(g.add(10 * kMs, 1.0));          // 1 rad/s over (0, 10 ms]
  REQUIRE(g.add(20 * kMs, 3.0));          // 3 rad/s over (10, 20 ms]
  CHECK(g.covers(0, 20 * kMs));
  CHECK_FALSE(g.covers(0, 21 * kMs));
  CHECK_FALSE(g.integrate(0, 25 * kMs));  // not covered yet
  // (0, 15 ms]: 10 ms at 1 rad/s + 5 ms at 3 rad/s.
  CHECK(*g.integrate(0, 15 * kMs) == Approx(0.010 + 0.015));
  // (15, 20 ms]: the rest of the second sample.
  CHECK(*g.integrate(15 * kMs, 20 * kMs) == Approx(0.015));
  REQUIRE(g.add(30 * kMs, -2.0));
  CHECK(*g.integrate(20 * kMs, 30 * kMs) == Approx(-0.02));
  CHECK(g.size() == 1);  // only the sample marking where coverage resumes
  // Before the start of coverage (dropped samples) is not covered.
  CHECK_FALSE(g.integrate(10 * kMs, 30 * kMs));
}

TEST_CASE("GyroBuffer refuses NaN, infinite and out-of-order samples", "[localization][gyro]") {
  GyroBuffer g;
  CHECK_FALSE(g.add(0, std::numeric_limits<double>::quiet_NaN()));
  CHECK_FALSE(g.add(0, std::numeric_limits<double>::infinity()));
  CHECK(g.size() == 0);
  REQUIRE(g.add(10 * kMs, 1.0));
  CHECK_FALSE(g.add(10 * kMs, 1.0));  // same stamp
  CHECK_FALSE(g.add(5 * kMs, 1.0));   // earlier
  REQUIRE(g.add(30 * kMs, 2.0));      // a skipped sample's interval goes to the next one
  CHECK(*g.integrate(10 * kMs, 30 * kMs) == Approx(0.04));
  CHECK(*g.lastStamp() == 30 * kMs);
}
