#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

using namespace tessera;
using namespace tessera::sim;

namespace {}

TEST_CASE("Pose2 math: wrap, compose, moveBy", "[sim][robot]") {
  CHECK(normalizeAngle(0.5) == Approx(0.5));
  CHECK(normalizeAngle(3 * std::numbers::pi / 2) == Approx(-std::numbers::pi / 2));
  CHECK(normalizeAngle(-3 * std::numbers::pi / 2) == Approx(std::numbers::pi / 2));
  CHECK(normalizeAngle(std::numbers::pi) ==
        Approx(std::numbers::pi));  // (-pi, pi], as every pose in the tree
  CHECK(normalizeAngle(7 * 2 * std::numbers::pi + 0.25) == Approx(0.25));

  const Pose2 a{1.0, 2.0, std::numbers::pi / 2};
  const Pose2 c = compose(a, {1.0, 0.0, std::numbers::pi / 4});
  CHECK(c.x == Approx(1.0).margin(1e-12));
  CHECK(c.y == Approx(3.0));
  CHECK(c.theta == Approx(3 * std::numbers::pi / 4));

  const Pose2 straight = moveBy({0, 0, std::numbers::pi / 2}, 2.0, 0.0);
  CHECK(straight.x == Approx(0.0).margin(1e-12));
  CHECK(straight.y == Approx(2.0));
  const Pose2 turn = moveBy({1, 1, 0}, 0.0, 0.3);
  CHECK(turn.x == 1.0);
  CHECK(turn.y == 1.0);
  CHECK(turn.theta == Approx(0.3));

  // Many small steps along a circle of radius 1 stay on it (mid-step heading integration).
  Pose2 p{0, 0, 0};
  const int n = 1000;
  for (int i = 0; i < n; ++i) p = moveBy(p, 2 * std::numbers::pi / n, 2 * std::numbers::pi / n);
  CHECK(p.x == Approx(0.0).margin(1e-5));
  CHECK(p.y == Approx(0.0).margin(1e-5));
  CHECK(std::abs(normalizeAngle(p.theta)) < 1e-9);
}

TEST_CASE("Odometry: zero noise reproduces the true pose exactly", "[sim][robot][odometry]") {
  DiffDriveRobot robot({3.0, 4.0, 0.5}, OdometryNoise{0.0, 0.0}, 42);
  std::mt19937_64 cmd_rng(9);
  std::uniform_real_distribution<double> uv(0.0, 0.5), uw(-1.0, 1.0);
  for (int i = 0; i < 5000; ++i) robot.step({uv(cmd_rng), uw(cmd_rng)}, 0.01);
  CHECK(robot.odometry().pose().x == robot.truePose().x);
  CHECK(robot.odometry().pose().y == robot.truePose().y);
  CHECK(robot.odometry().pose().theta == robot.truePose().theta);
  CHECK(robot.odometry().covariance().isZero());
  CHECK(robot.distanceTravelled() == Approx(5000 * 0.25 * 0.01).epsilon(0.05));
}

TEST_CASE("Odometry: per-step increment noise follows the proportional model",
          "[sim][robot][odometry]") {
  const OdometryNoise noise{0.05, 0.08, 0.0, 0.0};
  const double d = 0.1, t = 0.2;
  const int n = 40000;

  SECTION("straight steps: distance error std is sigma_d * D, no heading error") {
    Odometry odo({0, 0, 0}, noise);
    std::mt19937_64 rng(123);
    double sum = 0, sum2 = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d inc = odo.integrate(d, 0.0, rng);
      const double e = inc[0] - d;
      sum += e;
      sum2 += e * e;
      REQUIRE(inc[1] == 0.0);  // |theta| = 0 and no floor: no rotation noise
    }
    const double mean = sum / n, var = sum2 / n - mean * mean;
    CHECK(std::abs(mean) < 4 * 0.005 / std::sqrt(n));
    // Sample variance of n normals has relative std sqrt(2/n) = 0.7 %.
    CHECK(var == Approx((noise.sigma_d * d) * (noise.sigma_d * d)).epsilon(0.03));
    CHECK(odo.pose().y == Approx(0.0).margin(1e-12));
  }

  SECTION("rotations in place: rotation error std is sigma_theta * theta") {
    Odometry odo({0, 0, 0}, noise);
    std::mt19937_64 rng(321);
    double sum = 0, sum2 = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d inc = odo.integrate(0.0, -t, rng);
      const double e = inc[1] + t;
      sum += e;
      sum2 += e * e;
      REQUIRE(inc[0] == 0.0);
    }
    const double mean = sum / n, var = sum2 / n - mean * mean;
    CHECK(std::abs(mean) < 4 * 0.016 / std::sqrt(n));
    CHECK(var == Approx((noise.sigma_theta * t) * (noise.sigma_theta * t)).epsilon(0.03));
  }

  SECTION("the floor adds a small std where the proportional term is zero") {
    Odometry odo({0, 0, 0}, OdometryNoise{0.05, 0.05, 1e-3, 2e-3});
    CHECK(odo.incrementStd(0.0, 0.0).isZero());  // at rest: nothing to corrupt
    CHECK(odo.incrementStd(0.0, 0.2).isApprox(Eigen::Vector2d(1e-3, 0.01 + 2e-3)));
    CHECK(odo.incrementStd(0.1, -0.2).isApprox(Eigen::Vector2d(0.005 + 1e-3, 0.01 + 2e-3)));
    Odometry perfect({0, 0, 0}, OdometryNoise{0.0, 0.0, 1e-3, 2e-3});
    CHECK(perfect.incrementStd(0.1, 0.2).isZero());  // zero sigma means exact odometry
  }
}

