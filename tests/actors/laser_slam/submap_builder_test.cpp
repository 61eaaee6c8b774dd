// Tests for the rbpf_submap_builder and map_assembler actors (through the mock-mailbox harness)
// and the MapAssembler core.
#include <tessera/laser_slam/map_assembler.hpp>
#include <tessera/laser_slam/map_assembler_actor.hpp>
#include <tessera/laser_slam/submap_builder_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "../scan_messages.hpp"

using namespace tessera;
using laser_slam::MapAssembler;
using laser_slam::SubmapBuilderActor;
using laser_slam::SubmapBuilderOptions;
using tessera::Pose2;
using test::pushOdometry;
using test::pushScan;
using test::stampOf;

namespace {

SubmapBuilderOptions fastOptions() {
  SubmapBuilderOptions o;
  o.rbpf.particles = 8;
  o.rbpf.linear_update = 0.3;
  o.rbpf.angular_update = 0.3;
  return o;
}

Pose2 poseOf(msg::Pose2D::Reader p) {
  return {p.getX(), p.getY(), p.getTheta()};
}

/// Feeds scans [from, to) of the room loop with their odometry, one at a time, stamped
/// `epoch` + their time in the loop.
void feedScans(ActorHarness& h, const test::SimScans& sim, std::size_t from, std::size_t to,
               Nanos epoch = 0) {
  for (std::size_t k = from; k < to; ++k) {
    const Nanos t = epoch + stampOf(sim.scans[k].stamp_s);
    pushOdometry(h, t, sim.scans[k].odometry);
    pushScan(h, t, sim, sim.scans[k].ranges);
    h.runUntilIdle();
  }
}

/// The first n scans, then stop().
void feedAndStop(ActorHarness& h, const test::SimScans& sim, std::size_t n) {
  feedScans(h, sim, 0, n);
  h.stop();
}

}  // namespace

TEST_CASE("submap builder publishes a pose per scan, hand-over constraints and submaps",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.submap_scans = 25;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  const std::size_t n = 160;
  feedAndStop(h, sim, n);
  const auto poses = h.published<msg::PoseStamped>("pose");
  REQUIRE(poses.size() == n);
  CHECK(h.publishedCount("map_to_odom") == n);
  const auto constraints = h.published<msg::SubmapConstraint>("constraints");
  const auto submaps = h.published<msg::Submap>("submaps");
  REQUIRE(constraints.size() >= 2);
  CHECK(submaps.size() == constraints.size() + 1);  // the last one comes at stop
  for (std::size_t i = 0; i < submaps.size(); ++i) {
    CHECK(submaps[i]->getId() == i);
    CHECK(submaps[i]->getFinished());
    CHECK(submaps[i]->getGrid().getWidth() > 10);
  }
  // Chained hand-overs are the published global submap poses.
  Pose2 chained;
  for (std::size_t i = 0; i < constraints.size(); ++i) {
    CHECK(constraints[i]->getFromId() == i);
    CHECK(constraints[i]->getToId() == i + 1);
    CHECK(constraints[i]->getKind() == msg::SubmapConstraint::Kind::HAND_OVER);
    CHECK(constraints[i]->getRelative().getCovariance().size() == 9);
    chained = chained * poseOf(constraints[i]->getRelative());
    const Pose2 global = poseOf(submaps[i + 1]->getGlobalPose());
    CHECK(global.x == Approx(chained.x).margin(1e-9));
    CHECK(global.y == Approx(chained.y).margin(1e-9));
  }
  // The online estimate follows the truth (map frame = the first pose).
  const Pose2 truth = tessera::between(sim.scans.front().truth, sim.scans[n - 1].truth);
  const Pose2 last = poseOf(poses.back()->getPose());
  CHECK(std::hypot(last.x - truth.x, last.y - truth.y) < 0.15);
  // The smoothed trajectory: one pose per scan across all submaps (each the smoothed pose of
  // the update before it, moved by odometry), stamped like the online poses, in time order.
  const auto final_poses = h.published<msg::PoseStamped>("final_poses");
  REQUIRE(final_poses.size() == poses.size());
  for (std::size_t i = 0; i < final_poses.size(); ++i)
    CHECK(final_poses[i]->getHeader().getStampNs() == poses[i]->getHeader().getStampNs());
  const Pose2 final_last = poseOf(final_poses.back()->getPose());
  CHECK(std::hypot(final_last.x - truth.x, final_last.y - truth.y) < 0.2);
  // map_to_odom ⊕ odometry = the published pose.
  const auto corr = h.published<msg::PoseStamped>("map_to_odom").back();
  const Pose2 odom_in_map = poseOf(corr->getPose()) * sim.scans[n - 1].odometry;
  CHECK(odom_in_map.x == Approx(last.x).margin(1e-6));
  CHECK(odom_in_map.y == Approx(last.y).margin(1e-6));
}

