// Tests for the RBPF core (actors/laser_slam/rbpf.hpp): resampling, tracking a simulated robot
// whose odometry drifts, copy-on-write map sharing, submap hand-over, and bad input.
#include <tessera/laser_slam/rbpf.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <numeric>
#include <vector>

#include "sim_scans.hpp"

using namespace tessera;
using laser_slam::Rbpf;
using laser_slam::RbpfOptions;
using tessera::Pose2;

namespace {

RbpfOptions fastOptions(int particles) {
  RbpfOptions o;
  // These tests were tuned on the grid's and the scan matcher's own defaults, which the filter's
  // differ from (RbpfOptions): a match needs 30 % of the beams (so the failure and recovery
  // tests fail matches), no extra cost for unmatched beams, the grid's stronger miss, and no
  // tracking between updates.
  o.grid.log_odds.miss = -0.4f;
  o.matcher.min_score_fraction = 0.3;
  o.matcher.no_hit_distance = 0.0;
  o.matcher.compute_covariance = true;
  o.track_between_updates = false;
  o.particles = particles;
  o.linear_update = 0.3;
  o.angular_update = 0.3;
  return o;
}

double translationError(const Pose2& a, const Pose2& b) {
  return std::hypot(a.x - b.x, a.y - b.y);
}

/// Keeps every 6th beam on the walls and ends the rest halfway, in space the map knows to be
/// free: 31 of 181 beams agree with the map, as when the robot enters unmapped space.
void weaken(test::SimScan& s) {
  for (std::size_t b = 0; b < s.ranges.size(); ++b)
    if (b % 6 != 0) s.ranges[b] *= 0.5f;
}

/// The room loop whose odometry slips while the robot turns on the spot (as when a wheel
/// spins): from the first such scan after the 30th on, odometry reports `slip` more motion,
/// in the robot frame, than the robot made.
test::SimScans roomLoopWithSlip(const Pose2& slip) {
  auto sim = test::simulateRoomLoop();
  std::size_t first = 0;
  for (std::size_t k = 30; k < sim.scans.size() && first == 0; ++k)
    if (sim.scans[k].truth.theta != sim.scans[k - 1].truth.theta &&
        sim.scans[k].truth.x == sim.scans[k - 1].truth.x)
      first = k;
  REQUIRE(first > 0);
  const Pose2 at = sim.scans[first - 1].odometry;
  for (std::size_t k = first; k < sim.scans.size(); ++k)
    sim.scans[k].odometry = at * slip * tessera::between(at, sim.scans[k].odometry);
  return sim;
}

/// Feeds the whole run; returns the largest error of the online pose against the truth.
double worstOnlineError(Rbpf& rbpf, const test::SimScans& sim) {
  const Pose2 start = sim.scans.front().truth;
  double worst = 0;
  for (const auto& s : sim.scans) {
    rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
    worst = std::max(worst, translationError(rbpf.pose(), tessera::between(start, s.truth)));
  }
  return worst;
}

}  // namespace

TEST_CASE("systematic resampling draws each particle in proportion to its weight", "[rbpf]") {
  const std::vector<double> w{0.05, 0.15, 0.3, 0.0, 0.5};
  for (double u0 : {0.0, 0.0042, 0.0099}) {  // in [0, 1/n)
    std::vector<double> weights(100);
    for (std::size_t i = 0; i < weights.size(); ++i) weights[i] = w[i % w.size()];
    const auto drawn = laser_slam::systematicResample(weights, u0);
    REQUIRE(drawn.size() == weights.size());
    std::vector<int> count(weights.size(), 0);
    for (std::size_t i : drawn) ++count[i];
    const double total = std::accumulate(weights.begin(), weights.end(), 0.0);
    for (std::size_t i = 0; i < weights.size(); ++i) {
      const double expected = weights.size() * weights[i] / total;
      INFO("u0 " << u0 << " particle " << i);
      CHECK(count[i] >= std::floor(expected) - 1e-9);
      CHECK(count[i] <= std::ceil(expected) + 1e-9);
    }
  }
  // A toy posterior: 1000 particles on a line, weights from a Gaussian likelihood. After
  // resampling, the particle mean and spread match the weighted ones.
  std::vector<double> x(1000), lw(1000);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> prior(0.0, 1.0);
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] = prior(rng);
    lw[i] = std::exp(-0.5 * (x[i] - 0.8) * (x[i] - 0.8) / 0.25);
  }
  double wsum = 0, wmean = 0;
  for (std::size_t i = 0; i < x.size(); ++i) wsum += lw[i], wmean += lw[i] * x[i];
  wmean /= wsum;
  double mean = 0;
  for (std::size_t i : laser_slam::systematicResample(lw, 0.0005)) mean += x[i];
  mean /= static_cast<double>(x.size());
  CHECK(mean == Approx(wmean).margin(0.03));  // ~2 sigma of the resampling noise
  CHECK(wmean == Approx(0.64).margin(0.1));   // the analytic posterior mean, 0.8·1/(1+0.25)
}