TEST_CASE("Odometry: accumulated drift matches the propagated covariance",
          "[sim][robot][odometry]") {
  // 300 trials of 200 straight steps of 5 cm with heading noise from a small floor: the
  // spread of the final odometry pose must match covariance() (which all trials share, since
  // it only depends on the increments).
  const OdometryNoise noise{0.05, 0.05, 0.0, 2e-3};
  const int trials = 300, steps = 200;
  std::mt19937_64 rng(77);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> finals;
  Eigen::Matrix3d model;
  for (int k = 0; k < trials; ++k) {
    Odometry odo({0, 0, 0}, noise);
    for (int i = 0; i < steps; ++i) odo.integrate(0.05, 0.0, rng);
    finals.emplace_back(odo.pose().x, odo.pose().y, odo.pose().theta);
    mean += finals.back() / trials;
    model = odo.covariance();
  }
  for (const auto& f : finals) cov += (f - mean) * (f - mean).transpose() / (trials - 1);
  CHECK(mean.x() == Approx(10.0).epsilon(0.01));
  // Sample variances of 300 trials are within ~20 % of the truth (3 sigma).
  CHECK(cov(0, 0) == Approx(model(0, 0)).epsilon(0.3));
  CHECK(cov(1, 1) == Approx(model(1, 1)).epsilon(0.3));
  CHECK(cov(2, 2) == Approx(model(2, 2)).epsilon(0.3));
  // Model: x variance is steps * (sigma_d * D)^2.
  CHECK(model(0, 0) == Approx(steps * std::pow(0.05 * 0.05, 2)).epsilon(0.05));
}

TEST_CASE("Odometry: deterministic for a seed", "[sim][robot][odometry]") {
  auto run = [](std::uint64_t seed) {
    DiffDriveRobot r({0, 0, 0}, OdometryNoise{}, seed);
    for (int i = 0; i < 1000; ++i) r.step({0.4, 0.3}, 0.01);
    return r.odometry().pose();
  };
  const Pose2 a = run(5), b = run(5), c = run(6);
  CHECK(a.x == b.x);
  CHECK(a.y == b.y);
  CHECK(a.theta == b.theta);
  CHECK(a.x != c.x);
}

namespace {
struct FollowResult {
  std::vector<Pose2> trajectory;
  double max_v = 0, max_w = 0, max_accel = 0;
  double time = 0;
  bool done = false;
};

FollowResult follow(RouteFollower& f, double dt, double time_limit) {
  DiffDriveRobot robot(f.startPose(), OdometryNoise{0, 0}, 1);
  FollowResult out;
  double last_v = 0;
  out.trajectory.push_back(robot.truePose());
  while (out.time < time_limit && !f.done()) {
    const Twist cmd = f.command(robot.truePose(), dt);
    out.max_v = std::max(out.max_v, std::abs(cmd.v));
    out.max_w = std::max(out.max_w, std::abs(cmd.omega));
    out.max_accel = std::max(out.max_accel, std::abs(cmd.v - last_v) / dt);
    last_v = cmd.v;
    robot.step(cmd, dt);
    out.time += dt;
    out.trajectory.push_back(robot.truePose());
  }
  out.done = f.done();
  return out;
}

double closestApproach(const std::vector<Pose2>& traj, const Eigen::Vector2d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Pose2& q : traj) best = std::min(best, (q.translation() - p).norm());
  return best;
}
}  // namespace

