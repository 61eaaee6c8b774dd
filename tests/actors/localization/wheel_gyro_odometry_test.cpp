// The wheel_gyro_odometry actor through the mock-mailbox harness: wheel ticks alone give the
// hand-computed arc; the gyro corrects a wrong wheel rotation once its samples cover a tick
// interval (ticks wait for them, then time out to wheels alone); bad ticks and gyro samples are
// counted and skipped and the pose stays finite.
#include <tessera/localization/wheel_gyro_odometry_actor.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>

using namespace tessera;
using namespace tessera::localization;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::int64_t kMs = 1'000'000;
// 1000 ticks per revolution of a 0.05 m wheel: pi * 1e-4 m per tick; wheel base 0.4 m.
const double kMetresPerTick = 2 * std::numbers::pi * 0.05 / 1000;

struct Calibration {
  double tpr = 1000, radius = 0.05, base = 0.4;
};

void pushTicks(ActorHarness& h, std::int64_t stamp_ms, std::int64_t left, std::int64_t right,
               Calibration c = {}) {
  h.push<msg::WheelTicks>("wheel_ticks", [&](msg::WheelTicks::Builder b) {
    setHeader(b.initHeader(), stamp_ms * kMs, "base_link", 0);
    b.setLeft(left);
    b.setRight(right);
    b.setTicksPerRevolution(c.tpr);
    b.setWheelRadius(c.radius);
    b.setWheelBase(c.base);
  });
  h.runUntilIdle();
}

void pushImu(ActorHarness& h, std::int64_t stamp_ms, double yaw_rate) {
  h.push<msg::ImuSample>("imu", [&](msg::ImuSample::Builder b) {
    setHeader(b.initHeader(), stamp_ms * kMs, "imu", 0);
    b.setAngularVelocityX(0);
    b.setAngularVelocityY(0);
    b.setAngularVelocityZ(yaw_rate);
    b.setLinearAccelerationX(0);
    b.setLinearAccelerationY(0);
    b.setLinearAccelerationZ(9.8);
  });
  h.runUntilIdle();
}

std::int64_t summaryInt(ActorHarness& h, const std::string& key) {
  Summary s;
  h.actor().summarize(s);
  const auto it = s.find(key);
  return it == s.end() ? -1 : std::get<std::int64_t>(it->second);
}

WheelGyroOdometryOptions options(bool use_gyro) {
  WheelGyroOdometryOptions o;
  o.use_gyro = use_gyro;
  return o;
}

bool finite(const Pose2& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.theta);
}

}  // namespace

TEST_CASE("wheel_gyro_odometry: wheels alone give the hand-computed arc", "[localization][actor]") {
  WheelGyroOdometryOptions o = options(false);
  o.start = {1.0, 2.0, std::numbers::pi / 2};
  ActorHarness h(std::make_unique<WheelGyroOdometryActor>(o));
  pushTicks(h, 0, 500, 700);  // the baseline: no step
  CHECK(h.publishedCount("odom") == 0);
  for (int k = 1; k <= 10; ++k) pushTicks(h, 20 * k, 500 + 100 * k, 700 + 100 * k);
  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(odom.size() == 10);
  // 1000 ticks each: straight ahead (north) by 1000 * pi * 1e-4 m.
  const Pose2 last = toPose2(odom.back()->getPose());
  CHECK(last.x == Approx(1.0).margin(1e-12));
  CHECK(last.y == Approx(2.0 + 1000 * kMetresPerTick));
  CHECK(last.theta == Approx(std::numbers::pi / 2));
  CHECK(odom.back()->getHeader().getStampNs() == 200 * kMs);
  CHECK(std::string(odom.back()->getHeader().getFrameId().cStr()) == "odom");
  CHECK(std::string(odom.back()->getChildFrameId().cStr()) == "base_link");
  CHECK(odom.back()->getTwist().getVx() == Approx(100 * kMetresPerTick / 0.02));
  CHECK(odom.back()->getPose().getCovariance().size() == 9);

  // A turn in place: 100 ticks back on the left, forward on the right.
  pushTicks(h, 220, 1500 - 100, 1700 + 100);
  const auto turn = h.published<msg::Odometry>("odom").back();
  CHECK(toPose2(turn->getPose()).theta ==
        Approx(normalizeAngle(std::numbers::pi / 2 + 200 * kMetresPerTick / 0.4)));
  CHECK(turn->getTwist().getOmega() == Approx(200 * kMetresPerTick / 0.4 / 0.02));
  CHECK(summaryInt(h, "steps") == 11);
  CHECK(summaryInt(h, "steps_with_gyro") == 0);
}