TEST_CASE("the best particle is the best-supported hypothesis, not the single heaviest", "[rbpf]") {
  // Hypothesis A: three particles within a few cm; hypothesis B: one particle 0.8 m away that
  // alone outweighs each of A's (0.34 against 0.22) but not all three together.
  const std::vector<Pose2> poses{
      {0.8, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.03, 0.01, 0.01}, {-0.02, 0.02, -0.01}};
  const std::vector<double> weights{0.34, 0.22, 0.22, 0.22};
  const std::vector<double> scores{-1.0, -3.0, -2.0, -4.0};
  const std::size_t best = laser_slam::selectBestParticle(poses, weights, scores, 0.1, 0.05);
  CHECK(best != 0);
  CHECK(best <= 3);
  // Without the kernel, the highest accumulated log weight decides.
  CHECK(laser_slam::selectBestParticle(poses, weights, scores, 0.0, 0.05) == 0);
  // Copies left by resampling tie: the highest accumulated log weight among them, else the
  // first.
  const std::vector<Pose2> copies(3, Pose2{1.0, 2.0, 0.5});
  const std::vector<double> equal(3, 1.0 / 3.0);
  CHECK(laser_slam::selectBestParticle(copies, equal, std::vector<double>{-2, -1, -3}, 0.1, 0.05) ==
        1);
  CHECK(laser_slam::selectBestParticle(copies, equal, std::vector<double>(3, -1.0), 0.1, 0.05) ==
        0);
}

TEST_CASE("the online mean averages the chosen hypothesis and leaves the other out", "[rbpf]") {
  // Hypothesis A around the origin (three particles, headings either side of pi), B 0.8 m off.
  const double pi = std::numbers::pi;
  const std::vector<Pose2> poses{
      {0.8, 0.0, pi}, {0.0, 0.0, pi - 0.01}, {0.03, 0.0, -pi + 0.01}, {0.0, 0.03, pi}};
  const std::vector<double> weights{0.4, 0.2, 0.2, 0.2};
  const Pose2 mean = laser_slam::kernelMean(poses, weights, poses[1], 0.2, 0.1);
  // B's kernel weight is exp(-8) of A's: it moves the mean by well under a millimetre.
  CHECK(mean.x == Approx(0.01).margin(1e-3));
  CHECK(mean.y == Approx(0.01).margin(1e-3));
  // The headings average across the wrap to pi, not to 0.
  CHECK(std::abs(tessera::angleDiff(mean.theta, pi)) < 1e-3);
  // No kernel: the centre itself.
  const Pose2 same = laser_slam::kernelMean(poses, weights, poses[1], 0.0, 0.1);
  CHECK(same.x == poses[1].x);
  CHECK(same.theta == poses[1].theta);
}

TEST_CASE("with the online mean the filter reports the particles' mean at updates", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  RbpfOptions o = fastOptions(10);
  o.online_mean_linear = 0.2;
  o.online_mean_angular = 0.1;
  Rbpf rbpf(o);
  int updates = 0, moved = 0;
  for (const auto& s : sim.scans) {
    const laser_slam::RbpfStep step = rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
    if (!step.updated || rbpf.stats().updates < 2) continue;
    ++updates;
    const Pose2 expected = laser_slam::kernelMean(rbpf.particlePoses(), rbpf.weights(),
                                                  rbpf.poseWithCovariance().pose, 0.2, 0.1);
    CHECK(rbpf.pose().x == Approx(expected.x).margin(1e-12));
    CHECK(rbpf.pose().y == Approx(expected.y).margin(1e-12));
    CHECK(rbpf.pose().theta == Approx(expected.theta).margin(1e-12));
    moved += translationError(rbpf.pose(), rbpf.poseWithCovariance().pose) > 1e-6 ? 1 : 0;
  }
  REQUIRE(updates > 10);
  // Particles drawn from their proposals differ, so the mean is not the best particle's pose.
  CHECK(moved > updates / 2);
}