TEST_CASE("the smoothed trajectory keeps each scan's exact stamp at epoch times",
          "[rbpf][submap_builder]") {
  // A log stamped in Unix time (the Intel log: 976052856.338882 s): a double in seconds holds
  // such a stamp only to ~0.1 µs, so stamps passed through one would no longer equal the
  // scans', and a consumer pairing scans with the smoothed poses by stamp would find none.
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.submap_scans = 25;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  const Nanos epoch = 976052856338882123;
  const std::size_t n = 80;
  feedScans(h, sim, 0, n, epoch);
  h.stop();
  std::vector<Nanos> stamps;
  for (std::size_t k = 0; k < n; ++k) stamps.push_back(epoch + stampOf(sim.scans[k].stamp_s));
  const auto final_poses = h.published<msg::PoseStamped>("final_poses");
  REQUIRE(final_poses.size() == n);
  for (std::size_t i = 0; i < n; ++i) CHECK(final_poses[i]->getHeader().getStampNs() == stamps[i]);
  const auto submaps = h.published<msg::Submap>("submaps");
  REQUIRE(submaps.size() >= 2);
  for (const auto& submap : submaps)
    for (const auto p : submap->getTrajectory())
      CHECK(std::find(stamps.begin(), stamps.end(), p.getStampNs()) != stamps.end());
}

namespace {

struct SmoothedRun {
  std::vector<Pose2> poses;  // final_poses, map frame
  std::vector<Nanos> stamps;
};

SmoothedRun smoothedRun(const test::SimScans& sim, std::size_t n, bool interpolate) {
  SubmapBuilderOptions o = fastOptions();
  o.rbpf.parallel = false;  // the same filter run with either setting
  o.submap_scans = 25;
  o.interpolate_updates = interpolate;
  o.rbpf.track_between_updates = false;  // the odometry carries the scans between updates
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  feedAndStop(h, sim, n);
  SmoothedRun run;
  for (const auto& p : h.published<msg::PoseStamped>("final_poses")) {
    run.poses.push_back(poseOf(p->getPose()));
    run.stamps.push_back(p->getHeader().getStampNs());
  }
  return run;
}

}  // namespace