TEST_CASE("wheel_gyro_odometry: ticks wait for the gyro, which corrects their rotation",
          "[localization][actor]") {
  // 1 s standing (the filter learns the gyro's bias), then 1 s driving on which the right wheel
  // reports 2 % more than the left: the wheels alone see a turn where the gyro (no rate) sees
  // none. Ticks at 50 Hz, gyro at 100 Hz.
  const auto right = [](int k) { return k <= 50 ? 0 : 102 * (k - 50); };
  const auto left = [](int k) { return k <= 50 ? 0 : 100 * (k - 50); };
  ActorHarness wheels(std::make_unique<WheelGyroOdometryActor>(options(false)));
  for (int k = 0; k <= 100; ++k) pushTicks(wheels, 20 * k, left(k), right(k));

  ActorHarness fused(std::make_unique<WheelGyroOdometryActor>(options(true)));
  pushImu(fused, 0, 0.0);
  pushTicks(fused, 0, 0, 0);
  // Ticks at 20 ms arrive before the gyro covers them: nothing yet.
  pushTicks(fused, 20, 0, 0);
  CHECK(fused.publishedCount("odom") == 0);
  pushImu(fused, 10, 0.0);
  CHECK(fused.publishedCount("odom") == 0);
  pushImu(fused, 20, 0.0);
  CHECK(fused.publishedCount("odom") == 1);
  for (int k = 2; k <= 100; ++k) {
    pushTicks(fused, 20 * k, left(k), right(k));
    pushImu(fused, 20 * k - 10, 0.0);
    pushImu(fused, 20 * k, 0.0);
  }
  REQUIRE(fused.publishedCount("odom") == 100);
  REQUIRE(wheels.publishedCount("odom") == 100);
  const double wheel_heading =
      toPose2(wheels.published<msg::Odometry>("odom").back()->getPose()).theta;
  const double fused_heading =
      toPose2(fused.published<msg::Odometry>("odom").back()->getPose()).theta;
  CHECK(wheel_heading == Approx(100 * kMetresPerTick / 0.4));  // 0.0785 rad
  CHECK(std::abs(fused_heading) < 0.1 * wheel_heading);
  CHECK(summaryInt(fused, "steps_with_gyro") == 100);
  CHECK(summaryInt(fused, "steps_without_gyro") == 0);
  CHECK(summaryInt(fused, "imu_received") == 201);
}

TEST_CASE(
    "wheel_gyro_odometry: without gyro samples, ticks time out to wheels alone; stop() "
    "flushes",
    "[localization][actor]") {
  WheelGyroOdometryOptions o = options(true);
  o.gyro_timeout_s = 0.1;
  ActorHarness h(std::make_unique<WheelGyroOdometryActor>(o));
  pushTicks(h, 0, 0, 0);
  for (int k = 1; k <= 5; ++k) pushTicks(h, 20 * k, 10 * k, 10 * k);
  // The oldest interval ends 80 ms before the newest ticks: still waiting.
  CHECK(h.publishedCount("odom") == 0);
  pushTicks(h, 150, 60, 60);  // now (0, 20] and (20, 40] are more than 0.1 s old
  CHECK(h.publishedCount("odom") == 2);
  h.stop();  // the rest is stepped on the wheels alone
  CHECK(h.publishedCount("odom") == 6);
  CHECK(summaryInt(h, "steps_without_gyro") == 6);
  const auto last = h.published<msg::Odometry>("odom").back();
  CHECK(toPose2(last->getPose()).x == Approx(60 * kMetresPerTick));
}

