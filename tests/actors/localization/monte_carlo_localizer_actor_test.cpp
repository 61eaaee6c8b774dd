// Tests for the monte_carlo_localizer actor through the mock-mailbox harness: tracking on a map
// file, global localisation on a map topic, a restart from initial_pose, bad input.
#include <tessera/localization/monte_carlo_localizer_actor.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>

#include "toy_room.hpp"

using namespace tessera;
using localization::MonteCarloLocalizerActor;
using localization::MonteCarloLocalizerActorOptions;

namespace {

namespace fs = std::filesystem;

constexpr int kBeams = 180;
constexpr double kRangeMax = 8.0;
const Pose2 kMount(0.15, 0.0, 0.0);  // laser 15 cm ahead of base_link

Nanos stampOf(double s) {
  return static_cast<Nanos>(std::llround(s * 1e9));
}

void pushOdom(ActorHarness& h, double t, const Pose2& p) {
  h.push<msg::Odometry>("odom", [&](auto& b) {
    setHeader(b.initHeader(), stampOf(t), "odom", 0);
    b.setChildFrameId("base_link");
    writePose(b.initPose(), p);
  });
}

void pushScan(ActorHarness& h, double t, const std::vector<double>& ranges,
              float increment = static_cast<float>(2 * std::numbers::pi / kBeams)) {
  h.push<msg::LaserScan>("scan", [&](auto& b) {
    setHeader(b.initHeader(), stampOf(t), "laser", 0);
    b.setAngleMin(static_cast<float>(-std::numbers::pi));
    b.setAngleIncrement(increment);
    b.setRangeMin(0.05f);
    b.setRangeMax(static_cast<float>(kRangeMax));
    b.setMountX(static_cast<float>(kMount.x));
    b.setMountY(static_cast<float>(kMount.y));
    b.setMountTheta(static_cast<float>(kMount.theta));
    auto r = b.initRanges(static_cast<unsigned>(ranges.size()));
    for (unsigned i = 0; i < ranges.size(); ++i) r.set(i, static_cast<float>(ranges[i]));
  });
}

void pushMap(ActorHarness& h, const grid::OccupancyMap& m, std::size_t cells) {
  h.push<msg::OccupancyGrid>("map", [&](auto& b) {
    setHeader(b.initHeader(), 0, "map", 0);
    b.setResolution(static_cast<float>(m.resolution));
    b.setWidth(static_cast<std::uint32_t>(m.width));
    b.setHeight(static_cast<std::uint32_t>(m.height));
    writePose(b.initOrigin(), m.origin);
    auto data = b.initCells(static_cast<unsigned>(cells));
    for (std::size_t i = 0; i < cells && i < m.cells.size(); ++i)
      data[i] = static_cast<std::uint8_t>(m.cells[i]);
  });
}

struct Drive {
  double mean_error = 0;      ///< over the localized poses after the first `settle` metres
  double travel_to_fix = -1;  ///< [m] travelled until every later pose is within 0.3 m
  std::size_t poses = 0;
};

/// Drives the toy route: odometry at 5 steps per 10 cm (with 5 % / 2 % noise, in an odom frame
/// offset from the map), a scan stamped between two odometry poses every 10 cm; scores the
/// localized poses against the truth at their stamps.
Drive drive(ActorHarness& h, std::size_t steps, double settle_m, std::uint64_t seed = 1) {
  const grid::OccupancyMap room = test::toyRoom();
  const auto route = test::toyRoute();
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  Pose2 odom(0.5, -0.3, 0.2);
  std::vector<Pose2> truth_at_scan;
  double t = 0;
  pushOdom(h, t, odom);
  for (std::size_t i = 1; i < std::min(steps, route.size()); ++i) {
    const Pose2 d = between(route[i - 1], route[i]);
    const Pose2 noisy(d.x * (1 + 0.05 * n01(rng)), d.y * (1 + 0.05 * n01(rng)),
                      d.theta * (1 + 0.02 * n01(rng)) + 0.01 * n01(rng));
    for (int k = 1; k <= 5; ++k) {
      // Five odometry poses along the step; the scan falls between the 2nd and 3rd.
      odom = odom * Pose2(noisy.x / 5, noisy.y / 5, noisy.theta / 5);
      t += 0.02;
      pushOdom(h, t, odom);
      if (k == 2) {
        const Pose2 at = interpolate(route[i - 1], route[i], 0.3);  // odometry at 1.5 / 5
        pushScan(h, t - 0.01, test::toyRanges(room, at * kMount, kBeams, kRangeMax, rng));
        truth_at_scan.push_back(at);
      }
    }
    h.runUntilIdle();
  }
  h.runUntilIdle();
  const auto poses = h.published<msg::PoseStamped>("localized_pose");
  Drive out;
  out.poses = poses.size();
  double sum = 0;
  int counted = 0;
  for (const auto& p : poses) {
    // Scan j was stamped at 0.1 j + 0.03 s.
    const auto j = static_cast<std::size_t>(
        std::llround((static_cast<double>(p->getHeader().getStampNs()) * 1e-9 - 0.03) / 0.1));
    REQUIRE(j < truth_at_scan.size());
    const Pose2 e = toPose2(p->getPose()), g = truth_at_scan[j];
    REQUIRE(e.isFinite());
    const double err = std::hypot(e.x - g.x, e.y - g.y), travelled = 0.1 * static_cast<double>(j);
    if (err > 0.3)
      out.travel_to_fix = -1;
    else if (out.travel_to_fix < 0)
      out.travel_to_fix = travelled;
    if (travelled >= settle_m) {
      sum += err;
      ++counted;
    }
  }
  out.mean_error = counted > 0 ? sum / counted : std::numeric_limits<double>::infinity();
  return out;
}

fs::path tempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_mcl_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

template <class T>
T summaryValue(Actor& a, const std::string& key) {
  Summary s;
  a.summarize(s);
  const auto it = s.find(key);
  if (it == s.end()) return T{};
  return std::get<T>(it->second);
}

}  // namespace

