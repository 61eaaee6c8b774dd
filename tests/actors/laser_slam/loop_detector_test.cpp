// loop_detector actor through the mock-mailbox harness: which pose of the robot in its own
// submap a published closure uses.
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/laser_slam/loop_detector_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include "../scan_messages.hpp"

#include <Eigen/LU>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <tuple>
#include <vector>

using namespace tessera;
using tessera::Pose2;

namespace {

struct ClosureRun {
  int published = 0;
  std::int64_t smoothed = 0;
  Pose2 relative;
  bool has_scan = false;
  Pose2 scan_in_matched;  // scanInTo: the match itself
  Eigen::Matrix3d scan_covariance = Eigen::Matrix3d::Zero();
  std::vector<int> matched;  // the submap of each published closure
};

// Submap 0 is mapped from the room's first scans at their true poses (its frame = the first
// pose). The robot, then in submap 1 whose chained origin is `origin1`, sends one scan taken at
// the true pose of scan `probe`, with its online estimate exact. Submap 1 then finishes, with
// `smoothed` as its trajectory entry for that scan when given.
// Metres between the positions of two poses.
double apart(const Pose2& a, const Pose2& b) {
  return (a.translation() - b.translation()).norm();
}

// The room mapped from every other scan of the first 120, in the first scan's frame.
tessera::grid::OccupancyMap roomMap(const test::SimScans& sim) {
  const Pose2 frame0 = sim.scans[0].truth;
  tessera::grid::OccupancyGrid grid;
  for (std::size_t k = 0; k < 120; k += 2)
    grid.insertScan(sim.range(sim.scans[k]), frame0.inverse() * sim.scans[k].truth);
  return grid.toOccupancyMap();
}

// Publishes a finished submap holding `m`, placed at `origin` in the chained frame.
void pushSubmap(ActorHarness& h, int id, double t, const tessera::grid::OccupancyMap& m,
                const Pose2& origin) {
  h.push<msg::Submap>("submaps", [&](auto& b) {
    setHeader(b.initHeader(), test::stampOf(t), "map", 0);
    b.setId(static_cast<std::uint32_t>(id));
    auto g = b.initGrid();
    g.setResolution(static_cast<float>(m.resolution));
    g.setWidth(static_cast<std::uint32_t>(m.width));
    g.setHeight(static_cast<std::uint32_t>(m.height));
    writePose(g.initOrigin(), tessera::Pose2{m.origin.x, m.origin.y, m.origin.theta});
    auto cells = mutableViewInt8(g.initCells(static_cast<unsigned>(m.cells.size())));
    std::copy(m.cells.begin(), m.cells.end(), cells.begin());
    writePose(b.initGlobalPose(), tessera::Pose2{origin.x, origin.y, origin.theta});
    b.setFinished(true);
  });
}

// `copies` finished submaps hold the same map (ids 0..copies-1); the robot's own is `copies`.
ClosureRun runClosure(const std::optional<Pose2>& smoothed, int copies = 1,
                      int closures_per_scan = 1) {
  const auto sim = test::simulateRoomLoop();
  const Pose2 frame0 = sim.scans[0].truth;
  const tessera::grid::OccupancyMap map = roomMap(sim);

  laser_slam::LoopDetectorOptions o;
  o.skip_recent = 0;  // submap 0 is the most recent finished one
  o.every_n_scans = 1;
  o.closures_per_scan = closures_per_scan;
  ActorHarness h(std::make_unique<laser_slam::LoopDetectorActor>(o));
  for (int id = 0; id < copies; ++id) pushSubmap(h, id, 1.0 + 0.1 * id, map, Pose2{});
  h.runUntilIdle();

  const std::size_t probe = 60;
  const Pose2 in_map = frame0.inverse() * sim.scans[probe].truth;  // chained = submap 0 frame
  const Nanos stamp = test::stampOf(5.0);
  test::pushScan(h, stamp, sim, sim.scans[probe].ranges);
  h.push<msg::PoseStamped>("chained_pose", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), tessera::Pose2{in_map.x, in_map.y, in_map.theta});
  });
  h.runUntilIdle();

  const Pose2 origin1(1.0, 0.5, 0.2);
  h.push<msg::Submap>("submaps", [&](auto& b) {
    setHeader(b.initHeader(), test::stampOf(6.0), "map", 0);
    b.setId(static_cast<std::uint32_t>(copies));
    auto g = b.initGrid();
    g.setResolution(0.05f);
    g.setWidth(1);
    g.setHeight(1);
    g.initCells(1);
    writePose(b.initGlobalPose(), tessera::Pose2{origin1.x, origin1.y, origin1.theta});
    b.setFinished(true);
    if (smoothed) {
      auto t = b.initTrajectory(2);
      t[0].setStampNs(test::stampOf(4.9));
      t[1].setStampNs(stamp);
      t[1].setX(smoothed->x);
      t[1].setY(smoothed->y);
      t[1].setTheta(smoothed->theta);
    }
  });
  h.runUntilIdle();
  h.stop();

  ClosureRun run;
  const auto out = h.published<msg::SubmapConstraint>("loop_constraints");
  run.published = static_cast<int>(out.size());
  for (const auto& c : out) run.matched.push_back(static_cast<int>(c->getToId()));
  if (!out.empty()) {
    const auto r = out.back()->getRelative();
    run.relative = Pose2(r.getX(), r.getY(), r.getTheta());
    run.has_scan = out.back()->hasScanInTo();
    if (run.has_scan) {
      const auto m = out.back()->getScanInTo();
      run.scan_in_matched = Pose2(m.getX(), m.getY(), m.getTheta());
      if (!readCovariance(m, run.scan_covariance)) run.scan_covariance.setConstant(-1);
    }
  }
  Summary s;
  h.actor().summarize(s);
  run.smoothed = std::get<std::int64_t>(s.at("loops_published_smoothed"));
  return run;
}

}  // namespace

