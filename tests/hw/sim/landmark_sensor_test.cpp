#include <tessera/sim/landmark_sensor.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>

using namespace tessera;
using namespace tessera::sim;

namespace {

LandmarkSensorConfig noiseless() {
  LandmarkSensorConfig c;
  c.range_noise = 0;
  c.bearing_noise = 0;
  return c;
}

}  // namespace

TEST_CASE("LandmarkSensor: a known landmark at a known range and bearing", "[sim][landmarks]") {
  const LandmarkSensor sensor({{7, {4, 5}}}, noiseless());
  std::mt19937_64 rng(1);
  // Robot at (1, 1) facing +y: the landmark is 3 right, 4 ahead: range 5, bearing -atan2(3, 4).
  const auto z = sensor.observe({1, 1, std::numbers::pi / 2}, rng);
  REQUIRE(z.size() == 1);
  CHECK(z[0].id == 7);
  CHECK(z[0].true_id == 7);
  CHECK(z[0].range == Approx(5.0));
  CHECK(z[0].bearing == Approx(-std::atan2(3.0, 4.0)));

  // The mount moves and turns the sensor: 1 m ahead and turned left by 90 deg.
  LandmarkSensorConfig c = noiseless();
  c.fov = 2 * std::numbers::pi;
  c.mount = {1, 0, std::numbers::pi / 2};
  const LandmarkSensor mounted({{7, {4, 5}}}, c);
  const auto m = mounted.observe({1, 1, std::numbers::pi / 2}, rng);  // sensor at (1, 2), facing -x
  REQUIRE(m.size() == 1);
  CHECK(m[0].range == Approx(std::hypot(3.0, 3.0)));
  CHECK(m[0].bearing == Approx(-3 * std::numbers::pi / 4));
}

TEST_CASE("LandmarkSensor: field of view and range limits cut observations", "[sim][landmarks]") {
  LandmarkSensorConfig c = noiseless();
  c.fov = std::numbers::pi / 2;  // +-45 deg
  c.max_range = 10;
  c.min_range = 1;
  const LandmarkSensor sensor({{0, {5, 0}},     // ahead, 5 m: seen
                               {1, {5, 5.2}},   // 46 deg left: outside the view
                               {2, {5, 4.8}},   // 43.8 deg: seen
                               {3, {10.5, 0}},  // too far
                               {4, {0.5, 0}},   // too close
                               {5, {-5, 0}}},   // behind
                              c);
  std::mt19937_64 rng(1);
  const auto z = sensor.observe({0, 0, 0}, rng);
  REQUIRE(z.size() == 2);
  CHECK(z[0].id == 0);
  CHECK(z[1].id == 2);
}

TEST_CASE("LandmarkSensor: without ids reports -1, sorted by bearing", "[sim][landmarks]") {
  LandmarkSensorConfig c = noiseless();
  c.with_ids = false;
  const LandmarkSensor sensor({{0, {5, 3}}, {1, {5, -3}}, {2, {5, 0}}}, c);
  std::mt19937_64 rng(1);
  const auto z = sensor.observe({0, 0, 0}, rng);
  REQUIRE(z.size() == 3);
  for (const auto& o : z) CHECK(o.id == -1);
  CHECK(z[0].true_id == 1);
  CHECK(z[1].true_id == 2);
  CHECK(z[2].true_id == 0);
  CHECK(z[0].bearing < z[1].bearing);
  CHECK(z[1].bearing < z[2].bearing);
}

TEST_CASE("LandmarkSensor: noise statistics and bearing wrap", "[sim][landmarks]") {
  LandmarkSensorConfig c;
  c.range_noise = 0.2;
  c.bearing_noise = 0.05;
  c.fov = 2 * std::numbers::pi;
  const LandmarkSensor sensor({{0, {-10, 0.001}}}, c);  // bearing close to +pi
  std::mt19937_64 rng(5);
  double sr = 0, sr2 = 0, sb2 = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    const auto z = sensor.observe({0, 0, 0}, rng);
    REQUIRE(z.size() == 1);
    CHECK(z[0].bearing > -std::numbers::pi);
    CHECK(z[0].bearing <= std::numbers::pi);
    const double er = z[0].range - std::hypot(10.0, 0.001);
    const double eb = normalizeAngle(z[0].bearing - std::atan2(0.001, -10.0));
    sr += er;
    sr2 += er * er;
    sb2 += eb * eb;
  }
  CHECK(std::abs(sr / n) < 0.01);
  CHECK(std::sqrt(sr2 / n) == Approx(0.2).epsilon(0.05));
  CHECK(std::sqrt(sb2 / n) == Approx(0.05).epsilon(0.05));
  CHECK(normalizeAngle(-std::numbers::pi) == Approx(std::numbers::pi));
}

TEST_CASE("LandmarkSensor: walls occlude landmarks when asked", "[sim][landmarks]") {
  World world = World::box(10, 10, 0.05);
  world.fillRect(4.0, 0.0, 4.2, 5.0);  // a wall at x in [4, 4.2] up to y = 5
  const std::vector<PointLandmark> lms = {{0, {7, 3}}, {1, {6, 9}}, {2, {4.0, 3}}};
  LandmarkSensorConfig c = noiseless();
  c.fov = 2 * std::numbers::pi;
  std::mt19937_64 rng(1);
  const Pose2 robot{2, 3, 0};
  CHECK(LandmarkSensor(lms, c).observe(robot, rng).size() == 3);
  c.occlusion = true;
  const auto z = LandmarkSensor(lms, c, &world).observe(robot, rng);
  REQUIRE(z.size() == 2);
  CHECK(z[0].id == 1);                                             // over the end of the wall
  CHECK(z[1].id == 2);                                             // on the wall's face: still seen
  CHECK_THROWS_AS(LandmarkSensor(lms, c), std::invalid_argument);  // occlusion without world
}

TEST_CASE("LandmarkSensor: bad configs and landmarks are rejected", "[sim][landmarks]") {
  LandmarkSensorConfig c;
  c.fov = 0;
  CHECK_THROWS_AS(LandmarkSensor({}, c), std::invalid_argument);
  c = LandmarkSensorConfig{};
  c.max_range = std::nan("");
  CHECK_THROWS_AS(LandmarkSensor({}, c), std::invalid_argument);
  c = LandmarkSensorConfig{};
  CHECK_THROWS_AS(LandmarkSensor({{1, {0, 0}}, {1, {1, 1}}}, c), std::invalid_argument);
  CHECK_THROWS_AS(LandmarkSensor({{0, {std::nan(""), 0}}}, c), std::invalid_argument);
}