TEST_CASE("interpolate_updates spreads the correction found at an update over the scans before it",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  const std::size_t n = 160;
  const SmoothedRun held = smoothedRun(sim, n, false);
  const SmoothedRun blended = smoothedRun(sim, n, true);
  REQUIRE(held.poses.size() == n);
  REQUIRE(blended.stamps == held.stamps);
  // Held: the correction (pose ⊕ odometry⁻¹) changes only at filter updates. Blended: the same
  // poses there, and in between a correction on the way from one update's to the next one's.
  auto correction = [&](const SmoothedRun& r, std::size_t i) {
    return r.poses[i] * sim.scans[i].odometry.inverse();
  };
  std::vector<std::size_t> updates;
  for (std::size_t i = 1; i < n; ++i) {
    const Pose2 d = correction(held, i - 1).inverse() * correction(held, i);
    if (std::hypot(d.x, d.y) + std::abs(d.theta) > 1e-9) updates.push_back(i);
  }
  REQUIRE(updates.size() >= 5);
  std::size_t between = 0, moved = 0;
  for (std::size_t u = 0; u + 1 < updates.size(); ++u) {
    const std::size_t a = updates[u], b = updates[u + 1];
    CHECK((blended.poses[a].translation() - held.poses[a].translation()).norm() < 1e-9);
    const Pose2 ca = correction(held, a), cb = correction(held, b);
    for (std::size_t i = a + 1; i < b; ++i) {
      ++between;
      const Pose2 c = correction(blended, i);
      // On the segment between the two corrections (x and y each between theirs).
      CHECK(c.x >= std::min(ca.x, cb.x) - 1e-9);
      CHECK(c.x <= std::max(ca.x, cb.x) + 1e-9);
      CHECK(c.y >= std::min(ca.y, cb.y) - 1e-9);
      CHECK(c.y <= std::max(ca.y, cb.y) + 1e-9);
      if ((blended.poses[i].translation() - held.poses[i].translation()).norm() > 1e-6) ++moved;
    }
  }
  CHECK(between > 0);
  CHECK(moved > between / 2);
  // Near the truth either way (on the simulated room odometry drifts smoothly and both
  // stay within a few cm; on Intel blending is what brings the relations error down).
  for (std::size_t i = 0; i < n; ++i) {
    const Pose2 truth = tessera::between(sim.scans.front().truth, sim.scans[i].truth);
    CHECK((blended.poses[i].translation() - truth.translation()).norm() < 0.25);
  }
}

namespace {

void pushSubmapPoses(ActorHarness& h, const std::vector<std::pair<int, Pose2>>& poses) {
  h.push<msg::SubmapPoses>("submap_poses", [&](auto& b) {
    setHeader(b.initHeader(), 0, "map", 0);
    auto list = b.initPoses(static_cast<unsigned>(poses.size()));
    for (unsigned i = 0; i < poses.size(); ++i) {
      list[i].setId(static_cast<std::uint32_t>(poses[i].first));
      writePose(list[i].initPose(), poses[i].second);
    }
  });
  h.runUntilIdle();
}

}  // namespace

TEST_CASE("with optimized_poses the live pose follows the latest optimised graph",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.rbpf.parallel = false;
  o.submap_scans = 12;
  o.optimized_poses = true;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  feedScans(h, sim, 0, 140);
  const auto submaps = h.published<msg::Submap>("submaps");
  REQUIRE(submaps.size() >= 2);
  // Before any graph: pose = chained_pose.
  {
    const auto live = h.published<msg::PoseStamped>("pose");
    const auto chained = h.published<msg::PoseStamped>("chained_pose");
    REQUIRE(live.size() == chained.size());
    const Pose2 a = poseOf(live.back()->getPose()), b = poseOf(chained.back()->getPose());
    CHECK((a.translation() - b.translation()).norm() < 1e-12);
  }
  // The graph moved submap 0 (the newest it holds): every later submap moves with it.
  const Pose2 moved(0.4, -0.3, 0.1);
  pushSubmapPoses(h, {{0, moved}});
  // A graph naming submaps this builder never started, or a NaN pose, changes nothing.
  pushSubmapPoses(h, {{99, Pose2(5, 5, 0)}});
  pushSubmapPoses(h, {{0, Pose2(std::nan(""), 0, 0)}});
  const std::size_t before = h.publishedCount("pose");
  feedScans(h, sim, 140, 150);
  const auto live = h.published<msg::PoseStamped>("pose");
  const auto chained = h.published<msg::PoseStamped>("chained_pose");
  const auto corrections = h.published<msg::PoseStamped>("map_to_odom");
  REQUIRE(live.size() == before + 10);  // scans 140..149
  for (std::size_t i = before; i < live.size(); ++i) {
    // Submap 0's chained origin is the map frame's: live = moved ⊕ chained.
    const Pose2 expected = moved * poseOf(chained[i]->getPose());
    const Pose2 got = poseOf(live[i]->getPose());
    CHECK(got.x == Approx(expected.x).margin(1e-9));
    CHECK(got.y == Approx(expected.y).margin(1e-9));
    CHECK(tessera::angleDiff(got.theta, expected.theta) == Approx(0).margin(1e-9));
    const Pose2 via_odom = poseOf(corrections[i]->getPose()) * sim.scans[i].odometry;
    CHECK(via_odom.x == Approx(got.x).margin(1e-6));
    CHECK(via_odom.y == Approx(got.y).margin(1e-6));
  }
  // The newest submap the graph holds wins: submap 1 placed elsewhere overrides submap 0.
  const Pose2 one = poseOf(submaps[1]->getGlobalPose());
  const Pose2 one_moved = Pose2(-0.2, 0.3, -0.05) * one;
  pushSubmapPoses(h, {{0, moved}, {1, one_moved}});
  feedScans(h, sim, 150, 151);
  {
    const auto l = h.published<msg::PoseStamped>("pose");
    const auto c = h.published<msg::PoseStamped>("chained_pose");
    const Pose2 expected = one_moved * one.inverse() * poseOf(c.back()->getPose());
    const Pose2 got = poseOf(l.back()->getPose());
    CHECK(got.x == Approx(expected.x).margin(1e-9));
    CHECK(got.y == Approx(expected.y).margin(1e-9));
  }
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("graph_updates")) == 2);
  CHECK(std::get<std::int64_t>(s.at("live_corrections")) >= 1);
  // The first correction moved the robot by about |moved| at once (rotation about the origin
  // adds to the 0.5 m shift).
  CHECK(std::get<double>(s.at("live_correction_max_m")) > 0.4);
}