TEST_CASE("a loop closure uses the finished submap smoothed pose of its scan, else the online one",
          "[loop_detector]") {
  const auto sim = test::simulateRoomLoop();
  const Pose2 in_map = sim.scans[0].truth.inverse() * sim.scans[60].truth;
  const Pose2 origin1(1.0, 0.5, 0.2);
  // Relative = robot in submap 1 composed with the inverse of the robot in submap 0.
  const Pose2 online_in_1 = origin1.inverse() * in_map;

  const ClosureRun online = runClosure(std::nullopt);
  REQUIRE(online.published == 1);
  CHECK(online.smoothed == 0);
  const Pose2 expect_online = online_in_1 * in_map.inverse();
  CHECK(apart(online.relative, expect_online) < 0.05);

  // The particle kept for submap 1 had the robot 0.3 m and 0.05 rad elsewhere at that scan.
  const Pose2 smoothed_in_1 = online_in_1 * Pose2(0.3, -0.1, 0.05);
  const ClosureRun smoothed = runClosure(smoothed_in_1);
  REQUIRE(smoothed.published == 1);
  CHECK(smoothed.smoothed == 1);
  const Pose2 expect_smoothed = smoothed_in_1 * in_map.inverse();
  CHECK(apart(smoothed.relative, expect_smoothed) < 0.05);
  CHECK(std::abs(tessera::angleDiff(smoothed.relative.theta, expect_smoothed.theta)) < 0.02);
  // The two answers are told apart: they lie 0.13 m apart, each found within 0.05 m.
  REQUIRE(apart(expect_smoothed, expect_online) > 0.12);
  CHECK(apart(smoothed.relative, expect_online) > 0.07);
}