TEST_CASE("monte_carlo_localizer tracks on a map file from its initial pose",
          "[localization][mcl_actor]") {
  const fs::path dir = tempDir("track");
  mapping::saveMap(test::toyRoom(), dir / "room");
  const Pose2 start = test::toyRoute().front();
  MonteCarloLocalizerActorOptions o;
  o.map_file = (dir / "room.yaml").string();
  o.initial = {start.x + 0.1, start.y - 0.1, start.theta + 0.05, 0.2, 0.1};
  ActorHarness h(std::make_unique<MonteCarloLocalizerActor>(o));
  const Drive d = drive(h, 200, 1.0);
  INFO("mean error " << d.mean_error << " m over " << d.poses << " poses");
  CHECK(d.mean_error < 0.05);
  CHECK(d.travel_to_fix == 0.0);
  const auto updates = summaryValue<std::int64_t>(h.actor(), "updates");
  CHECK(updates > 50);
  CHECK(d.poses == static_cast<std::size_t>(updates));  // one pose per filter update
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_input") == 0);
  CHECK(summaryValue<std::int64_t>(h.actor(), "particles_min") >= 500);
  CHECK(summaryValue<double>(h.actor(), "update_ms_p95") > 0);

  // map_to_odom ⊕ the odometry pose of the last update = its localized pose.
  const auto poses = h.published<msg::PoseStamped>("localized_pose");
  const auto corrections = h.published<msg::PoseStamped>("map_to_odom");
  REQUIRE(corrections.size() == poses.size());
  REQUIRE(poses.back()->getPose().getCovariance().size() == 9);
  CHECK(poses.back()->getHeader().getFrameId() == "map");
  const auto& mcl = *dynamic_cast<MonteCarloLocalizerActor&>(h.actor()).localizer();
  const Pose2 via = toPose2(corrections.back()->getPose()) * mcl.estimate().odom;
  const Pose2 last = toPose2(poses.back()->getPose());
  CHECK(via.x == Approx(last.x).margin(1e-9));
  CHECK(via.y == Approx(last.y).margin(1e-9));
  CHECK(angleDiff(via.theta, last.theta) == Approx(0).margin(1e-9));
  fs::remove_all(dir);
}