TEST_CASE("with tracking the smoothed trajectory follows the scan-matched motion between updates",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.rbpf.parallel = false;
  o.rbpf.track_between_updates = true;
  o.submap_scans = 25;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  const std::size_t n = 160;
  feedAndStop(h, sim, n);
  const auto online = h.published<msg::PoseStamped>("chained_pose");
  const auto smoothed = h.published<msg::PoseStamped>("final_poses");
  REQUIRE(online.size() == n);
  REQUIRE(smoothed.size() == n);
  // Between two scans of one filter interval the smoothed poses move as the online (tracked)
  // ones do, which is not the odometry's motion wherever tracking corrected it.
  std::size_t tracked = 0, as_tracked = 0;
  for (std::size_t i = 1; i < n; ++i) {
    const Pose2 online_step =
        poseOf(online[i - 1]->getPose()).inverse() * poseOf(online[i]->getPose());
    const Pose2 odom_step = sim.scans[i - 1].odometry.inverse() * sim.scans[i].odometry;
    const Pose2 smoothed_step =
        poseOf(smoothed[i - 1]->getPose()).inverse() * poseOf(smoothed[i]->getPose());
    if ((online_step.translation() - odom_step.translation()).norm() < 1e-6) continue;
    ++tracked;
    if ((smoothed_step.translation() - online_step.translation()).norm() < 1e-6 &&
        std::abs(tessera::angleDiff(smoothed_step.theta, online_step.theta)) < 1e-6)
      ++as_tracked;
  }
  // Steps that end at an update (the online pose jumps to the filter's estimate there) differ;
  // the others move as tracked. Moved by odometry, as before tracking counted, none would.
  CHECK(tracked > 20);
  CHECK(as_tracked > 20);
}

TEST_CASE("submap builder waits for odometry and counts scans it cannot pair",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  ActorHarness h(std::make_unique<SubmapBuilderActor>(fastOptions()));
  // Scan first, odometry after it: the scan waits, then is processed.
  pushScan(h, stampOf(1.0), sim, sim.scans[0].ranges);
  h.runUntilIdle();
  CHECK(h.publishedCount("pose") == 0);
  pushOdometry(h, stampOf(0.5), sim.scans[0].odometry);
  pushOdometry(h, stampOf(1.5), sim.scans[0].odometry);
  h.runUntilIdle();
  CHECK(h.publishedCount("pose") == 1);
  // A scan older than every odometry pose is dropped and counted; one never paired at stop too.
  pushScan(h, stampOf(0.1), sim, sim.scans[1].ranges);
  pushScan(h, stampOf(9.0), sim, sim.scans[1].ranges);
  h.runUntilIdle();
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("scans_read")) == 3);
  CHECK(std::get<std::int64_t>(s.at("scans_unpaired")) == 2);
  CHECK(std::get<std::int64_t>(s.at("scans_processed")) == 1);
  CHECK(h.publishedCount("submaps") == 1);
}