TEST_CASE("RouteFollower: drives a square with limits respected", "[sim][robot][follower]") {
  const std::vector<Eigen::Vector2d> square{{0, 0}, {4, 0}, {4, 3}, {0, 3}, {0, 0}};
  FollowerConfig cfg;
  RouteFollower f(square, cfg);
  CHECK(f.totalLength() == Approx(14.0));
  CHECK(f.legCount() == 4);
  const Pose2 start = f.startPose();
  CHECK(start.theta == Approx(0.0));

  const FollowResult r = follow(f, 0.01, 200.0);
  REQUIRE(r.done);
  CHECK(f.progress() == 1.0);
  CHECK(r.max_v <= cfg.v_max + 1e-12);
  CHECK(r.max_w <= cfg.w_max + 1e-12);
  CHECK(r.max_accel <= cfg.a_max + 1e-6);
  CHECK(r.time > 14.0 / cfg.v_max);  // cannot beat driving at top speed all the way
  CHECK(r.time < 60.0);
  for (const auto& w : square) CHECK(closestApproach(r.trajectory, w) < cfg.waypoint_tolerance);
  // After finishing it commands nothing.
  CHECK(f.command(r.trajectory.back(), 0.01).v == 0.0);
}

TEST_CASE("RouteFollower: laps and progress", "[sim][robot][follower]") {
  const std::vector<Eigen::Vector2d> open_route{{0, 0}, {3, 0}, {3, 3}};
  RouteFollower two(open_route, FollowerConfig{}, 2);
  // An open route gets a closing leg between laps.
  CHECK(two.legCount() == 5);
  CHECK(two.totalLength() == Approx(2 * 6.0 + std::sqrt(18.0)));
  CHECK(two.progress() == 0.0);

  DiffDriveRobot robot(two.startPose(), OdometryNoise{0, 0}, 1);
  double last = 0;
  bool monotone = true;
  for (int i = 0; i < 20000 && !two.done(); ++i) {
    robot.step(two.command(robot.truePose(), 0.01), 0.01);
    monotone = monotone && two.progress() >= last - 1e-3;
    last = two.progress();
  }
  CHECK(two.done());
  CHECK(monotone);
  CHECK((robot.truePose().translation() - Eigen::Vector2d(3, 3)).norm() < 0.1);
}

TEST_CASE("RouteFollower: a kidnapped robot goes on from where it was put on the route",
          "[sim][robot][follower]") {
  const std::vector<Eigen::Vector2d> square{{0, 0}, {4, 0}, {4, 3}, {0, 3}, {0, 0}};
  RouteFollower f(square, FollowerConfig{});
  // 5.5 m along: 1.5 m up the second leg, facing along it.
  const Pose2 at = f.jumpTo(5.5);
  CHECK(at.x == Approx(4.0));
  CHECK(at.y == Approx(1.5));
  CHECK(at.theta == Approx(std::numbers::pi / 2));
  CHECK(f.legIndex() == 1);
  CHECK(f.progress() == Approx(5.5 / 14.0));
  // Put down turned away from the route, it turns back and finishes the route from there
  // without going back to the first leg.
  DiffDriveRobot robot(Pose2(at.x, at.y, at.theta + 2.0), OdometryNoise{0, 0}, 1);
  double min_y_after = 10;
  for (int i = 0; i < 20000 && !f.done(); ++i) {
    robot.step(f.command(robot.truePose(), 0.01), 0.01);
    if (robot.truePose().x > 3.5) min_y_after = std::min(min_y_after, robot.truePose().y);
  }
  CHECK(f.done());
  CHECK(min_y_after > 1.0);  // never drove the first leg again
  CHECK((robot.truePose().translation() - Eigen::Vector2d(0, 0)).norm() < 0.2);
  // Out of range: clamped to the route's ends.
  CHECK(f.jumpTo(-3).x == Approx(0.0));
  CHECK(f.jumpTo(99).y == Approx(0.0).margin(1e-9));
  CHECK_FALSE(f.done());
}

TEST_CASE("RouteFollower: bad routes and configs", "[sim][robot][follower]") {
  CHECK_THROWS_AS(RouteFollower({}, FollowerConfig{}), std::invalid_argument);
  CHECK_THROWS_AS(RouteFollower({{1, 1}}, FollowerConfig{}), std::invalid_argument);
  CHECK_THROWS_AS(RouteFollower({{0, 0}, {1, 0}, {1, 0}}, FollowerConfig{}), std::invalid_argument);
  CHECK_THROWS_AS(RouteFollower({{0, 0}, {1, 0}}, FollowerConfig{}, 0), std::invalid_argument);
  FollowerConfig slow;
  slow.v_max = 0;
  CHECK_THROWS_AS(RouteFollower({{0, 0}, {1, 0}}, slow), std::invalid_argument);
}