TEST_CASE("a loop closure also carries the scan pose in the matched submap with its covariance",
          "[loop_detector][scan_graph]") {
  const auto sim = test::simulateRoomLoop();
  // The robot in submap 0 (the matched one) at the probe scan: what the match must find, the
  // same whichever pose in its own submap the closure was expressed with.
  const Pose2 in_map = sim.scans[0].truth.inverse() * sim.scans[60].truth;
  for (const auto& smoothed : {std::optional<Pose2>{}, std::optional<Pose2>{Pose2(1, 2, 0.3)}}) {
    const ClosureRun run = runClosure(smoothed);
    REQUIRE(run.published == 1);
    REQUIRE(run.has_scan);
    CHECK(apart(run.scan_in_matched, in_map) < 0.05);
    CHECK(std::abs(tessera::angleDiff(run.scan_in_matched.theta, in_map.theta)) < 0.02);
    // Symmetric, positive definite, and at least the published floors (0.05 m, 0.02 rad).
    REQUIRE(run.scan_covariance.allFinite());
    CHECK((run.scan_covariance - run.scan_covariance.transpose()).norm() < 1e-12);
    CHECK(run.scan_covariance(0, 0) >= 0.05 * 0.05);
    CHECK(run.scan_covariance(1, 1) >= 0.05 * 0.05);
    CHECK(run.scan_covariance(2, 2) >= 0.02 * 0.02);
    CHECK(run.scan_covariance.determinant() > 0);
  }
}

TEST_CASE("closures_per_scan publishes the verified matches of one scan against several submaps",
          "[loop_detector][scan_graph]") {
  // Two finished submaps hold the room: the scan matches both.
  const ClosureRun best = runClosure(std::nullopt, 2, 1);
  CHECK(best.published == 1);
  const ClosureRun both = runClosure(std::nullopt, 2, 2);
  REQUIRE(both.published == 2);
  std::vector<int> matched = both.matched;
  std::sort(matched.begin(), matched.end());
  CHECK(matched == std::vector<int>{0, 1});
  // The best one is the one published alone.
  CHECK(std::find(both.matched.begin(), both.matched.end(), best.matched.at(0)) !=
        both.matched.end());
  // More than there are candidates to search is a configuration error.
  laser_slam::LoopDetectorOptions o;
  o.closures_per_scan = o.max_candidates + 1;
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);
  o.closures_per_scan = 0;
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);
}

TEST_CASE("a non-finite smoothed scan pose falls back to the online estimate", "[loop_detector]") {
  const auto sim = test::simulateRoomLoop();
  const Pose2 in_map = sim.scans[0].truth.inverse() * sim.scans[60].truth;
  const Pose2 origin1(1.0, 0.5, 0.2);
  const Pose2 expect_online = (origin1.inverse() * in_map) * in_map.inverse();
  const ClosureRun run = runClosure(Pose2(std::nan(""), 0.0, 0.0));
  REQUIRE(run.published == 1);
  CHECK(run.smoothed == 0);
  CHECK(run.relative.isFinite());
  CHECK(apart(run.relative, expect_online) < 0.05);
}