TEST_CASE("submap builder survives NaN, empty and all-max-range scans", "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  ActorHarness h(std::make_unique<SubmapBuilderActor>(fastOptions()));
  const std::vector<float> nans(181, std::numeric_limits<float>::quiet_NaN());
  const std::vector<float> maxed(181, std::numeric_limits<float>::infinity());
  const std::vector<float> empty;
  int k = 0;
  for (const auto* r : {&nans, &empty, &maxed, &sim.scans[0].ranges, &nans, &maxed}) {
    const Nanos t = stampOf(++k);
    pushOdometry(h, t, sim.scans[0].odometry);
    pushScan(h, t, sim, *r);
    h.runUntilIdle();
  }
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("scans_unusable")) == 5);
  CHECK(std::get<std::int64_t>(s.at("scans_read")) == 6);
  CHECK(h.publishedCount("pose") == 3);  // from the first usable scan on
  CHECK(h.publishedCount("submaps") == 1);
}

TEST_CASE("submap builder starts a new submap when the robot enters another camera",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.camera_trigger = true;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  const auto event = [&](int camera, bool entered) {
    h.push<msg::CameraEvent>("camera_events", [&](auto& b) {
      setHeader(b.initHeader(), 0, "camera", 0);
      b.setCameraId(camera);
      b.setEntered(entered);
    });
  };
  for (std::size_t k = 0; k < 30; ++k) {
    if (k == 10) event(3, true);
    if (k == 15) event(3, false);
    if (k == 18) event(3, true);  // back in the same view: no new submap
    if (k == 22) event(5, true);
    const Nanos t = stampOf(sim.scans[k].stamp_s);
    pushOdometry(h, t, sim.scans[k].odometry);
    pushScan(h, t, sim, sim.scans[k].ranges);
    h.runUntilIdle();
  }
  h.stop();
  CHECK(h.publishedCount("constraints") == 2);
  CHECK(h.publishedCount("submaps") == 3);
}

TEST_CASE("submap builder rejects bad options naming the key", "[rbpf][submap_builder]") {
  SubmapBuilderOptions o;
  o.rbpf.particles = 0;
  CHECK_THROWS_WITH(SubmapBuilderActor(o), Catch::Contains("particles"));
  o = {};
  o.submap_distance = -1;
  CHECK_THROWS_WITH(SubmapBuilderActor(o), Catch::Contains("submap_distance"));
  o = {};
  o.loop_scan_every = -2;
  CHECK_THROWS_WITH(SubmapBuilderActor(o), Catch::Contains("loop_scan_every"));
}

TEST_CASE("loop_scan_every republishes every n-th scan that got a pose, and only those",
          "[rbpf][submap_builder]") {
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.loop_scan_every = 5;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  feedAndStop(h, sim, 60);
  const auto poses = h.published<msg::PoseStamped>("chained_pose");
  const auto scans = h.published<msg::LaserScan>("loop_scans");
  REQUIRE(poses.size() == 60);
  REQUIRE(scans.size() == 12);
  for (std::size_t k = 0; k < scans.size(); ++k)
    CHECK(scans[k]->getHeader().getStampNs() == poses[5 * k + 4]->getHeader().getStampNs());
  // Off by default: nothing on loop_scans.
  ActorHarness off(std::make_unique<SubmapBuilderActor>(fastOptions()));
  feedAndStop(off, sim, 10);
  CHECK(off.publishedCount("loop_scans") == 0);
}

