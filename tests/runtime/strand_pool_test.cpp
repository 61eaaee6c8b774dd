// Tests for the executor's internals (runtime/src/executor.hpp).
#include "executor.hpp"

#include <catch2/catch.hpp>

using tessera::Nanos;
using tessera::detail::PostRate;

TEST_CASE("idle executor threads poll only while work is posted faster than the poll window",
          "[runtime]") {
  constexpr Nanos kWindow = 20'000;
  PostRate rate(kWindow);
  Nanos now = 1'000'000;
  SECTION("a steady stream of posts microseconds apart is worth polling for") {
    for (int i = 0; i < 50; ++i) rate.post(now += 1'000);
    CHECK(rate.steady());
  }
  SECTION("posts a millisecond apart (long handlers, sparse input) are not") {
    for (int i = 0; i < 50; ++i) rate.post(now += 1'000'000);
    CHECK_FALSE(rate.steady());
  }
  SECTION("the estimate follows a change of pace both ways") {
    for (int i = 0; i < 50; ++i) rate.post(now += 1'000);
    REQUIRE(rate.steady());
    for (int i = 0; i < 3; ++i) rate.post(now += 2'000'000);
    CHECK_FALSE(rate.steady());
    for (int i = 0; i < 80; ++i) rate.post(now += 1'000);
    CHECK(rate.steady());
  }
}
