// Tests for Monte Carlo localisation: the KLD bound, tracking, global localisation, the kidnapped
// robot, bad input.
#include <tessera/localization/monte_carlo_localizer.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>

using namespace tessera;
using namespace tessera::localization;

namespace {

/// A 12 x 9 m room (5 cm cells) with an asymmetric set of inner walls and boxes.
grid::OccupancyMap room() {
  grid::OccupancyMap m;
  m.resolution = 0.05;
  m.width = 240;
  m.height = 180;
  m.cells.assign(static_cast<std::size_t>(m.width * m.height), 0);
  auto box = [&](double x0, double y0, double x1, double y1) {
    for (int r = 0; r < m.height; ++r)
      for (int c = 0; c < m.width; ++c) {
        const Eigen::Vector2d p = m.cellCenter(c, r);
        if (p.x() >= x0 && p.x() <= x1 && p.y() >= y0 && p.y() <= y1) m.at(c, r) = 100;
      }
  };
  box(0, 0, 12, 0.1);
  box(0, 8.9, 12, 9);
  box(0, 0, 0.1, 9);
  box(11.9, 0, 12, 9);
  box(4, 0, 4.1, 5);  // a wall from the bottom
  box(8, 4, 8.1, 9);  // a wall from the top
  box(1.5, 6.5, 2.5, 7.2);
  box(9.5, 1.0, 10.0, 2.5);
  box(5.5, 7.0, 6.0, 7.5);
  return m;
}

/// Endpoints (robot frame) of `beams` rays over 360° from pose, by marching the map.
std::vector<Eigen::Vector2d> scan(const grid::OccupancyMap& m, const Pose2& pose, int beams,
                                  double range_max, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, 0.02);
  std::vector<Eigen::Vector2d> out;
  for (int b = 0; b < beams; ++b) {
    const double a = -std::numbers::pi + 2 * std::numbers::pi * b / beams;
    const Eigen::Vector2d dir(std::cos(pose.theta + a), std::sin(pose.theta + a));
    for (double r = 0.05; r < range_max; r += 0.02) {
      const Eigen::Vector2i c = m.cellOf(Eigen::Vector2d(pose.x, pose.y) + r * dir);
      if (!m.contains(c.x(), c.y())) break;
      if (m.at(c.x(), c.y()) >= 65) {
        const double range = r + noise(rng);
        out.emplace_back(range * std::cos(a), range * std::sin(a));
        break;
      }
    }
  }
  return out;
}

/// A loop through the room's three bays, as poses every 10 cm.
std::vector<Pose2> route() {
  const std::vector<Eigen::Vector2d> corners = {{2, 2},   {2, 5.5},  {3.2, 8.0},  {6.5, 8.2},
                                                {6.5, 2}, {10.8, 3}, {10.8, 7.5}, {9, 8.2}};
  std::vector<Pose2> out;
  for (std::size_t i = 0; i + 1 < corners.size(); ++i) {
    const Eigen::Vector2d a = corners[i], b = corners[i + 1];
    const double heading = std::atan2(b.y() - a.y(), b.x() - a.x());
    const int n = static_cast<int>((b - a).norm() / 0.1);
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector2d p = a + (b - a) * (double(k) / n);
      out.emplace_back(p.x(), p.y(), heading);
    }
  }
  return out;
}

struct Run {
  double mean_error = 0;
  double final_error = 0;
  int converged_at = -1;  ///< first step from which every estimate is within 0.3 m
};

/// Drives `truth`, feeding odometry with drift and noisy scans. At `kidnap_at` the robot is
/// carried off: the odometry does not see that step.
Run drive(MonteCarloLocalizer& mcl, const std::vector<Pose2>& truth, int first = 0,
          int kidnap_at = -1, std::uint64_t seed = 1) {
  const grid::OccupancyMap& m = mcl.field().map();
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  Pose2 odom(0.5, -0.3, 0.2);  // odometry frame differs from the map frame
  Run run;
  double sum = 0;
  int counted = 0;
  for (std::size_t i = static_cast<std::size_t>(first); i < truth.size(); ++i) {
    if (i > static_cast<std::size_t>(first) && static_cast<int>(i) != kidnap_at) {
      const Pose2 d = between(truth[i - 1], truth[i]);
      // 5 % translation noise, 2 % + 0.01 rad rotation noise per step.
      odom = odom * Pose2(d.x * (1 + 0.05 * n01(rng)), d.y * (1 + 0.05 * n01(rng)),
                          d.theta * (1 + 0.02 * n01(rng)) + 0.01 * n01(rng));
    }
    mcl.update(odom, scan(m, truth[i], 180, 8.0, rng));
    const PoseEstimate e = mcl.estimate();
    const Pose2 now = e.pose * between(e.odom, odom);  // the last update moved by odometry since
    const double err = std::hypot(now.x - truth[i].x, now.y - truth[i].y);
    if (err > 0.3)
      run.converged_at = -1;
    else if (run.converged_at < 0)
      run.converged_at = static_cast<int>(i) - first;
    sum += err;
    ++counted;
    run.final_error = err;
  }
  run.mean_error = sum / counted;
  return run;
}

}  // namespace