TEST_CASE("map assembler draws submaps at their global poses", "[map_assembler]") {
  // Submap: 20 x 10 free cells at 0.1 m with one occupied cell at (15, 5) = (1.55, 0.55) m.
  tessera::grid::OccupancyMap grid;
  grid.resolution = 0.1;
  grid.width = 20;
  grid.height = 10;
  grid.cells.assign(200, 0);
  grid.at(15, 5) = 100;
  MapAssembler assembler;
  CHECK(assembler.assemble().empty());
  assembler.setSubmap(0, grid);
  assembler.setSubmap(1, grid);
  CHECK(assembler.assemble().empty());  // nothing placed yet
  assembler.setPose(0, Pose2{});
  assembler.setPose(1, Pose2(5.0, 0.0, std::numbers::pi / 2));
  const auto map = assembler.assemble();
  REQUIRE_FALSE(map.empty());
  CHECK(map.resolution == Approx(0.1));
  const auto valueAt = [&](double x, double y) {
    const auto c = map.cellOf({x, y});
    REQUIRE(map.contains(c.x(), c.y()));
    return map.at(c.x(), c.y());
  };
  CHECK(valueAt(1.55, 0.55) > 90);
  CHECK(valueAt(0.55, 0.55) < 10);
  // Submap 1 is turned by 90 degrees: its obstacle lands at (5 - 0.55, 1.55).
  CHECK(valueAt(5.0 - 0.55, 1.55) > 90);
  CHECK(valueAt(5.0 - 0.55, 0.55) < 10);
  CHECK(valueAt(3.0, 0.5) == -1);  // between the two: never seen
  tessera::grid::OccupancyMap bad = grid;
  bad.cells.pop_back();
  CHECK_THROWS_WITH(assembler.setSubmap(2, bad), Catch::Contains("submap 2"));
  tessera::grid::OccupancyMap nan_origin = grid;
  nan_origin.origin.x = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(assembler.setSubmap(3, nan_origin), Catch::Contains("origin"));
  CHECK_THROWS_WITH(assembler.setPose(1, Pose2(std::numeric_limits<double>::infinity(), 0, 0)),
                    Catch::Contains("non-finite"));
  CHECK(assembler.pose(1).x == 5.0);  // unchanged
}

TEST_CASE("map assembler keeps submaps packed and gives back their exact cells",
          "[map_assembler]") {
  // Mostly unknown, a free strip and a wall: compresses well, and every value must come back.
  tessera::grid::OccupancyMap grid;
  grid.resolution = 0.05;
  grid.width = 200;
  grid.height = 150;
  grid.origin = Pose2(-1.0, 2.0, 0.25);
  grid.cells.assign(200 * 150, tessera::grid::OccupancyMap::kUnknown);
  for (int r = 40; r < 90; ++r)
    for (int c = 0; c < 200; ++c) grid.at(c, r) = static_cast<std::int8_t>(r == 89 ? 100 : c % 7);
  MapAssembler assembler;
  CHECK(assembler.bytes() == 0);
  CHECK_FALSE(assembler.grid(0).has_value());  // no such submap
  assembler.setSubmap(0, grid);
  CHECK(assembler.bytes() > 0);
  CHECK(assembler.bytes() * 10 < grid.cells.size());
  const auto back = assembler.grid(0);
  REQUIRE(back.has_value());
  CHECK(back->width == grid.width);
  CHECK(back->height == grid.height);
  CHECK(back->resolution == grid.resolution);
  CHECK(back->origin.x == grid.origin.x);
  CHECK(back->origin.theta == grid.origin.theta);
  CHECK(back->cells == grid.cells);
  assembler.setPose(1, Pose2{});  // a pose without cells: no grid, not drawn
  CHECK_FALSE(assembler.grid(1).has_value());
  assembler.setPose(0, Pose2(1.0, -0.5, 0.1));
  const auto map = assembler.assemble();  // drawn from the packed cells
  REQUIRE_FALSE(map.empty());
  const auto valueAt = [&](int col, int row) {
    const auto c = map.cellOf(Pose2(1.0, -0.5, 0.1) * grid.cellCenter(col, row));
    REQUIRE(map.contains(c.x(), c.y()));
    return map.at(c.x(), c.y());
  };
  CHECK(valueAt(100, 89) > 90);  // the wall
  CHECK(valueAt(100, 60) < 10);  // the free strip
  CHECK(valueAt(100, 10) == -1);
}