TEST_CASE("rbpf tracks a simulated robot whose odometry drifts", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  Rbpf rbpf(fastOptions(10));
  const Pose2 start = sim.scans.front().truth;
  double worst = 0, odom_final = 0;
  for (const auto& s : sim.scans) {
    rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
    const Pose2 truth = tessera::between(start, s.truth);
    worst = std::max(worst, translationError(rbpf.pose(), truth));
    odom_final = translationError(tessera::between(sim.scans.front().odometry, s.odometry), truth);
  }
  INFO("scans " << sim.scans.size() << ", updates " << rbpf.stats().updates << ", worst error "
                << worst << " m, odometry final error " << odom_final << " m");
  CHECK(odom_final > 0.5);  // the test is only meaningful when odometry alone is far off
  CHECK(worst < 0.12);
  CHECK(rbpf.stats().updates > 50);
  CHECK(rbpf.stats().match_failures < rbpf.stats().particle_updates / 10);
  const auto trajectory = rbpf.bestTrajectory();
  CHECK(trajectory.size() == rbpf.stats().updates);
}

TEST_CASE("a heading slip beyond the matcher basin is recovered from the odometry prior",
          "[rbpf]") {
  // A wheel spins while the robot turns on the spot: from one scan on, odometry reports 0.8 rad
  // more rotation than the robot made. The next update's prior is off by that much, beyond what
  // the coarse stage reaches from the prior mean but within the recovery search (the prior's
  // heading spread grows with the reported rotation).
  const auto sim = roomLoopWithSlip(Pose2(0, 0, 0.8));
  const auto run = [&](double recovery_sigma) {
    RbpfOptions o = fastOptions(5);
    o.recovery_sigma = recovery_sigma;
    Rbpf rbpf(o);
    const double worst = worstOnlineError(rbpf, sim);
    return std::make_pair(worst, rbpf.stats());
  };
  const auto [worst_off, stats_off] = run(0.0);
  const auto [worst_on, stats_on] = run(RbpfOptions{}.recovery_sigma);
  INFO("without recovery: worst " << worst_off << " m, " << stats_off.match_failures
                                  << " failures; with: worst " << worst_on << " m, "
                                  << stats_on.match_failures << " failures, "
                                  << stats_on.match_recoveries << " recoveries");
  // Without the search every particle fails and inserts its scan at a pose drawn from the
  // motion model, which corrupts its map.
  CHECK(stats_off.match_failures >= 5);
  CHECK(stats_off.match_recoveries == 0);
  CHECK(worst_off > 0.3);
  CHECK(stats_on.match_recoveries >= 5);
  CHECK(stats_on.match_failures < stats_off.match_failures);
  CHECK(worst_on < 0.12);
}

TEST_CASE("a weak match from the odometry prior still gets the recovery search", "[rbpf]") {
  // As at t = 911 s of the Intel log: odometry slips 0.5 rad and 0.18 m while the robot turns on
  // the spot. From the prior the coarse stage, with its wide kernel, still reports success, but
  // in a wrong place where the fine stage keeps under 20 % of the beams on the map: too few
  // to trust (min_overlap_fraction). When every particle's match is that weak, each must get
  // the wider search like a failed one; before, every particle fell back to the motion model
  // there and the filter diverged (worst error 1.67 m, no recovery).
  const auto sim = roomLoopWithSlip(Pose2(0.15, 0.1, 0.5));
  RbpfOptions o = fastOptions(5);
  o.min_overlap_fraction = 0.2;
  Rbpf rbpf(o);
  const double worst = worstOnlineError(rbpf, sim);
  INFO("worst " << worst << " m, " << rbpf.stats().match_failures << " failures, "
                << rbpf.stats().match_recoveries << " recoveries");
  CHECK(rbpf.stats().match_recoveries >= 5);
  CHECK(rbpf.stats().match_failures < 5);
  CHECK(worst < 0.12);
}

TEST_CASE("a match with too few beams on the map falls back to the motion model", "[rbpf]") {
  // After the map is built, one update's scan is weakened: its 31 beams on the map are enough
  // for the matcher's own 10 % floor, not for min_overlap_fraction 0.2.
  const auto sim = test::simulateRoomLoop();
  const auto run = [&](double min_overlap) {
    RbpfOptions o = fastOptions(5);
    o.min_overlap_fraction = min_overlap;
    Rbpf rbpf(o);
    std::uint64_t failures_in_weak_update = 0;
    bool weak_done = false;
    for (std::size_t k = 0; k < sim.scans.size(); ++k) {
      test::SimScan s = sim.scans[k];
      const bool weak = k >= 40 && !weak_done;
      if (weak) weaken(s);
      const std::uint64_t before = rbpf.stats().match_failures;
      const auto step = rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
      if (weak && step.updated) {
        failures_in_weak_update = rbpf.stats().match_failures - before;
        weak_done = true;
      }
    }
    REQUIRE(weak_done);
    return failures_in_weak_update;
  };
  CHECK(run(0.0) == 0);  // every particle trusts its 31-beam match
  CHECK(run(0.2) == 5);  // every particle follows the motion model instead
}