TEST_CASE("monte_carlo_localizer localises globally on a map topic, and keeps going on a new map",
          "[localization][mcl_actor]") {
  MonteCarloLocalizerActorOptions o;
  o.global = true;
  o.mcl.max_particles = 5000;
  o.pose_every_scan = true;
  ActorHarness h(std::make_unique<MonteCarloLocalizerActor>(o));
  const grid::OccupancyMap room = test::toyRoom();
  pushMap(h, room, room.cells.size());
  h.runUntilIdle();
  const Drive first = drive(h, 120, 6.0);
  INFO("fixed after " << first.travel_to_fix << " m; then " << first.mean_error << " m");
  REQUIRE(first.travel_to_fix >= 0);
  CHECK(first.travel_to_fix < 5.0);
  CHECK(first.mean_error < 0.1);
  // pose_every_scan: a pose per scan, more than there are updates.
  CHECK(first.poses == 119);
  CHECK(summaryValue<std::int64_t>(h.actor(), "updates") < 119);
  CHECK(summaryValue<std::string>(h.actor(), "map_source") == "topic");

  // A new map (the same room, as a re-published SLAM map) replaces the field, not the particles.
  pushMap(h, room, room.cells.size());
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "maps_received") == 2);
  const auto& mcl = *dynamic_cast<MonteCarloLocalizerActor&>(h.actor()).localizer();
  const Pose2 kept = mcl.estimate().pose;
  const Pose2 truth = test::toyRoute()[118];
  CHECK(std::hypot(kept.x - truth.x, kept.y - truth.y) < 0.4);  // the last update: <= 0.2 m back
}

TEST_CASE("monte_carlo_localizer restarts at an initial_pose message",
          "[localization][mcl_actor]") {
  MonteCarloLocalizerActorOptions o;
  o.initial = {9.0, 7.0, 1.0, 0.1, 0.05};  // far from where the robot is
  o.mcl.recovery_alpha_slow = 0;           // no random particles: only the message can help
  o.initial_pose_topic = true;
  ActorHarness h(std::make_unique<MonteCarloLocalizerActor>(o));
  const grid::OccupancyMap room = test::toyRoom();
  pushMap(h, room, room.cells.size());
  const Pose2 start = test::toyRoute().front();
  h.push<msg::PoseStamped>("initial_pose", [&](auto& b) {
    setHeader(b.initHeader(), 0, "map", 0);
    const Eigen::Matrix3d cov = Eigen::Vector3d(0.04, 0.04, 0.01).asDiagonal();
    writePose(b.initPose(), Pose2(start.x + 0.1, start.y, start.theta), &cov);
  });
  h.runUntilIdle();
  const Drive d = drive(h, 100, 1.0);
  CHECK(d.travel_to_fix == 0.0);
  CHECK(d.mean_error < 0.05);
  CHECK(summaryValue<std::int64_t>(h.actor(), "initial_poses") == 1);
}