TEST_CASE("map assembler actor chains hand-over constraints", "[map_assembler]") {
  ActorHarness h(
      std::make_unique<laser_slam::MapAssemblerActor>(laser_slam::MapAssemblerOptions{}));
  const auto submap = [&](int id, const Pose2& carried) {
    h.push<msg::Submap>("submaps", [&](auto& b) {
      setHeader(b.initHeader(), id, "map", 0);
      b.setId(static_cast<std::uint32_t>(id));
      auto g = b.initGrid();
      g.setResolution(0.1f);
      g.setWidth(4);
      g.setHeight(4);
      writePose(g.initOrigin(), tessera::Pose2{0, 0, 0});
      auto cells = mutableViewInt8(g.initCells(16));
      std::fill(cells.begin(), cells.end(), std::int8_t{0});
      cells[5] = 100;
      writePose(b.initGlobalPose(), tessera::Pose2{carried.x, carried.y, carried.theta});
      b.setFinished(true);
    });
  };
  submap(0, Pose2{});
  h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
    b.setFromId(0);
    b.setToId(1);
    writePose(b.initRelative(), tessera::Pose2{2.0, 1.0, 0.0});
    b.setKind(msg::SubmapConstraint::Kind::HAND_OVER);
  });
  submap(1, Pose2(9.0, 9.0, 0.0));  // the chained pose wins over what the message carries
  h.runUntilIdle();
  auto& actor = static_cast<laser_slam::MapAssemblerActor&>(h.actor());
  CHECK(actor.assembler().pose(1).x == Approx(2.0));
  CHECK(actor.assembler().pose(1).y == Approx(1.0));
  // A malformed submap (cells do not match width x height) is reported and left out.
  h.push<msg::Submap>("submaps", [&](auto& b) {
    b.setId(2);
    auto g = b.initGrid();
    g.setResolution(0.1f);
    g.setWidth(4);
    g.setHeight(4);
    g.initCells(3);
  });
  h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
    b.setFromId(1);
    b.setToId(2);
    writePose(b.initRelative(), tessera::Pose2{std::numeric_limits<double>::quiet_NaN(), 0.0, 0.0});
    b.setKind(msg::SubmapConstraint::Kind::HAND_OVER);
  });
  h.runUntilIdle();
  Summary summary;
  h.actor().summarize(summary);
  CHECK(std::get<std::int64_t>(summary.at("submaps_rejected")) == 1);
  CHECK(std::get<std::int64_t>(summary.at("constraints_rejected")) == 1);
  CHECK(std::get<std::int64_t>(summary.at("submaps_received")) == 2);
  h.stop();
  const auto maps = h.published<msg::OccupancyGrid>("map");
  REQUIRE(maps.size() == 1);
  CHECK(maps[0]->getWidth() == 24);  // 0..2.4 m at 0.1 m
  CHECK(maps[0]->getHeight() == 14);
}

TEST_CASE("the particles' map memory is reported, its peak never below the final figure",
          "[rbpf][submap_builder]") {
  // Fewer updates than the peak's sampling period and no submap closed: the peak must still
  // cover the maps held at stop.
  const auto sim = test::simulateRoomLoop();
  SubmapBuilderOptions o = fastOptions();
  o.rbpf.parallel = false;
  ActorHarness h(std::make_unique<SubmapBuilderActor>(o));
  feedAndStop(h, sim, 4);
  Summary s;
  h.actor().summarize(s);
  REQUIRE(std::get<std::int64_t>(s.at("scans_processed")) <
          static_cast<std::int64_t>(tessera::laser_slam::Rbpf::kMapBytesEvery));
  const double now = std::get<double>(s.at("memory_mb"));
  CHECK(now > 0);
  CHECK(std::get<double>(s.at("memory_peak_mb")) >= now);
}