TEST_CASE("wheel_gyro_odometry: bad ticks and gyro samples are counted and skipped",
          "[localization][actor]") {
  ActorHarness h(std::make_unique<WheelGyroOdometryActor>(options(true)));
  Calibration bad_radius;
  bad_radius.radius = kNaN;
  pushTicks(h, 0, 0, 0, bad_radius);  // no calibration: not even a baseline
  CHECK(summaryInt(h, "ticks_bad_calibration") == 1);
  pushImu(h, 0, 0.0);
  pushTicks(h, 0, 0, 0);
  pushImu(h, 10, kNaN);  // NaN: its interval goes to the next sample
  pushImu(h, 20, 0.1);
  pushImu(h, 15, 0.0);  // out of order
  pushTicks(h, 20, 50, 50);
  REQUIRE(h.publishedCount("odom") == 1);
  CHECK(summaryInt(h, "steps_with_gyro") == 1);
  // Straight on the wheels; the gyro's turn (partly taken as bias) moved the heading.
  CHECK(toPose2(h.published<msg::Odometry>("odom").back()->getPose()).theta > 1e-4);
  pushTicks(h, 20, 60, 60);  // same stamp: zero dt
  pushTicks(h, 10, 60, 60);  // before the last
  pushImu(h, 40, 0.0);
  pushTicks(h, 40, 0, 0);  // -50 ticks in 20 ms is 0.8 m/s: plausible
  pushImu(h, 60, 0.0);
  pushTicks(h, 60, 1'000'000, -7);  // a counter reset: 1e6 ticks in 20 ms
  pushImu(h, 80, 0.0);
  pushTicks(h, 80, 1'000'010, 3);  // counts on from the new baseline
  Calibration other;
  other.base = 0.5;
  pushImu(h, 100, 0.0);
  pushTicks(h, 100, 1'000'020, 13, other);  // calibration changed: kept the first
  CHECK(summaryInt(h, "ticks_bad_zero_dt") == 1);
  CHECK(summaryInt(h, "ticks_bad_out_of_order") == 1);
  CHECK(summaryInt(h, "ticks_bad_jump") == 1);
  CHECK(summaryInt(h, "ticks_bad") == 4);
  CHECK(summaryInt(h, "imu_bad_nan") == 1);
  CHECK(summaryInt(h, "imu_bad_out_of_order") == 1);
  CHECK(summaryInt(h, "calibration_changes") == 1);
  CHECK(summaryInt(h, "steps") == 4);  // 20, 40, 80, 100
  for (const auto& m : h.published<msg::Odometry>("odom")) CHECK(finite(toPose2(m->getPose())));
  // 50 forward, 50 back, the reset skipped, 10 + 10 forward.
  CHECK(toPose2(h.published<msg::Odometry>("odom").back()->getPose()).x ==
        Approx(20 * kMetresPerTick).margin(1e-4));
}

TEST_CASE("wheel_gyro_odometry: bad options are named", "[localization][actor]") {
  const auto error = [](const WheelGyroOdometryOptions& o) -> std::string {
    try {
      WheelGyroOdometryActor a(o);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  };
  WheelGyroOdometryOptions o;
  o.max_wheel_speed = 0;
  CHECK_THAT(error(o), Catch::Contains("max_wheel_speed"));
  o = {};
  o.gyro_timeout_s = kNaN;
  CHECK_THAT(error(o), Catch::Contains("gyro_timeout_s"));
  o = {};
  o.ekf.gyro_noise = -1;
  CHECK_THAT(error(o), Catch::Contains("gyro_noise"));
  o = {};
  o.start.x = kNaN;
  CHECK_THAT(error(o), Catch::Contains("start"));
}