TEST_CASE("particles that fall back to the motion model are weighted at the pose they drew",
          "[rbpf]") {
  // The first update after the first scan, with the weak scan of the test above: every particle
  // falls back and draws from a wide motion model, and the 31 beams that see known walls must
  // decide between the draws. Weighted at the untrusted match instead, the heaviest draw would
  // be a random one.
  const auto sim = test::simulateRoomLoop();
  const Pose2 start = sim.scans.front().truth;
  int heaviest_was_closest = 0;
  const int runs = 8;
  for (int seed = 1; seed <= runs; ++seed) {
    RbpfOptions o = fastOptions(10);
    o.min_overlap_fraction = 0.2;
    o.motion = {0.5, 0.5, 0.5, 0.5};
    o.seed = static_cast<std::uint64_t>(seed);
    Rbpf rbpf(o);
    for (std::size_t k = 0; k < sim.scans.size(); ++k) {
      test::SimScan s = sim.scans[k];
      if (k > 0) weaken(s);
      const auto step = rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
      if (k == 0 || !step.updated) continue;
      REQUIRE(rbpf.stats().match_failures == 10);
      REQUIRE_FALSE(step.resampled);
      const Pose2 truth = tessera::between(start, s.truth);
      const auto error = [&](const Pose2& p) {
        return translationError(p, truth) +
               0.5 * std::abs(tessera::angleDiff(p.theta, truth.theta));
      };
      const auto poses = rbpf.particlePoses();
      const auto weights = rbpf.weights();
      std::size_t closest = 0, heaviest = 0;
      for (std::size_t i = 1; i < poses.size(); ++i) {
        if (error(poses[i]) < error(poses[closest])) closest = i;
        if (weights[i] > weights[heaviest]) heaviest = i;
      }
      heaviest_was_closest += heaviest == closest ? 1 : 0;
      break;
    }
  }
  // Chance alone would pick the closest of ten draws about once in ten runs.
  CHECK(heaviest_was_closest >= runs / 2);
}

TEST_CASE("tracking between updates keeps the online pose on the scans instead of odometry",
          "[rbpf]") {
  // Wide gates, as on a real log: between updates the online pose would follow odometry with
  // its 4 % rotation and 3 % distance errors.
  const auto sim = test::simulateRoomLoop();
  const auto run = [&](bool track) {
    RbpfOptions o = fastOptions(5);
    o.linear_update = 1.0;
    o.angular_update = 0.5;
    o.track_between_updates = track;
    Rbpf rbpf(o);
    const Pose2 start = sim.scans.front().truth;
    double sum = 0, heading = 0;
    for (const auto& s : sim.scans) {
      rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
      const Pose2 truth = tessera::between(start, s.truth);
      sum += translationError(rbpf.pose(), truth);
      heading += std::abs(tessera::angleDiff(rbpf.pose().theta, truth.theta));
    }
    const double n = static_cast<double>(sim.scans.size());
    return std::make_tuple(sum / n, heading / n, rbpf.stats());
  };
  const auto [odom_mean, odom_heading, odom_stats] = run(false);
  const auto [track_mean, track_heading, track_stats] = run(true);
  INFO("mean error on odometry between updates " << odom_mean << " m / " << odom_heading
                                                 << " rad, tracked " << track_mean << " m / "
                                                 << track_heading << " rad");
  CHECK(odom_stats.tracked_scans == 0);
  CHECK(track_stats.tracked_scans + track_stats.updates == sim.scans.size());
  // Scans whose match does not beat the odometry prediction keep it; the others move it.
  CHECK(track_stats.tracking_failures < track_stats.tracked_scans);
  // The filter itself is unchanged: same updates, same best trajectory.
  CHECK(track_stats.updates == odom_stats.updates);
  CHECK(track_stats.resamples == odom_stats.resamples);
  CHECK(track_heading < 0.8 * odom_heading);
  CHECK(track_mean < odom_mean);
}

