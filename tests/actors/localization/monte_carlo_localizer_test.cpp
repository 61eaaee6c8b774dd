// Tests for Monte Carlo localisation: the KLD bound, tracking, global localisation, the kidnapped
// robot, bad input.
#include <tessera/localization/monte_carlo_localizer.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <memory>
#include <numbers>
#include <random>

#include "toy_room.hpp"

using namespace tessera;
using namespace tessera::localization;

namespace {

using test::toyRoom;
using test::toyRoute;
using test::toyScan;

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
    mcl.update(odom, toyScan(m, truth[i], 180, 8.0, rng));
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

/// From a known start, the toy route's first 4 m, then the robot is carried 6 m along it without
/// the odometry seeing it (step 40), and drives on. `relocalisations` gets the filter's count.
Run kidnappedRun(const MonteCarloOptions& o, int* relocalisations = nullptr) {
  const auto truth = toyRoute();
  MonteCarloLocalizer mcl(toyRoom(), 8.0, o);
  mcl.initialise(truth.front(),
                 Eigen::Vector3d(0.05 * 0.05, 0.05 * 0.05, 0.02 * 0.02).asDiagonal());
  std::vector<Pose2> route(truth.begin(), truth.begin() + 40);
  route.insert(route.end(), truth.begin() + 100, truth.end());
  const Run run = drive(mcl, route, 0, 40);
  if (relocalisations) *relocalisations = mcl.relocalisations();
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
  const grid::OccupancyMap m = toyRoom();
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
  const grid::OccupancyMap m = toyRoom();
  const auto truth = toyRoute();
  MonteCarloLocalizer mcl(m, 8.0);
  mcl.initialise(truth.front(), Eigen::Vector3d(0.1 * 0.1, 0.1 * 0.1, 0.05 * 0.05).asDiagonal());
  const Run run = drive(mcl, truth);
  INFO("mean error " << run.mean_error << " m");
  CHECK(run.mean_error < 0.03);  // 0.014 m when written
  CHECK(run.converged_at == 0);
  CHECK(mcl.updates() > 50);
}

TEST_CASE("global localisation converges from a uniform start", "[localization]") {
  const grid::OccupancyMap m = toyRoom();
  const auto truth = toyRoute();
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
  MonteCarloOptions o;
  o.max_particles = 5000;
  const Run run = kidnappedRun(o);
  INFO("recovered after " << run.converged_at << " steps; final error " << run.final_error);
  REQUIRE(run.converged_at >= 0);
  CHECK(run.converged_at - 40 < 100);  // found within 10 m of travel (5.7 m when written)
  CHECK(run.final_error < 0.3);
}

TEST_CASE("a kidnapped robot is found lost and relocalised without random particles",
          "[localization]") {
  const grid::OccupancyMap m = toyRoom();
  MonteCarloOptions o;
  o.recovery_alpha_slow = o.recovery_alpha_fast = 0;  // no augmented MCL: only the re-spread
  o.lost_inlier_fraction = 0.5;
  o.global_particles = 5000;
  o.min_ess = 0.3;
  SECTION("tracking alone never counts as lost") {
    const auto truth = toyRoute();
    MonteCarloLocalizer mcl(m, 8.0, o);
    mcl.initialise(truth.front(), Eigen::Vector3d(0.0025, 0.0025, 0.0004).asDiagonal());
    const Run run = drive(mcl, truth);
    CHECK(run.converged_at == 0);
    CHECK(mcl.relocalisations() == 0);
    CHECK(mcl.inlierFraction() > 0.8);
  }
  SECTION("carried 6 m off, it is found again") {
    int relocalisations = 0;
    const Run run = kidnappedRun(o, &relocalisations);
    INFO("recovered after " << run.converged_at << " steps; final error " << run.final_error);
    CHECK(relocalisations >= 1);
    REQUIRE(run.converged_at >= 0);
    CHECK(run.converged_at - 40 < 100);
    CHECK(run.final_error < 0.3);
  }
  SECTION("without the re-spread the same kidnapping is never recovered") {
    MonteCarloOptions off = o;
    off.lost_inlier_fraction = 0;
    int relocalisations = -1;
    const Run run = kidnappedRun(off, &relocalisations);
    CHECK(relocalisations == 0);
    CHECK(run.final_error > 0.3);
  }
  MonteCarloOptions bad = o;
  bad.lost_inlier_fraction = 1.5;
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, bad), Catch::Contains("lost_inlier_fraction"));
  bad = o;
  bad.lost_updates = 0;
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, bad), Catch::Contains("lost_updates"));
  bad = o;
  bad.inlier_distance = std::nan("");
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, bad), Catch::Contains("inlier_distance"));
}