namespace {

// Every published closure, field by field, to compare runs exactly.
struct PublishedClosure {
  std::uint32_t from = 0, to = 0;
  std::vector<double> values;  // relative and scanInTo poses with their covariances
  bool operator==(const PublishedClosure&) const = default;
};

struct CacheRun {
  std::vector<PublishedClosure> closures;
  std::size_t before_stop = 0;  // published before the actor was stopped
  std::int64_t builds = 0, hits = 0;
  double memory_mb = 0, memory_peak_mb = 0;
};

std::vector<double> poseValues(msg::Pose2D::Reader p) {
  std::vector<double> v{p.getX(), p.getY(), p.getTheta()};
  Eigen::Matrix3d cov;
  if (readCovariance(p, cov))
    for (int k = 0; k < 9; ++k) v.push_back(cov(k / 3, k % 3));
  return v;
}

// Two finished submaps (ids 0, 1) hold the same room; probe scans in submap 2 match both, so
// each scan searches one, then the other: with one cached pyramid every search rebuilds one.
CacheRun runCachedClosures(int pyramid_cache) {
  const auto sim = test::simulateRoomLoop();
  const Pose2 frame0 = sim.scans[0].truth;
  const tessera::grid::OccupancyMap map = roomMap(sim);

  laser_slam::LoopDetectorOptions o;
  o.skip_recent = 0;
  o.every_n_scans = 1;
  o.closures_per_scan = 2;
  o.pyramid_cache = pyramid_cache;
  ActorHarness h(std::make_unique<laser_slam::LoopDetectorActor>(o));
  const auto pushSubmapNow = [&](int id, double t, const tessera::grid::OccupancyMap& m,
                                 const Pose2& origin) {
    pushSubmap(h, id, t, m, origin);
    h.runUntilIdle();
  };
  const auto pushPose = [&](Nanos stamp, const Pose2& p) {
    h.push<msg::PoseStamped>("chained_pose", [&](auto& b) {
      setHeader(b.initHeader(), stamp, "map", 0);
      writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
    });
    h.runUntilIdle();
  };
  pushSubmapNow(0, 1.0, map, Pose2());
  pushSubmapNow(1, 1.1, map, Pose2());
  double t = 5.0;
  for (const std::size_t probe : {40u, 60u, 80u, 100u}) {
    const Nanos stamp = test::stampOf(t);
    t += 0.5;
    test::pushScan(h, stamp, sim, sim.scans[probe].ranges);
    pushPose(stamp, frame0.inverse() * sim.scans[probe].truth);
  }
  tessera::grid::OccupancyMap own;  // the robot's submap: a single cell
  own.width = own.height = 1;
  own.cells = {-1};
  pushSubmapNow(2, 10.0, own, Pose2(1.0, 0.5, 0.2));
  // Its closures go out with the builder's next pose (which follows its hand-over).
  pushPose(test::stampOf(10.0), Pose2(1.0, 0.5, 0.2));

  CacheRun run;
  run.before_stop = h.published<msg::SubmapConstraint>("loop_constraints").size();
  h.stop();
  for (const auto& c : h.published<msg::SubmapConstraint>("loop_constraints")) {
    PublishedClosure p{c->getFromId(), c->getToId(), poseValues(c->getRelative())};
    const auto scan = poseValues(c->getScanInTo());
    p.values.insert(p.values.end(), scan.begin(), scan.end());
    run.closures.push_back(std::move(p));
  }
  Summary s;
  h.actor().summarize(s);
  run.builds = std::get<std::int64_t>(s.at("pyramid_builds"));
  run.hits = std::get<std::int64_t>(s.at("pyramid_cache_hits"));
  run.memory_mb = std::get<double>(s.at("memory_mb"));
  run.memory_peak_mb = std::get<double>(s.at("memory_peak_mb"));
  return run;
}

}  // namespace

TEST_CASE("pyramids rebuilt from a submap's cells give the same closures as cached ones",
          "[loop_detector][pyramid_cache]") {
  const CacheRun big = runCachedClosures(8);
  const CacheRun one = runCachedClosures(1);
  REQUIRE(big.closures.size() >= 4);  // the probes match both submaps
  CHECK(big.before_stop == big.closures.size());
  CHECK(one.closures == big.closures);  // bit for bit
  CHECK(big.builds == 2);               // each submap's pyramid once
  CHECK(one.builds > 2);                // rebuilt as the searches alternate
  CHECK(one.builds + one.hits == big.builds + big.hits);
  // Held: the cells of the three submaps plus the cached pyramids (~9 bytes per cell each).
  CHECK(one.memory_mb > 0);
  CHECK(one.memory_mb < big.memory_mb);
  CHECK(big.memory_peak_mb >= big.memory_mb);
}

TEST_CASE("loop_detector pyramid_cache must be at least 1", "[loop_detector][options]") {
  CHECK(laser_slam::LoopDetectorOptions{}.pyramid_cache == 4);
  const auto o = loadOptions<laser_slam::LoopDetectorOptions>(
      Params(YAML::Load("{pyramid_cache: 0}"), "test"));
  CHECK(o.pyramid_cache == 0);
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);
  CHECK_THROWS_WITH(laser_slam::LoopDetectorActor(o),
                    Catch::Contains("loop_detector: pyramid_cache must be >= 1"));
  auto one = o;
  one.pyramid_cache = 1;
  CHECK_NOTHROW(laser_slam::LoopDetectorActor(one));
}