TEST_CASE("tracking climbs from its own smaller steps with fewer evaluations", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  const auto run = [&](double linear, double angular, int refinements) {
    RbpfOptions o = fastOptions(5);
    o.linear_update = 1.0;
    o.angular_update = 0.5;
    o.track_between_updates = true;
    o.track_linear_step = linear;
    o.track_angular_step = angular;
    o.track_refinements = refinements;
    Rbpf rbpf(o);
    const Pose2 start = sim.scans.front().truth;
    double sum = 0;
    for (const auto& s : sim.scans) {
      rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
      sum += translationError(rbpf.pose(), tessera::between(start, s.truth));
    }
    return std::make_pair(sum / static_cast<double>(sim.scans.size()), rbpf.stats());
  };
  const auto [fine_mean, fine_stats] = run(0, 0, 0);  // the fine matcher's 5 cm, 5 halvings
  const auto [small_mean, small_stats] = run(0.025, 0.025, 3);
  INFO("tracking evaluations " << fine_stats.tracking_evaluations << " -> "
                               << small_stats.tracking_evaluations << ", mean error " << fine_mean
                               << " -> " << small_mean << " m");
  REQUIRE(fine_stats.tracked_scans > 50);
  // The filter is the same; only the between-update matches change.
  CHECK(small_stats.tracked_scans == fine_stats.tracked_scans);
  CHECK(small_stats.resamples == fine_stats.resamples);
  CHECK(small_stats.tracking_evaluations < 0.85 * fine_stats.tracking_evaluations);
  CHECK(small_mean < 1.1 * fine_mean);
}

TEST_CASE("particles copied by resampling share their map tiles", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  RbpfOptions o = fastOptions(20);
  o.sample_proposal = false;  // identical particles stay identical: nothing may be copied
  o.motion = {0, 0, 0, 0};
  Rbpf rbpf(o);
  const auto before = tessera::grid::TiledGrid::counters();
  rbpf.addScan(0.0, sim.range(sim.scans[0]), Pose2{}, sim.scans[0].odometry);
  const auto after_first = tessera::grid::TiledGrid::counters();
  CHECK(rbpf.distinctMaps() == 1);
  CHECK(after_first.tiles_cloned == before.tiles_cloned);
  const std::uint64_t tiles_one_map = after_first.tiles_allocated - before.tiles_allocated;
  CHECK(tiles_one_map == rbpf.bestMap().tileCount());
  for (std::size_t k = 1; k < 40; ++k)
    rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  REQUIRE(rbpf.stats().updates > 3);
  CHECK(rbpf.distinctMaps() == 1);
  CHECK(tessera::grid::TiledGrid::counters().tiles_cloned == before.tiles_cloned);
  // One map for all 20 particles: it is what they hold.
  CHECK(rbpf.mapBytes() == rbpf.bestMap().memoryBytes());

  // With sampling the particles diverge; each clones only the tiles its scans touch.
  RbpfOptions diverse = fastOptions(20);
  Rbpf rbpf2(diverse);
  const auto start = tessera::grid::TiledGrid::counters();
  for (std::size_t k = 0; k < 40; ++k)
    rbpf2.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  const auto end = tessera::grid::TiledGrid::counters();
  const std::uint64_t tiles =
      end.tiles_allocated + end.tiles_cloned - start.tiles_allocated - start.tiles_cloned;
  const std::uint64_t map_tiles = rbpf2.bestMap().tileCount();
  INFO("tiles created " << tiles << ", one map " << map_tiles << ", updates "
                        << rbpf2.stats().updates);
  CHECK(rbpf2.distinctMaps() > 1);
  // Deep copies at every update would create particles × updates × map tiles.
  CHECK(tiles < 20 * rbpf2.stats().updates * map_tiles / 2);
  // Diverged maps hold more than one map's tiles, and far less than one each: shared tiles
  // count once.
  const std::size_t one_map = rbpf2.bestMap().memoryBytes();
  CHECK(rbpf2.mapBytes() > one_map);
  CHECK(rbpf2.mapBytes() < static_cast<std::size_t>(rbpf2.distinctMaps()) * one_map);
  // The peak is sampled at least when a submap closes: the closing submap's maps are in it.
  const std::size_t held = rbpf2.mapBytes();
  rbpf2.startSubmap();
  CHECK(rbpf2.stats().map_bytes_peak >= held);
  CHECK(rbpf2.mapBytes() < held);  // the new submap starts from one map of the last metres
}

