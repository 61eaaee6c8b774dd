#include <tessera/sim/car_like.hpp>
#include <tessera/sim/landmark_sensor.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <set>

using namespace tessera;
using namespace tessera::sim;

namespace {

CarLikeConfig noiseless() {
  CarLikeConfig c;
  c.sigma_speed = 0;
  c.sigma_steer = 0;
  return c;
}

// Closed form of the continuous model for constant V, gamma (omega = V sin(gamma) / L).
Pose2 circle(const Pose2& p0, double v, double g, double l, double t) {
  const double w = v * std::sin(g) / l, a0 = p0.theta + g, a1 = a0 + w * t;
  return {p0.x + v / w * (std::sin(a1) - std::sin(a0)),
          p0.y - v / w * (std::cos(a1) - std::cos(a0)), normalizeAngle(p0.theta + w * t)};
}

}  // namespace

TEST_CASE(
    "carLikeStep: one step follows the the model of "
    "docs/algorithms.md#simulated-motion-and-sensors",
    "[sim][carlike]") {
  const Pose2 p = carLikeStep({1, 2, 0.3}, 3, 0.2, 0.03, 1.0);
  CHECK(p.x == Approx(1 + 0.09 * std::cos(0.5)));
  CHECK(p.y == Approx(2 + 0.09 * std::sin(0.5)));
  CHECK(p.theta == Approx(0.3 + 0.09 * std::sin(0.2)));
}

TEST_CASE("CarLikeRobot: constant steering drives the closed-form circle", "[sim][carlike]") {
  const double v = 3, g = 0.3, l = 1.0;
  const Pose2 start{5, -2, 0.4};
  auto errorAfter = [&](double dt, double t_end) {
    CarLikeConfig c = noiseless();
    c.steer_rate = 1e6;  // reach the angle in the first step
    CarLikeRobot robot(start, c, 1);
    robot.step(0, g, dt);  // turn the wheels at rest
    const int n = static_cast<int>(std::lround(t_end / dt));
    for (int i = 0; i < n; ++i) robot.step(v, g, dt);
    const Pose2 want = circle(start, v, g, l, t_end);
    return std::hypot(robot.truePose().x - want.x, robot.truePose().y - want.y);
  };
  // Radius L / sin(gamma) = 3.38 m; 5 s is more than two laps.
  const double coarse = errorAfter(0.03, 5.0), fine = errorAfter(0.001, 5.0);
  INFO("coarse " << coarse << " fine " << fine);
  CHECK(fine < 0.02);
  CHECK(fine < coarse / 10);  // first-order convergence

  // Without noise the odometry is the truth.
  CarLikeRobot robot(start, noiseless(), 1);
  for (int i = 0; i < 100; ++i) robot.step(v, g, 0.03);
  CHECK(robot.odometryPose().x == robot.truePose().x);
  CHECK(robot.odometryPose().theta == robot.truePose().theta);
}

TEST_CASE("CarLikeRobot: steering rate and angle limits hold", "[sim][carlike]") {
  CarLikeRobot robot({0, 0, 0}, noiseless(), 1);
  const double dt = 0.03, rate = 0.2 * std::numbers::pi, max = 30 * std::numbers::pi / 180;
  double prev = 0;
  int steps_to_max = -1;
  for (int i = 0; i < 200; ++i) {
    const double demand = (i / 50) % 2 == 0 ? 1.0 : -1.0;  // bang-bang beyond the limit
    robot.step(3, demand, dt);
    CHECK(std::abs(robot.steering() - prev) <= rate * dt + 1e-12);
    CHECK(std::abs(robot.steering()) <= max + 1e-12);
    if (steps_to_max < 0 && robot.steering() >= max - 1e-12) steps_to_max = i + 1;
    prev = robot.steering();
  }
  // 30 deg at 36 deg/s: 0.833 s = 28 steps of 0.03 s.
  CHECK(steps_to_max == 28);
}

TEST_CASE("CarLikeRobot: reported controls carry the configured noise", "[sim][carlike]") {
  CarLikeConfig c;  // 0.3 m/s, 3 deg
  CarLikeRobot robot({0, 0, 0}, c, 9);
  double sv = 0, sv2 = 0, sg2 = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    const DriveCommand applied = robot.step(3, 0.1, 0.03);
    const double ev = robot.lastReportedControl().speed - applied.speed;
    const double eg = robot.lastReportedControl().steer - applied.steer;
    sv += ev;
    sv2 += ev * ev;
    sg2 += eg * eg;
  }
  CHECK(std::abs(sv / n) < 0.01);
  CHECK(std::sqrt(sv2 / n) == Approx(0.3).epsilon(0.05));
  CHECK(std::sqrt(sg2 / n) == Approx(3 * std::numbers::pi / 180).epsilon(0.05));
  CHECK(robot.distanceTravelled() == Approx(n * 0.09));
}

TEST_CASE("WaypointSteering: the seed 004 route is driven through all 14 waypoints",
          "[sim][carlike][worlds]") {
  const World world = World::builtinLandmarks();
  WaypointSteering steering(world.defaultRoute(), 1.0);
  REQUIRE(steering.waypointCount() == 14);
  CarLikeRobot robot(steering.startPose(), CarLikeConfig{}, 4);
  const double dt = 0.03;
  std::size_t steps = 0;
  double max_off = 0;
  while (!steering.done() && steps < 20000) {
    const double demand = steering.demand(robot.truePose());
    if (steering.done()) break;
    robot.step(3, demand, dt);
    ++steps;
    const Pose2& p = robot.truePose();
    max_off = std::max({max_off, -p.x, -p.y, p.x - 100, p.y - 90});
  }
  CHECK(steering.done());
  CHECK(steering.reached() == 14);
  CHECK(max_off <= 0);  // stays in the 100 m x 90 m area
  // About the route length at 3 m/s (the car cuts corners a little).
  const double driven = robot.distanceTravelled();
  INFO("route " << steering.totalLength() << " m, driven " << driven << " m in " << steps * dt
                << " s");
  CHECK(driven == Approx(steering.totalLength()).epsilon(0.05));

  // Every landmark is seen from the route with the seed 004 sensor (180 deg, 30 m).
  LandmarkSensorConfig sc;
  sc.range_noise = sc.bearing_noise = 0;
  const LandmarkSensor sensor(world.landmarks(), sc);
  WaypointSteering again(world.defaultRoute(), 1.0);
  CarLikeRobot car(again.startPose(), CarLikeConfig{}, 4);
  std::mt19937_64 rng(1);
  std::set<int> seen;
  while (!again.done()) {
    for (const auto& z : sensor.observe(car.truePose(), rng)) seen.insert(z.true_id);
    const double demand = again.demand(car.truePose());
    car.step(3, demand, dt);
  }
  CHECK(seen.size() == 27);
}

TEST_CASE("CarLikeRobot and WaypointSteering reject bad input", "[sim][carlike]") {
  CarLikeConfig c;
  c.max_steer = 2.0;
  CHECK_THROWS_AS(CarLikeRobot({}, c, 1), std::invalid_argument);
  c = CarLikeConfig{};
  c.wheelbase = 0;
  CHECK_THROWS_AS(CarLikeRobot({}, c, 1), std::invalid_argument);
  CHECK_THROWS_AS(WaypointSteering({{0, 0}}, 1.0), std::invalid_argument);
  CHECK_THROWS_AS(WaypointSteering({{0, 0}, {0, 0}}, 1.0), std::invalid_argument);
  CHECK_THROWS_AS(WaypointSteering({{0, 0}, {1, 0}}, 0.0), std::invalid_argument);
}
