#include <tessera/sim/ray_caster.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

using tessera::Pose2;
using tessera::sim::LaserConfig;
using tessera::sim::LaserModel;
using tessera::sim::RayCaster;
using tessera::sim::World;

namespace {

// Distance from o along angle a to the boundary of the open rectangle [x0,x1] x [y0,y1] that
// contains o: the free inside of a box world, whose walls start exactly at those lines.
double rectExit(const Eigen::Vector2d& o, double a, double x0, double y0, double x1, double y1) {
  const double dx = std::cos(a), dy = std::sin(a);
  double t = std::numeric_limits<double>::infinity();
  if (dx > 0) t = std::min(t, (x1 - o.x()) / dx);
  if (dx < 0) t = std::min(t, (x0 - o.x()) / dx);
  if (dy > 0) t = std::min(t, (y1 - o.y()) / dy);
  if (dy < 0) t = std::min(t, (y0 - o.y()) / dy);
  return t;
}
}  // namespace

TEST_CASE("RayCaster: axis and diagonal rays in a box room", "[sim][raycaster]") {
  // 10 m x 8 m at 0.1 m/cell with one-cell walls: the free inside is [0.1, 9.9] x [0.1, 7.9].
  const World box = World::box(10.0, 8.0, 0.1);
  const RayCaster rc(box);
  const Eigen::Vector2d c(5.0, 4.0);
  CHECK(rc.cast(c, 0.0, 30) == Approx(4.9).margin(1e-9));
  CHECK(rc.cast(c, std::numbers::pi, 30) == Approx(4.9).margin(1e-9));
  CHECK(rc.cast(c, std::numbers::pi / 2, 30) == Approx(3.9).margin(1e-9));
  CHECK(rc.cast(c, -std::numbers::pi / 2, 30) == Approx(3.9).margin(1e-9));
  // Diagonals reach the long walls first (3.9 m away across y).
  for (double a : {std::numbers::pi / 4, 3 * std::numbers::pi / 4, -std::numbers::pi / 4,
                   -3 * std::numbers::pi / 4})
    CHECK(rc.cast(c, a, 30) == Approx(3.9 * std::sqrt(2.0)).margin(1e-9));
  // Off-centre, off-axis: exactly the distance to the cell boundary.
  CHECK(rc.cast({2.0, 3.0}, std::atan2(1.0, 2.0), 30) ==
        Approx(rectExit({2.0, 3.0}, std::atan2(1.0, 2.0), 0.1, 0.1, 9.9, 7.9)).margin(1e-9));
}

TEST_CASE("RayCaster: matches analytic distances for random rays", "[sim][raycaster]") {
  const World box = World::box(10.0, 8.0, 0.1);
  const RayCaster rc(box);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> ux(0.2, 9.8), uy(0.2, 7.8),
      ua(-std::numbers::pi, std::numbers::pi);
  for (int i = 0; i < 5000; ++i) {
    const Eigen::Vector2d o(ux(rng), uy(rng));
    const double a = ua(rng);
    const double expected = rectExit(o, a, 0.1, 0.1, 9.9, 7.9);
    const double got = rc.cast(o, a, 30);
    INFO("origin (" << o.x() << ", " << o.y() << ") angle " << a);
    REQUIRE(got == Approx(expected).margin(1e-9));
  }
}

TEST_CASE("RayCaster: never skips a one-cell wall", "[sim][raycaster]") {
  // A vertical wall one cell thick at column 60 (x in [3.0, 3.05)) across the whole map.
  World w(100, 100, 0.05);
  for (int r = 0; r < 100; ++r) w.setWall(60, r, true);
  const RayCaster rc(w);
  const Eigen::Vector2d o(1.0, 2.5);
  for (int i = -80; i <= 80; ++i) {
    const double a = i * std::numbers::pi / 180.0;  // -80 deg .. 80 deg, steep ones graze the wall
    const double expected = (3.0 - o.x()) / std::cos(a);
    const double y_hit = o.y() + expected * std::sin(a);
    const double got = rc.cast(o, a, 100);
    if (y_hit >= 0 && y_hit < 5.0)
      CHECK(got == Approx(expected).margin(1e-9));
    else
      CHECK(std::isinf(got));  // leaves the map above or below the wall
  }
}

TEST_CASE("RayCaster: range limit, open space, start in a wall or outside", "[sim][raycaster]") {
  const World box = World::box(10.0, 8.0, 0.1);
  const RayCaster rc(box);
  CHECK(std::isinf(rc.cast({5.0, 4.0}, 0.0, 4.8)));  // wall at 4.9 m
  CHECK(rc.cast({5.0, 4.0}, 0.0, 4.95) == Approx(4.9));
  CHECK(rc.cast({0.05, 4.0}, 0.0, 30) == 0.0);  // starts inside the wall

  const World open(50, 50, 0.1);
  const RayCaster open_rc(open);
  CHECK(std::isinf(open_rc.cast({2.5, 2.5}, 0.3, 100)));

  // From outside the map, a ray that enters it finds the far wall; one that misses finds nothing.
  CHECK(rc.cast({-2.0, 4.0}, 0.0, 30) == Approx(2.0).margin(1e-9));  // enters the left wall
  CHECK(std::isinf(rc.cast({-2.0, 4.0}, std::numbers::pi, 30)));
  CHECK(std::isinf(rc.cast({-2.0, 4.0}, 0.0, 1.5)));
}

