// Tests for PoseHistory: pairing sensor stamps with poses.
#include <tessera/geometry/pose_history.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

using tessera::Pose2;
using tessera::PoseHistory;
using Lookup = PoseHistory::Lookup;

TEST_CASE("pose history interpolates between bracketing poses", "[pose_history]") {
  PoseHistory h(8, 1.0);
  Pose2 out;
  CHECK(h.at(5, out) == Lookup::kWait);
  h.add(1'000'000'000, Pose2(0, 0, 3.0));
  h.add(1'500'000'000, Pose2(1, 2, -3.0));
  CHECK(h.at(1'000'000'000, out) == Lookup::kExact);
  CHECK(out.theta == Approx(3.0));
  REQUIRE(h.at(1'250'000'000, out) == Lookup::kInterpolated);
  CHECK(out.x == Approx(0.5));
  CHECK(out.y == Approx(1.0));
  // Shortest arc through ±π, not through 0.
  CHECK(std::abs(out.theta) == Approx(M_PI).margin(1e-9));
  CHECK(h.at(1'600'000'000, out) == Lookup::kWait);
  CHECK(h.at(900'000'000, out) == Lookup::kTooOld);
  h.add(3'000'000'000, Pose2(5, 5, 0));
  CHECK(h.at(2'000'000'000, out) == Lookup::kGap);  // 1.5 s apart > max gap 1 s
}

TEST_CASE("pose history keeps order, replaces duplicates, forgets the oldest and rejects NaN",
          "[pose_history]") {
  PoseHistory h(3, 10.0);
  CHECK(h.add(30, Pose2(3, 0, 0)));
  CHECK(h.add(10, Pose2(1, 0, 0)));  // out of order: inserted in place
  CHECK(h.add(20, Pose2(2, 0, 0)));
  CHECK(h.add(20, Pose2(2.5, 0, 0)));  // same stamp: replaced
  CHECK(h.size() == 3);
  Pose2 out;
  REQUIRE(h.at(20, out) == Lookup::kExact);
  CHECK(out.x == 2.5);
  CHECK(h.add(40, Pose2(4, 0, 0)));
  CHECK(h.size() == 3);
  CHECK(h.at(10, out) == Lookup::kTooOld);
  CHECK_FALSE(h.add(50, Pose2(std::numeric_limits<double>::quiet_NaN(), 0, 0)));
  CHECK(h.size() == 3);
  CHECK_THROWS_AS(PoseHistory(1, 1.0), std::invalid_argument);
  CHECK_THROWS_AS(PoseHistory(4, 0.0), std::invalid_argument);
}