TEST_CASE("copies of one particle are matched once and still draw their own poses", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  // All particles start as copies of one: the first update matches them all from one pose.
  Rbpf one(fastOptions(1)), ten(fastOptions(10));
  std::size_t k = 0;
  for (; k < sim.scans.size() && ten.stats().updates < 2; ++k) {
    one.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
    ten.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  }
  REQUIRE(ten.stats().updates == 2);
  REQUIRE(one.stats().updates == 2);
  CHECK(ten.stats().particle_updates == 10);
  CHECK(ten.stats().fine_evaluations == one.stats().fine_evaluations);
  CHECK(ten.stats().coarse_evaluations == one.stats().coarse_evaluations);
  // Particle 0 draws from the same random stream in both filters, so lands on the same pose.
  const auto poses = ten.particlePoses();
  const Pose2 p0 = one.particlePoses()[0];
  CHECK(poses[0].x == p0.x);
  CHECK(poses[0].y == p0.y);
  CHECK(poses[0].theta == p0.theta);
  int distinct = 0;
  for (std::size_t i = 1; i < poses.size(); ++i) distinct += poses[i].x != poses[0].x;
  CHECK(distinct == 9);
}

TEST_CASE("a submap hand-over publishes the robot pose in the old submap", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  RbpfOptions o = fastOptions(8);
  o.carry_over_distance = 0;  // the new submap starts with the last scan only
  Rbpf rbpf(o);
  CHECK_THROWS_AS(rbpf.startSubmap(), std::logic_error);
  for (std::size_t k = 0; k < 60; ++k)
    rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  const Pose2 in_old = rbpf.pose();
  const std::uint64_t scans_in_old = rbpf.submapScans();
  const auto done = rbpf.startSubmap();
  CHECK(done.id == 0);
  CHECK(rbpf.submapId() == 1);
  CHECK(done.next_in_this.pose.x == Approx(in_old.x));
  CHECK(done.next_in_this.pose.y == Approx(in_old.y));
  CHECK(done.next_in_this.pose.theta == Approx(in_old.theta));
  CHECK(done.scans_inserted == scans_in_old);
  CHECK(done.grid.knownCount() > 1000);
  for (int i = 0; i < 3; ++i) CHECK(done.next_in_this.covariance(i, i) > 0);
  // The new submap starts at the robot with zero uncertainty and already holds the last scan.
  CHECK(rbpf.pose().x == 0.0);
  CHECK(rbpf.pose().theta == 0.0);
  CHECK(rbpf.poseWithCovariance().covariance.norm() == 0.0);
  CHECK(rbpf.submapScans() == 1);
  CHECK(rbpf.bestMap().knownCount() > 100);
  // Tracking continues in the new submap: chaining the constraint gives the true pose.
  const Pose2 start = sim.scans.front().truth;
  for (std::size_t k = 60; k < 120; ++k)
    rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  const Pose2 chained = done.next_in_this.pose * rbpf.pose();
  CHECK(translationError(chained, tessera::between(start, sim.scans[119].truth)) < 0.1);
}

TEST_CASE(
    "a new submap starts with the last metres' update scans, placed where the old one had them",
    "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  const auto runTo60 = [&](double carry) {
    RbpfOptions o = fastOptions(8);
    o.carry_over_distance = carry;
    auto rbpf = std::make_unique<Rbpf>(o);
    for (std::size_t k = 0; k < 60; ++k)
      rbpf->addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
    return rbpf;
  };
  auto last_only = runTo60(0.0);
  auto carried = runTo60(1.0);
  // Same filter up to the hand-over: the option only acts there.
  CHECK(carried->pose().x == last_only->pose().x);
  const auto done_last = last_only->startSubmap();
  const auto done = carried->startSubmap();
  CHECK(last_only->submapScans() == 1);
  // 1 m of path (updates every 0.3 m or 0.3 rad): more than the last scan, fewer than all of
  // the submap's, which a longer distance carries (each once: the last one is not doubled).
  auto all = runTo60(100.0);
  const auto done_all = all->startSubmap();
  CHECK(carried->submapScans() > 1);
  CHECK(carried->submapScans() < all->submapScans());
  CHECK(all->submapScans() == done_all.scans_inserted);
  CHECK(carried->bestMap().knownCount() > last_only->bestMap().knownCount());
  CHECK(done.scans_inserted == done_last.scans_inserted);
  // Every occupied cell of the new submap, moved into the old submap's frame, lies on an
  // occupied cell of the old one (within a cell): the carried scans are where the filter had
  // them.
  const tessera::grid::OccupancyMap now = carried->bestMap().toOccupancyMap();
  const tessera::grid::OccupancyMap old = done.grid.toOccupancyMap();
  int occupied = 0, agree = 0;
  for (int r = 0; r < now.height; ++r)
    for (int c = 0; c < now.width; ++c) {
      if (now.at(c, r) < 65) continue;
      ++occupied;
      const Eigen::Vector2d in_old =
          done.next_in_this.pose *
          (now.origin * Eigen::Vector2d((c + 0.5) * now.resolution, (r + 0.5) * now.resolution));
      const Eigen::Vector2d g = old.origin.inverse() * in_old / old.resolution;
      bool hit = false;
      for (int dr = -1; dr <= 1 && !hit; ++dr)
        for (int dc = -1; dc <= 1 && !hit; ++dc) {
          const int oc = static_cast<int>(std::floor(g.x())) + dc;
          const int orow = static_cast<int>(std::floor(g.y())) + dr;
          hit = old.contains(oc, orow) && old.at(oc, orow) >= 50;
        }
      agree += hit ? 1 : 0;
    }
  REQUIRE(occupied > 50);
  CHECK(agree >= 0.95 * occupied);
  // And the filter goes on from there.
  for (std::size_t k = 60; k < 120; ++k)
    carried->addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  const Pose2 chained = done.next_in_this.pose * carried->pose();
  CHECK(translationError(chained, tessera::between(sim.scans.front().truth, sim.scans[119].truth)) <
        0.1);
}

