// Tests for the progress line: bar, percentage, time left, and runs without finite sources.
#include <catch2/catch.hpp>

#include <cmath>

#include "runtime_impl.hpp"

using tessera::detail::formatProgress;

TEST_CASE("the progress line shows a bar, the share done and the time left", "[console]") {
  const std::string quarter = formatProgress(0.25, true, 100.0, 10.0, true);
  CHECK_THAT(quarter, Catch::StartsWith("[progress] [#####...............]  25.0% | "));
  CHECK_THAT(quarter, Catch::Contains("data 100.0 s | wall 10.0 s | 10.0x real time"));
  // A quarter in 10 s: three quarters left at that rate take 30 s.
  CHECK_THAT(quarter, Catch::EndsWith("| ETA 30 s"));
  CHECK_THAT(formatProgress(0.1, true, 1, 100, false), Catch::EndsWith("ETA 15 min 0 s"));
  CHECK_THAT(formatProgress(0.02, true, 1, 100, false), Catch::EndsWith("ETA 1 h 21 min"));
  CHECK_THAT(formatProgress(0.001, true, 1, 100, false), !Catch::Contains("ETA"));
  CHECK_THAT(formatProgress(0.01, true, 1, 100, false), Catch::EndsWith("ETA 2 h 45 min"));
  // Done: a full bar and no time left.
  const std::string done = formatProgress(1.0, true, 464.8, 5.1, true);
  CHECK_THAT(done, Catch::StartsWith("[progress] [####################] 100.0%"));
  CHECK_THAT(done, !Catch::Contains("ETA"));
  // A wall clock run (sensors): no speed against real time.
  CHECK_THAT(formatProgress(0.5, true, 5, 5, false), !Catch::Contains("real time"));
}

TEST_CASE("the progress line of an endless run and of odd progress values", "[console]") {
  CHECK(formatProgress(0, false, 3.0, 1.5, true) ==
        "[running] data 3.0 s | wall 1.5 s | 2.0x real time");
  CHECK_THAT(formatProgress(std::nan(""), true, 1, 1, false), Catch::Contains("  0.0%"));
  CHECK_THAT(formatProgress(1.7, true, 1, 1, false), Catch::Contains("100.0%"));
  CHECK_THAT(formatProgress(-0.5, true, 1, 1, false), Catch::Contains("  0.0%"));
}