namespace {

struct AtMatchRun {
  int before_finish = 0;  // closures published while submap 1 was being built
  int after_stop = 0;
  Pose2 relative;  // of the first closure
};

// Submap 0 holds the room (frame = the first true pose). The builder's hand-overs on
// `constraints` are `handovers` (from, to, relative); then the robot, in submap 1, sends one scan
// at the true pose of scan 60 with its chained estimate exact. Submap 1 finishes last, at
// `origin1` (a 1-cell grid, no trajectory).
AtMatchRun runAtMatch(const std::vector<std::tuple<int, int, Pose2>>& handovers,
                      const Pose2& origin1) {
  const auto sim = test::simulateRoomLoop();
  const Pose2 frame0 = sim.scans[0].truth;
  laser_slam::LoopDetectorOptions o;
  o.skip_recent = 0;
  o.every_n_scans = 1;
  o.publish_at_match = true;
  ActorHarness h(std::make_unique<laser_slam::LoopDetectorActor>(o));
  pushSubmap(h, 0, 1.0, roomMap(sim), Pose2{});
  for (const auto& [from, to, rel] : handovers)
    h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
      setHeader(b.initHeader(), test::stampOf(1.5), "map", 0);
      b.setFromId(static_cast<std::uint32_t>(from));
      b.setToId(static_cast<std::uint32_t>(to));
      writePose(b.initRelative(), rel);
      b.setKind(msg::SubmapConstraint::Kind::HAND_OVER);
    });
  h.runUntilIdle();
  const Pose2 chained = frame0.inverse() * sim.scans[60].truth;
  const Nanos stamp = test::stampOf(5.0);
  test::pushScan(h, stamp, sim, sim.scans[60].ranges);
  h.push<msg::PoseStamped>("chained_pose", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), chained);
  });
  h.runUntilIdle();
  AtMatchRun run;
  run.before_finish =
      static_cast<int>(h.published<msg::SubmapConstraint>("loop_constraints").size());
  tessera::grid::OccupancyMap tiny;
  tiny.resolution = 0.05;
  tiny.width = tiny.height = 1;
  tiny.cells = {-1};
  pushSubmap(h, 1, 6.0, tiny, origin1);
  h.runUntilIdle();
  h.stop();
  const auto out = h.published<msg::SubmapConstraint>("loop_constraints");
  run.after_stop = static_cast<int>(out.size());
  if (!out.empty()) {
    const auto r = out.front()->getRelative();
    run.relative = Pose2(r.getX(), r.getY(), r.getTheta());
  }
  return run;
}

}  // namespace

TEST_CASE(
    "publish_at_match sends a closure of the submap being built at once, placed by the "
    "builder's hand-over",
    "[loop_detector]") {
  const Pose2 origin1(1.0, 0.5, 0.2);
  const AtMatchRun run = runAtMatch({{0, 1, origin1}}, origin1);
  REQUIRE(run.before_finish == 1);
  CHECK(run.after_stop == 1);  // not sent again when the submap finishes
  // The matched submap's origin seen from submap 1: the hand-over's inverse.
  const Pose2 expected = origin1.inverse();
  CHECK(apart(run.relative, expected) < 0.1);
  CHECK(std::abs(tessera::angleDiff(run.relative.theta, expected.theta)) < 0.03);
}

TEST_CASE("publish_at_match ignores hand-overs from unknown submaps and with NaN poses",
          "[loop_detector]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Pose2 origin1(1.0, 0.5, 0.2);
  // Neither places submap 1: the closure waits for submap 1's own message, which does.
  const AtMatchRun run =
      runAtMatch({{0, 1, Pose2(nan, 0.5, 0.2)}, {7, 8, Pose2(1.0, 0.0, 0.0)}}, origin1);
  CHECK(run.before_finish == 0);
  REQUIRE(run.after_stop == 1);
  const Pose2 expected = origin1.inverse();
  CHECK(apart(run.relative, expected) < 0.1);
}