TEST_CASE("RouteFollower: the office route is driven without touching walls",
          "[sim][robot][follower]") {
  const World office = World::builtinOffice();
  const Route& route = office.defaultRoute();
  FollowerConfig cfg;
  RouteFollower f(route, cfg);
  const FollowResult r = follow(f, 0.01, 2000.0);
  REQUIRE(r.done);
  INFO("route took " << r.time << " s");
  CHECK(r.time < 1.6 * f.totalLength() / cfg.v_max);
  for (std::size_t i = 0; i < route.size(); ++i) {
    INFO("waypoint " << i);
    CHECK(closestApproach(r.trajectory, route[i]) < cfg.waypoint_tolerance);
  }
  // The robot stays well clear of walls (the route keeps 0.35 m; corner cutting costs little).
  double min_clear = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < r.trajectory.size(); i += 5)
    min_clear = std::min(min_clear, office.clearance(r.trajectory[i].translation(), 1.0));
  CHECK(min_clear > 0.25);
}

TEST_CASE("Odometry: systematic biases make dead reckoning drift", "[sim][robot]") {
  std::mt19937_64 rng(5);
  OdometryNoise noise{0.0, 0.0};
  noise.bias_d = 0.1;        // wheels report 10 % too much distance
  noise.drift_theta = 0.01;  // and turn 0.01 rad per metre
  Odometry odo({0, 0, 0}, noise);
  for (int i = 0; i < 1000; ++i) odo.integrate(0.01, 0.0, rng);  // 10 m straight
  const double path = 10.0 * 1.1;
  CHECK(odo.pose().theta == Approx(0.01 * 10.0).margin(1e-9));
  // Driving an arc of length 11 m that turns by 0.1 rad.
  CHECK(std::hypot(odo.pose().x, odo.pose().y) == Approx(path).epsilon(0.01));
  CHECK(odo.pose().y > 0.3);
  noise.bias_theta = 0.05;
  noise.bias_d = 0.0;
  noise.drift_theta = 0.0;
  Odometry turn({0, 0, 0}, noise);
  for (int i = 0; i < 100; ++i) turn.integrate(0.0, 0.01, rng);  // 1 rad in place
  CHECK(turn.pose().theta == Approx(1.05).margin(1e-9));
}

TEST_CASE("DiffDriveRobot: the base follows commands under its acceleration limits",
          "[sim][robot]") {
  OdometryNoise quiet;
  quiet.sigma_d = quiet.sigma_theta = 0;
  const double dt = 0.01;
  SECTION("limited: speed ramps at a_max and alpha_max, and brakes likewise") {
    DiffDriveRobot robot({0, 0, 0}, quiet, 1, BaseLimits{0.5, 2.0});
    for (int i = 1; i <= 50; ++i) {
      robot.step({1.0, -1.5}, dt);
      CHECK(robot.velocity().v == Approx(std::min(1.0, 0.5 * dt * i)));
      CHECK(robot.velocity().omega == Approx(std::max(-1.5, -2.0 * dt * i)));
    }
    // After 0.5 s: v = 0.25 m/s; distance = sum of 0.005 i dt = 0.005 * 1275 * 0.01.
    CHECK(robot.distanceTravelled() == Approx(0.5 * dt * dt * 50 * 51 / 2));
    robot.step({0, 0}, dt);  // braking is limited too
    CHECK(robot.velocity().v == Approx(0.25 - 0.5 * dt));
    CHECK(robot.velocity().omega == Approx(-1.0 + 2.0 * dt));
  }
  SECTION("unlimited (0): the command itself, bit for bit") {
    DiffDriveRobot robot({0, 0, 0}, quiet, 1);
    robot.step({0.37, -0.81}, dt);
    CHECK(robot.velocity().v == 0.37);
    CHECK(robot.velocity().omega == -0.81);
  }
  SECTION("bad limits are named") {
    CHECK(BaseLimits{-1, 0}.check().problem()->key == "a_max");
    CHECK(BaseLimits{0, std::numeric_limits<double>::quiet_NaN()}.check().problem()->key ==
          "alpha_max");
  }
}