TEST_CASE("rbpf ignores empty, NaN and all-max-range scans and bad odometry", "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  Rbpf rbpf(fastOptions(5));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> nans(181, nan), maxed(181, inf), empty;
  const auto scanOf = [&](const std::vector<float>& r) {
    return tessera::grid::RangeScan{r, sim.laser.angleMin(), sim.laser.angleIncrement(),
                                    sim.laser.range_min, sim.laser.range_max};
  };
  // Before the first usable scan: nothing starts.
  CHECK(rbpf.addScan(0.0, scanOf(nans), Pose2{}, Pose2{}).scan_unusable);
  CHECK_FALSE(rbpf.initialized());
  rbpf.addScan(0.0, sim.range(sim.scans[0]), Pose2{}, sim.scans[0].odometry);
  REQUIRE(rbpf.initialized());
  for (std::size_t k = 1; k < 20; ++k)
    rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
  const Pose2 before = rbpf.pose();
  const auto known = rbpf.bestMap().knownCount();
  const Pose2 odom = sim.scans[19].odometry;
  for (const auto* r : {&nans, &maxed, &empty}) {
    const auto step = rbpf.addScan(10.0, scanOf(*r), Pose2{}, odom);
    CHECK(step.scan_unusable);
    CHECK_FALSE(step.updated);
  }
  const double bad = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(rbpf.addScan(11.0, sim.range(sim.scans[20]), Pose2{}, Pose2(bad, 0, 0)).updated);
  CHECK(rbpf.stats().unusable_scans == 4);
  CHECK(rbpf.stats().invalid_odometry == 1);
  CHECK(rbpf.pose().x == before.x);
  CHECK(rbpf.pose().y == before.y);
  CHECK(rbpf.bestMap().knownCount() == known);
}

TEST_CASE("the hand-over covariance is the particle spread plus a floor growing with distance",
          "[rbpf]") {
  const auto sim = test::simulateRoomLoop();
  auto handOver = [&](double lin, double ang) {
    RbpfOptions o = fastOptions(8);
    o.handover_sigma_linear = lin;
    o.handover_sigma_angular = ang;
    Rbpf rbpf(o);
    for (std::size_t k = 0; k < 60; ++k)
      rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{}, sim.scans[k].odometry);
    return rbpf.startSubmap();
  };
  const auto spread = handOver(0.0, 0.0);
  const auto floored = handOver(0.03, 0.004);
  REQUIRE(spread.travelled_m > 1.0);
  // Same filter run (the floor changes nothing else), so the covariances differ by the floor.
  CHECK(floored.next_in_this.pose.x == spread.next_in_this.pose.x);
  const Eigen::Matrix3d added = floored.next_in_this.covariance - spread.next_in_this.covariance;
  CHECK(added(0, 0) == Approx(0.03 * 0.03 * spread.travelled_m));
  CHECK(added(1, 1) == Approx(0.03 * 0.03 * spread.travelled_m));
  CHECK(added(2, 2) == Approx(0.004 * 0.004 * spread.travelled_m));
  CHECK(added(0, 1) == 0.0);
}