TEST_CASE("bad input never corrupts the filter", "[localization]") {
  const grid::OccupancyMap m = toyRoom();
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

TEST_CASE("a new map keeps the particles; a bad one changes nothing", "[localization]") {
  const grid::OccupancyMap m = toyRoom();
  const auto truth = toyRoute();
  MonteCarloLocalizer mcl(m, 8.0);
  mcl.initialise(truth.front(), Eigen::Vector3d(0.01, 0.01, 0.0025).asDiagonal());
  drive(mcl, std::vector<Pose2>(truth.begin(), truth.begin() + 30));
  const Pose2 before = mcl.estimate().pose;
  const std::size_t particles = mcl.particles().size();

  CHECK_THROWS_WITH(mcl.setMap(grid::OccupancyMap{}), Catch::Contains("empty"));
  CHECK(mcl.field().map().width == m.width);

  // The same room, grown by 1 m on the left and bottom (as a SLAM map grows): same frame.
  grid::OccupancyMap grown;
  grown.resolution = m.resolution;
  grown.width = m.width + 20;
  grown.height = m.height + 20;
  grown.origin = Pose2(-1.0, -1.0, 0.0);
  grown.cells.assign(static_cast<std::size_t>(grown.width * grown.height),
                     grid::OccupancyMap::kUnknown);
  for (int r = 0; r < m.height; ++r)
    for (int c = 0; c < m.width; ++c) grown.at(c + 20, r + 20) = m.at(c, r);
  mcl.setMap(grown);
  CHECK(mcl.field().map().width == grown.width);
  CHECK(mcl.particles().size() == particles);
  CHECK(mcl.estimate().pose.x == Approx(before.x));
  CHECK(mcl.field().distance(Eigen::Vector2d(4.05, 2.0)) < 0.05);  // the inner wall, same place
  // Weighing goes on in the grown map: scans seen from the estimate keep it there.
  std::mt19937_64 rng(3);
  for (int k = 0; k < 5; ++k)
    REQUIRE(mcl.update(mcl.estimate().odom, toyScan(grown, before, 180, 8.0, rng), true));
  const Pose2 after = mcl.estimate().pose;
  CHECK(std::hypot(after.x - before.x, after.y - before.y) < 0.05);
}

TEST_CASE("endpoints on the faces of a corridor fit best at the true pose to the millimetre",
          "[localization]") {
  // A corridor between walls filling x < 1 m and x >= 3 m (5 cm cells); the robot in the middle
  // sees both faces. Faces lie on cell boundaries, where a beam ends: a centre-to-centre field
  // scores every pose up to a cell off alike, the interpolated face distance only the true one.
  grid::OccupancyMap m;
  m.resolution = 0.05;
  m.width = 100;
  m.height = 80;
  m.cells.assign(static_cast<std::size_t>(m.width * m.height), 0);
  for (int r = 0; r < m.height; ++r)
    for (int c = 0; c < m.width; ++c)
      if (c < 20 || c >= 60) m.at(c, r) = 100;
  LikelihoodFieldOptions sharp;
  sharp.penalise_inside = GENERATE(false, true);
  const LikelihoodField field(m, 8.0, sharp);
  std::vector<Eigen::Vector2d> points;
  for (double a = -0.6; a <= 0.6; a += 0.05) {
    points.emplace_back(1.0, std::tan(a));   // right face, x = 3
    points.emplace_back(-1.0, std::tan(a));  // left face, x = 1
  }
  const Pose2 truth(2.0, 2.0, 0.0);
  const double at_truth = field.logLikelihood(truth, points);
  for (double shift : {-0.04, -0.02, -0.01, -0.003, 0.003, 0.01, 0.02, 0.04}) {
    INFO("shifted by " << shift << " m");
    CHECK(at_truth > field.logLikelihood(Pose2(2.0 + shift, 2.0, 0.0), points));
  }
  // Along the corridor the fit is flat: no pull that way.
  CHECK(field.logLikelihood(Pose2(2.0, 2.03, 0.0), points) == Approx(at_truth).epsilon(1e-6));
}

TEST_CASE("on a sharp map, endpoints pushed into the walls ahead cost as much as short ones",
          "[localization]") {
  // A wall filling x >= 3 m; the robot at x = 1 sees only its face (a forward-looking laser).
  grid::OccupancyMap m;
  m.resolution = 0.05;
  m.width = 100;
  m.height = 80;
  m.cells.assign(static_cast<std::size_t>(m.width * m.height), 0);
  for (int r = 0; r < m.height; ++r)
    for (int c = 60; c < m.width; ++c) m.at(c, r) = 100;
  std::vector<Eigen::Vector2d> points;
  for (double a = -0.6; a <= 0.6; a += 0.05) points.emplace_back(2.0, 2.0 * std::tan(a));
  LikelihoodFieldOptions o;
  o.penalise_inside = true;
  const LikelihoodField sharp(m, 8.0, o);
  const double truth = sharp.logLikelihood(Pose2(1.0, 2.0, 0.0), points);
  CHECK(truth > sharp.logLikelihood(Pose2(1.05, 2.0, 0.0), points));
  CHECK(sharp.logLikelihood(Pose2(1.05, 2.0, 0.0), points) ==
        Approx(sharp.logLikelihood(Pose2(0.95, 2.0, 0.0), points)).epsilon(1e-4));
  // Without the penalty, inside the wall is as good as on its face: the pull the option removes.
  const LikelihoodField blurred(m, 8.0, {});
  CHECK(blurred.logLikelihood(Pose2(1.05, 2.0, 0.0), points) ==
        Approx(blurred.logLikelihood(Pose2(1.0, 2.0, 0.0), points)));
}

TEST_CASE("a tempered global start keeps its spread set until it converges, then tracks plainly",
          "[localization]") {
  const grid::OccupancyMap m = toyRoom();
  const auto truth = toyRoute();
  std::mt19937_64 rng(3);
  MonteCarloOptions o;
  o.max_particles = 1000;
  o.global_particles = 8000;
  auto firstUpdateSize = [&](double min_ess) {
    o.min_ess = min_ess;
    MonteCarloLocalizer mcl(m, 8.0, o);
    mcl.initialiseGlobal();
    REQUIRE(mcl.particles().size() == 8000);
    mcl.update(Pose2(), toyScan(m, truth[0], 180, 8.0, rng), /*force=*/true);
    return mcl.particles().size();
  };
  // Plain Bayes cuts the uniform set to max_particles at the first resampling; tempered, the
  // set keeps its size while it is spread.
  CHECK(firstUpdateSize(0.0) <= 1000);
  CHECK(firstUpdateSize(0.3) > 1000);
  o.min_ess = 0.3;
  MonteCarloLocalizer mcl(m, 8.0, o);
  mcl.initialiseGlobal();
  const Run run = drive(mcl, truth);
  INFO("converged after " << run.converged_at << " steps of 0.1 m; final error "
                          << run.final_error);
  REQUIRE(run.converged_at >= 0);
  CHECK(run.converged_at * 0.1 < 5.0);
  CHECK(mcl.particles().size() <= 1000);  // shrunk by the KLD bound once converged
  CHECK(run.final_error < 0.1);
}

TEST_CASE("the scan-matched refinement pins a slipped estimate to the walls", "[localization]") {
  // The particles start 0.12 m and 0.03 rad off the truth with a spread (σ 0.02 m) that does
  // not cover it, as after a slip the motion noise missed: one update leaves the plain filter
  // about as far off, the refined one within two centimetres (position plus heading error, the
  // scan's noise), its particles moved along.
  const grid::OccupancyMap m = toyRoom();
  const Pose2 truth(2.0, 1.5, 0.3);
  std::mt19937_64 rng(3);
  const auto scan = toyScan(m, truth, 180, 8.0, rng);
  const Eigen::Matrix3d tight =
      Eigen::Vector3d(0.02 * 0.02, 0.02 * 0.02, 0.005 * 0.005).asDiagonal();
  const auto afterOneUpdate = [&](double refine_step) {
    MonteCarloOptions o;
    o.refine_step = refine_step;
    auto mcl = std::make_unique<MonteCarloLocalizer>(m, 8.0, o);
    mcl->initialise(Pose2(truth.x + 0.1, truth.y - 0.066, truth.theta + 0.03), tight);
    REQUIRE(mcl->update(Pose2(), scan, true));
    return mcl;
  };
  const auto error = [&](const MonteCarloLocalizer& mcl) {
    const Pose2 e = mcl.estimate().pose;
    return std::hypot(e.x - truth.x, e.y - truth.y) + std::abs(angleDiff(e.theta, truth.theta));
  };
  const auto plain = afterOneUpdate(0);
  const auto refined = afterOneUpdate(0.05);
  INFO("plain " << error(*plain) << ", refined " << error(*refined));
  CHECK(error(*plain) > 0.05);
  CHECK(error(*refined) < 0.02);  // 0.0104 when written
  CHECK(plain->refinements() == 0);
  CHECK(refined->refinements() == 1);
  CHECK(refined->lastRefinementShift() > 0.05);
  double mx = 0, my = 0;
  const double n = static_cast<double>(refined->particles().size());
  for (const Particle& p : refined->particles()) {
    mx += p.pose.x / n;
    my += p.pose.y / n;
  }
  CHECK(std::hypot(mx - truth.x, my - truth.y) < 0.02);  // the cloud followed its mean
}

TEST_CASE("a refinement further than refine_max_shift is refused", "[localization]") {
  const grid::OccupancyMap m = toyRoom();
  const Pose2 truth(2.0, 1.5, 0.3);
  std::mt19937_64 rng(3);
  const auto scan = toyScan(m, truth, 180, 8.0, rng);
  MonteCarloOptions o;
  o.refine_step = 0.05;
  o.refine_max_shift = 0.02;
  MonteCarloLocalizer mcl(m, 8.0, o);
  const Pose2 start(truth.x + 0.1, truth.y - 0.066, truth.theta + 0.03);
  mcl.initialise(start, Eigen::Vector3d(1e-6, 1e-6, 1e-8).asDiagonal());
  REQUIRE(mcl.update(Pose2(), scan, true));
  CHECK(mcl.refinements() == 0);
  CHECK(mcl.refinementsRefused() == 1);
  CHECK(std::hypot(mcl.estimate().pose.x - start.x, mcl.estimate().pose.y - start.y) < 0.01);
  o.refine_step = -0.1;
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, o), Catch::Contains("refine_step"));
  o.refine_step = 0.05;
  o.refine_max_shift = std::nan("");
  CHECK_THROWS_WITH(MonteCarloLocalizer(m, 8.0, o), Catch::Contains("refine_max_shift"));
}