TEST_CASE("the KLD sample count follows the chi-square bound", "[localization]") {
  CHECK(kldSampleCount(1, 0.01, 2.326) == 1);
  // n = chi2_{k-1, 0.99} / (2 eps): chi2_{1,0.99} = 6.635, chi2_{99,0.99} = 134.642.
  CHECK(kldSampleCount(2, 0.01, 2.326) == Approx(6.635 / 0.02).epsilon(0.02));
  CHECK(kldSampleCount(100, 0.01, 2.326) == Approx(134.642 / 0.02).epsilon(0.002));
  CHECK(kldSampleCount(100, 0.05, 2.326) < kldSampleCount(100, 0.01, 2.326));
}

TEST_CASE("a concentrated particle set shrinks to min_particles, a spread one grows",
          "[localization]") {
  const grid::OccupancyMap m = room();
  MonteCarloOptions o;
  o.min_particles = 100;
  o.max_particles = 3000;
  MonteCarloLocalizer tight(m, 8.0, o), wide(m, 8.0, o);
  tight.initialise(Pose2(2.2, 2.2, 0.05), Eigen::Vector3d(1e-6, 1e-6, 1e-8).asDiagonal());
  wide.initialiseGlobal();
  const std::vector<Eigen::Vector2d> none;
  tight.update(Pose2(), none, true);
  tight.update(Pose2(), std::vector<Eigen::Vector2d>{{1.0, 0.0}}, true);
  wide.update(Pose2(), std::vector<Eigen::Vector2d>{{1.0, 0.0}}, true);
  CHECK(tight.particles().size() == 100);
  CHECK(wide.particles().size() > 1000);
}

TEST_CASE("tracking from a known start stays within a few centimetres", "[localization]") {
  const grid::OccupancyMap m = room();
  const auto truth = route();
  MonteCarloLocalizer mcl(m, 8.0);
  mcl.initialise(truth.front(), Eigen::Vector3d(0.1 * 0.1, 0.1 * 0.1, 0.05 * 0.05).asDiagonal());
  const Run run = drive(mcl, truth);
  INFO("mean error " << run.mean_error << " m");
  CHECK(run.mean_error < 0.03);  // 0.014 m when written
  CHECK(run.converged_at == 0);
  CHECK(mcl.updates() > 50);
}

TEST_CASE("global localisation converges from a uniform start", "[localization]") {
  const grid::OccupancyMap m = room();
  const auto truth = route();
  MonteCarloOptions o;
  o.max_particles = 5000;
  MonteCarloLocalizer mcl(m, 8.0, o);
  mcl.initialiseGlobal();
  const Run run = drive(mcl, truth);
  INFO("converged after " << run.converged_at << " steps of 0.1 m; final error "
                          << run.final_error);
  REQUIRE(run.converged_at >= 0);
  CHECK(run.converged_at * 0.1 < 5.0);  // within 5 m of travel
}

TEST_CASE("a kidnapped robot is found again through random particles", "[localization]") {
  const grid::OccupancyMap m = room();
  auto truth = route();
  MonteCarloOptions o;
  o.max_particles = 5000;
  MonteCarloLocalizer mcl(m, 8.0, o);
  mcl.initialise(truth.front(),
                 Eigen::Vector3d(0.05 * 0.05, 0.05 * 0.05, 0.02 * 0.02).asDiagonal());
  // Tracks the first 4 m, then is carried 6 m along the route without odometry seeing it.
  std::vector<Pose2> kidnapped(truth.begin(), truth.begin() + 40);
  kidnapped.insert(kidnapped.end(), truth.begin() + 100, truth.end());
  const Run run = drive(mcl, kidnapped, 0, 40);
  INFO("recovered after " << run.converged_at << " steps; final error " << run.final_error);
  REQUIRE(run.converged_at >= 0);
  CHECK(run.converged_at - 40 < 100);  // found within 10 m of travel (5.7 m when written)
  CHECK(run.final_error < 0.3);
}

TEST_CASE("bad input never corrupts the filter", "[localization]") {
  const grid::OccupancyMap m = room();
  MonteCarloLocalizer mcl(m, 8.0);
  CHECK_FALSE(mcl.update(Pose2(), {}, true));  // not initialised
  mcl.initialise(Pose2(2, 2, 0), Eigen::Matrix3d::Identity() * 0.01);
  const double nan = std::nan("");
  CHECK_FALSE(mcl.update(Pose2(nan, 0, 0), {}, true));
  const std::vector<Eigen::Vector2d> bad = {{nan, 1.0}, {1.0, 0.0}};
  CHECK(mcl.update(Pose2(), bad, true));
  CHECK(mcl.estimate().pose.isFinite());
  CHECK_THROWS_WITH(mcl.initialise(Pose2(nan, 0, 0), Eigen::Matrix3d::Identity()),
                    Catch::Contains("not finite"));
  grid::OccupancyMap empty;
  CHECK_THROWS_WITH(MonteCarloLocalizer(empty, 8.0), Catch::Contains("empty"));
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, std::nan("")), Catch::Contains("range_max"));
  MonteCarloOptions o;
  o.max_particles = 10;
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, o), Catch::Contains("max_particles"));
  grid::OccupancyMap full = m;
  for (auto& c : full.cells) c = 100;
  MonteCarloLocalizer blocked(full, 8.0);
  CHECK_THROWS_WITH(blocked.initialiseGlobal(), Catch::Contains("no free cell"));
}