TEST_CASE("rbpf rejects invalid options with the option name", "[rbpf]") {
  RbpfOptions o;
  o.particles = 0;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("particles"));
  o = {};
  o.resample_threshold = 1.5;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("resample_threshold"));
  o = {};
  o.motion.srr = -1;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("srr"));
  o = {};
  o.grid.resolution = 0;
  CHECK_THROWS(Rbpf(o));
  o = {};
  o.handover_sigma_angular = -0.1;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("handover_sigma"));
  o = {};
  o.min_overlap_fraction = 1.5;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("min_overlap_fraction"));
  o = {};
  o.best_support_linear = -0.1;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("best_support_linear"));
  o = {};
  o.best_support_angular = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("best_support_angular"));
  o = {};
  o.track_linear_step = -0.01;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("track_linear_step"));
  o = {};
  o.track_angular_step = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("track_angular_step"));
  o = {};
  o.track_refinements = -1;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("track_refinements"));
  o = {};
  o.online_mean_angular = -0.1;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("online_mean_angular"));
  for (double bad :
       {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    o = {};
    o.carry_over_distance = bad;
    CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("carry_over_distance"));
    o = {};
    o.lost_match_fraction = bad;
    CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("lost_match_fraction"));
    o = {};
    o.lost_sigma_linear = bad;
    CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("lost_sigma_linear"));
  }
  o = {};
  o.lost_match_fraction = 1.0;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("lost_match_fraction"));
  o = {};
  o.lost_updates = 0;
  CHECK_THROWS_WITH(Rbpf(o), Catch::Contains("lost_updates"));
}

TEST_CASE("a robot carried away unseen is found lost without drawing the wrong place's walls",
          "[rbpf]") {
  // From the first turn on the spot after the 30th scan, odometry is 1.5 m and 90 degrees off:
  // for the filter the same as a robot picked up and put down elsewhere.
  const auto sim = roomLoopWithSlip(Pose2(1.5, 0.5, 1.57));
  RbpfOptions o = fastOptions(8);
  o.carry_over_distance = 0;
  std::size_t slip = 0;
  for (std::size_t k = 31; k < sim.scans.size() && slip == 0; ++k)
    if (std::abs(tessera::between(sim.scans[k - 1].odometry, sim.scans[k].odometry).theta -
                 tessera::between(sim.scans[k - 1].truth, sim.scans[k].truth).theta) > 1.0)
      slip = k;
  REQUIRE(slip > 0);

  SECTION("without the lost check the filter keeps inserting at the wrong pose") {
    Rbpf rbpf(o);
    for (const auto& s : sim.scans) rbpf.addScan(s.stamp_s, sim.range(s), Pose2{}, s.odometry);
    CHECK(rbpf.stats().lost == 0);
    CHECK(rbpf.stats().suspect_updates == 0);
  }
  SECTION("with it, suspect scans are held back and two in a row declare the robot lost") {
    o.lost_match_fraction = 0.25;
    o.lost_updates = 2;
    Rbpf rbpf(o);
    std::size_t k = 0;
    for (; k < slip; ++k) {
      const auto step = rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{},
                                     sim.scans[k].odometry);
      CHECK_FALSE(step.suspect);  // the normal updates put most beams on the map
    }
    const auto known = rbpf.bestMap().knownCount();
    const auto inserted = rbpf.submapScans();
    bool lost = false;
    int suspects = 0;
    for (; k < sim.scans.size() && !lost; ++k) {
      const auto step = rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{},
                                     sim.scans[k].odometry);
      suspects += step.suspect ? 1 : 0;
      if (step.updated) CHECK(step.match_fraction < 0.25);
      lost = step.lost;
      // Nothing of the wrong place reaches the map: the best particle may switch to a sibling's
      // map a few cells different, where an inserted scan would add hundreds.
      CHECK(rbpf.bestMap().knownCount() <= known + 10);
      CHECK(rbpf.submapScans() == inserted);
    }
    REQUIRE(lost);
    CHECK(suspects == 2);
    CHECK(rbpf.stats().lost == 1);
    const auto done = rbpf.startSubmapLost();
    CHECK(done.id == 0);
    CHECK(done.next_in_this.covariance(0, 0) == Approx(1e4));
    CHECK(done.next_in_this.covariance(1, 1) == Approx(1e4));
    CHECK(done.next_in_this.covariance(2, 2) == Approx(9.0));
    CHECK(done.next_in_this.covariance(0, 1) == 0.0);
    // The fresh submap maps the new place consistently: its poses follow the true motion.
    const Pose2 start = sim.scans[k - 1].truth;
    const std::size_t end = std::min(sim.scans.size(), k + 40);
    for (; k < end; ++k) {
      const auto step = rbpf.addScan(sim.scans[k].stamp_s, sim.range(sim.scans[k]), Pose2{},
                                     sim.scans[k].odometry);
      CHECK_FALSE(step.suspect);
    }
    CHECK(translationError(rbpf.pose(), tessera::between(start, sim.scans[end - 1].truth)) < 0.15);
  }
}