TEST_CASE("LaserConfig: field of view and validation", "[sim][laser]") {
  const LaserConfig c;  // 180 deg, 181 beams
  CHECK(c.beams == 181);
  CHECK(c.angleMin() == -std::numbers::pi / 2);
  CHECK(c.angleIncrement() == Approx(std::numbers::pi / 180));
  LaserConfig full;
  full.fov = 2 * std::numbers::pi;
  full.beams = 360;
  CHECK(full.angleMin() == -std::numbers::pi);
  CHECK(full.angleIncrement() ==
        Approx(std::numbers::pi / 180));  // last beam does not repeat the first
  LaserConfig one;
  one.beams = 1;
  CHECK(one.angleMin() == 0);
  CHECK(one.angleIncrement() > 0);

  auto bad = [](auto change) {
    LaserConfig cfg;
    change(cfg);
    return cfg;
  };
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.dropout = 1.5; }).validate(), std::invalid_argument);
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.range_noise = -0.1; }).validate(),
                  std::invalid_argument);
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.range_max = 0.01; }).validate(),
                  std::invalid_argument);
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.fov = 0; }).validate(), std::invalid_argument);
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.fov = 7; }).validate(), std::invalid_argument);
  CHECK_THROWS_AS(bad([](LaserConfig& k) { k.beams = 0; }).validate(), std::invalid_argument);
  CHECK_THROWS_WITH(bad([](LaserConfig& k) { k.range_max = 0.01; }).validate(),
                    Catch::Contains("laser: range_max must be finite"));
  CHECK(bad([](LaserConfig& k) { k.dropout = -1; }).check().problem()->key == "dropout");
  LaserConfig{}.validate();  // defaults are valid
}

TEST_CASE("LaserModel: noiseless scan equals ray casts from the laser pose", "[sim][laser]") {
  const World box = World::box(10.0, 8.0, 0.1);
  LaserConfig cfg;
  cfg.range_noise = 0;
  cfg.mount = {0.3, -0.1, 0.2};
  const LaserModel laser(box, cfg);
  const Pose2 base{4.0, 3.0, 0.7};
  const Pose2 lp = laser.laserPose(base);
  CHECK(lp.x == Approx(4.0 + 0.3 * std::cos(0.7) + 0.1 * std::sin(0.7)));
  CHECK(lp.y == Approx(3.0 + 0.3 * std::sin(0.7) - 0.1 * std::cos(0.7)));
  CHECK(lp.theta == Approx(0.9));

  std::mt19937_64 rng(1);
  const auto ranges = laser.scan(base, rng);
  REQUIRE(ranges.size() == 181);
  for (int i = 0; i < 181; ++i) {
    const double a = lp.theta - std::numbers::pi / 2 + i * std::numbers::pi / 180;
    CHECK(ranges[i] == Approx(rectExit(lp.translation(), a, 0.1, 0.1, 9.9, 7.9)).epsilon(1e-6));
  }
}

TEST_CASE("LaserModel: range noise, range limits and dropouts", "[sim][laser]") {
  const World box = World::box(10.0, 8.0, 0.1);
  const Pose2 centre{5.0, 4.0, 0.0};

  SECTION("Gaussian range noise has the configured std and no bias") {
    LaserConfig cfg;
    cfg.range_noise = 0.01;
    const LaserModel laser(box, cfg);
    std::mt19937_64 rng(3);
    const RayCaster rc(box);
    double sum = 0, sum2 = 0;
    int n = 0;
    for (int k = 0; k < 200; ++k) {
      const auto r = laser.scan(centre, rng);
      for (int i = 0; i < cfg.beams; ++i) {
        const double e =
            r[i] - rc.cast(centre.translation(), cfg.angleMin() + i * cfg.angleIncrement(), 30);
        sum += e;
        sum2 += e * e;
        ++n;
      }
    }
    const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
    CHECK(std::abs(mean) < 3e-4);
    CHECK(sd == Approx(0.01).epsilon(0.03));
  }

  SECTION("walls beyond range_max give +inf") {
    LaserConfig cfg;
    cfg.range_max = 4.0;  // side walls 3.9 m away, end walls 4.9 m
    cfg.range_noise = 0;
    const LaserModel laser(box, cfg);
    std::mt19937_64 rng(3);
    const auto r = laser.scan(centre, rng);
    CHECK(std::isinf(r[90]));       // straight ahead: 4.9 m
    CHECK(r[0] == Approx(3.9f));    // right: -90 deg
    CHECK(r[180] == Approx(3.9f));  // left: +90 deg
  }

  SECTION("readings closer than range_min are invalid (NaN)") {
    LaserConfig cfg;
    cfg.range_min = 0.5;
    cfg.range_noise = 0;
    const LaserModel laser(box, cfg);
    std::mt19937_64 rng(3);
    const auto r = laser.scan({0.4, 4.0, std::numbers::pi}, rng);  // facing the wall 0.3 m away
    CHECK(std::isnan(r[90]));
    CHECK(r[0] == Approx(3.9f));
  }

  SECTION("dropout probability") {
    LaserConfig cfg;
    cfg.dropout = 1.0;
    std::mt19937_64 rng(5);
    for (float v : LaserModel(box, cfg).scan(centre, rng)) CHECK(std::isinf(v));
    cfg.dropout = 0.3;
    const LaserModel laser(box, cfg);
    int dropped = 0, total = 0;
    for (int k = 0; k < 100; ++k)
      for (float v : laser.scan(centre, rng)) {
        dropped += std::isinf(v);
        ++total;
      }
    CHECK(static_cast<double>(dropped) / total == Approx(0.3).margin(0.02));
  }

  SECTION("same seed, same scan") {
    const LaserModel laser(box, LaserConfig{});
    std::mt19937_64 a(11), b(11);
    CHECK(laser.scan(centre, a) == laser.scan(centre, b));
  }

  SECTION("output size must match the beam count") {
    const LaserModel laser(box, LaserConfig{});
    std::mt19937_64 rng(1);
    std::vector<float> out(10);
    CHECK_THROWS_AS(laser.scan(centre, rng, out), std::invalid_argument);
  }
}