TEST_CASE("monte_carlo_localizer counts and skips bad input, never publishing NaN",
          "[localization][mcl_actor]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const grid::OccupancyMap room = test::toyRoom();
  const Pose2 start = test::toyRoute().front();
  MonteCarloLocalizerActorOptions o;
  o.initial = {start.x, start.y, start.theta, 0.05, 0.02};
  o.initial_pose_topic = true;
  ActorHarness h(std::make_unique<MonteCarloLocalizerActor>(o));
  std::mt19937_64 rng(5);
  const auto good = test::toyRanges(room, start * kMount, kBeams, kRangeMax, rng);

  pushOdom(h, 0.0, Pose2());
  pushOdom(h, 0.1, Pose2());
  pushScan(h, 0.05, good);  // before any map
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_scan_no_map") == 1);

  pushMap(h, room, room.cells.size() - 7);  // wrong size
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_map_invalid") == 1);
  grid::OccupancyMap nan_origin = room;
  nan_origin.origin = Pose2(nan, 0, 0);
  pushMap(h, nan_origin, room.cells.size());
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_map_invalid") == 2);
  pushMap(h, room, room.cells.size());
  h.runUntilIdle();

  pushOdom(h, 0.2, Pose2(nan, 0, 0));  // NaN odometry
  pushOdom(h, 0.3, Pose2());
  pushScan(h, 0.21, {});                                             // empty
  pushScan(h, 0.22, std::vector<double>(kBeams, nan));               // all NaN
  pushScan(h, 0.23, std::vector<double>(kBeams, 50.0));              // all beyond range
  pushScan(h, 0.24, good, std::numeric_limits<float>::quiet_NaN());  // bad increment
  pushScan(h, 0.25, good, 0.0f);                                     // zero increment
  h.push<msg::PoseStamped>("initial_pose", [&](auto& b) {            // NaN start
    setHeader(b.initHeader(), 0, "map", 0);
    writePose(b.initPose(), Pose2(nan, 1, 0));
  });
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_odom_invalid") == 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_scan_empty") == 3);
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_scan_fields") == 2);
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_initial_pose_invalid") == 1);
  CHECK(h.publishedCount("localized_pose") == 0);

  // A scan much older than the odometry history cannot be paired.
  for (int k = 0; k < 600; ++k) {
    pushOdom(h, 1.0 + 0.01 * k, Pose2());
    h.runUntilIdle();
  }
  pushScan(h, 0.5, good);
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_scan_no_pose") == 1);

  // A scan with some NaN and out-of-range beams still localises; nothing published is NaN.
  auto mixed = good;
  for (std::size_t i = 0; i < mixed.size(); i += 3) mixed[i] = nan;
  mixed[1] = 0.01;  // below rangeMin
  pushScan(h, 6.0, mixed);
  pushOdom(h, 6.1, Pose2());
  h.runUntilIdle();
  const auto poses = h.published<msg::PoseStamped>("localized_pose");
  REQUIRE(poses.size() == 1);
  const Pose2 p = toPose2(poses[0]->getPose());
  REQUIRE(p.isFinite());
  CHECK(std::hypot(p.x - start.x, p.y - start.y) < 0.1);
  for (const double c : poses[0]->getPose().getCovariance()) CHECK(std::isfinite(c));
  CHECK(summaryValue<std::int64_t>(h.actor(), "beams_dropped") > 60);
}

TEST_CASE("monte_carlo_localizer refuses a missing or malformed map file and bad options",
          "[localization][mcl_actor]") {
  const fs::path dir = tempDir("bad_files");
  MonteCarloLocalizerActorOptions o;
  o.map_file = (dir / "missing.yaml").string();
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(o), Catch::Contains("missing.yaml"));
  std::ofstream(dir / "broken.yaml") << "image: [unclosed\n";
  o.map_file = (dir / "broken.yaml").string();
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(o), Catch::Contains("broken.yaml"));
  std::ofstream(dir / "no_image.yaml") << "image: nothing.pgm\nresolution: 0.05\n"
                                          "origin: [0, 0, 0]\n";
  o.map_file = (dir / "no_image.yaml").string();
  CHECK_THROWS_AS(MonteCarloLocalizerActor(o), ConfigError);
  std::ofstream(dir / "short.pgm") << "P5\n10 10\n255\n" << std::string(20, '\0');
  std::ofstream(dir / "short.yaml") << "image: short.pgm\nresolution: 0.05\n"
                                       "origin: [0, 0, 0]\n";
  o.map_file = (dir / "short.yaml").string();
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(o), Catch::Contains("short"));

  MonteCarloLocalizerActorOptions bad;
  bad.range_max = -1;
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(bad), Catch::Contains("range_max"));
  bad = {};
  bad.initial.sigma_xy = std::nan("");
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(bad), Catch::Contains("initial.sigma_xy"));
  bad = {};
  bad.mcl.max_particles = 10;
  CHECK_THROWS_WITH(MonteCarloLocalizerActor(bad), Catch::Contains("max_particles"));
  // Unknown keys in a profile are errors.
  CHECK_THROWS_AS(loadOptions<MonteCarloLocalizerActorOptions>(
                      Params(YAML::Load("{mcl: {particles: 10}}"), "test")),
                  ConfigError);
  fs::remove_all(dir);
}
