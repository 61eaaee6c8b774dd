// Tests for the line_slam actor through the mock-mailbox harness.
#include <tessera/msg/lines.capnp.h>
#include <tessera/line_slam/line_slam_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

#include "../scan_messages.hpp"

using namespace tessera;
using line_slam::LineSlamActor;
using line_slam::LineSlamActorOptions;
using tessera::Pose2;
using test::pushOdometry;
using test::pushScan;
using test::stampOf;

namespace {

void pushTruth(ActorHarness& h, Nanos stamp, const Pose2& p) {
  h.push<msg::GroundTruthPose>("ground_truth", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
  });
}

}  // namespace

TEST_CASE("line_slam actor publishes a pose per scan and a line map, and scores itself",
          "[lines][line_slam_actor]") {
  const auto sim = test::simulateRoomLoop();
  LineSlamActorOptions o;
  o.ground_truth = true;
  o.map_every = 20;
  ActorHarness h(std::make_unique<LineSlamActor>(o));
  const std::size_t n = 120;
  for (std::size_t k = 0; k < n; ++k) {
    const Nanos t = stampOf(sim.scans[k].stamp_s);
    pushTruth(h, t, sim.scans[k].truth);
    pushOdometry(h, t, sim.scans[k].odometry);
    pushScan(h, t, sim, sim.scans[k].ranges);
    h.runUntilIdle();
  }
  // Bad scans: empty, all NaN; counted and skipped.
  pushScan(h, stampOf(100.0), sim, {});
  pushScan(h, stampOf(100.1), sim,
           std::vector<float>(181, std::numeric_limits<float>::quiet_NaN()));
  h.runUntilIdle();
  h.stop();

  const auto poses = h.published<msg::PoseStamped>("pose");
  CHECK(poses.size() == n);
  CHECK(poses.back()->getPose().getCovariance().size() == 9);
  const auto maps = h.published<msg::LineMap>("line_map");
  CHECK(maps.size() == n / 20 + 1);  // periodic, plus the one in stop()
  const auto last = maps.back();
  REQUIRE(last->getLines().size() > 5);
  for (const auto l : last->getLines()) {
    CHECK(l.getR() >= 0);
    CHECK(l.getCovariance().size() == 4);
  }

  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("scans_read")) == static_cast<std::int64_t>(n) + 2);
  CHECK(std::get<std::int64_t>(s.at("scans_rejected")) == 2);
  CHECK(std::get<std::int64_t>(s.at("scans_processed")) == static_cast<std::int64_t>(n));
  CHECK(std::get<std::int64_t>(s.at("lines")) ==
        static_cast<std::int64_t>(last->getLines().size()));
  CHECK(std::get<std::int64_t>(s.at("tentative_promoted")) > 0);
  const double err = std::get<double>(s.at("final_position_error_m"));
  const double odom_err =
      (sim.scans[n - 1].odometry.translation() - sim.scans[n - 1].truth.translation()).norm();
  INFO("slam " << err << " m, odometry " << odom_err << " m");
  CHECK(err < 0.1);
  CHECK(err < 0.5 * odom_err);
}

TEST_CASE("line_slam actor rejects bad options", "[lines][line_slam_actor]") {
  LineSlamActorOptions o;
  o.ekf.tentative_sightings = 0;
  CHECK_THROWS_WITH(LineSlamActor(o), Catch::Contains("ekf.tentative_sightings"));
  o = {};
  o.extractor.min_points = 0;
  CHECK_THROWS_WITH(LineSlamActor(o), Catch::Contains("extractor.min_points"));
  o = {};
  o.map_every = 0;
  CHECK_THROWS_AS(LineSlamActor(o), ConfigError);
}

TEST_CASE("line_slam options: groups extractor and ekf, association by name",
          "[lines][line_slam_actor][options]") {
  const auto load = [](const std::string& yaml) {
    return loadOptions<LineSlamActorOptions>(Params(YAML::Load(yaml), "test"));
  };
  const auto o = load(
      "extractor: {min_points: 10, merge_angle: 0.1}\n"
      "ekf: {association: threshold, merge_angle: 0.2}\nmin_travel: 0.1\n");
  CHECK(o.extractor.min_points == 10);
  CHECK(o.extractor.merge_angle == 0.1);
  CHECK(o.ekf.association == line_slam::Association::kThreshold);
  CHECK(o.ekf.merge_angle == 0.2);
  CHECK(o.min_travel == 0.1);
  CHECK_THROWS_WITH(load("ekf: {association: nearest}\n"), Catch::Contains("cost | threshold"));
  CHECK_THROWS_WITH(load("segment_merge_angle: 0.1\n"),
                    Catch::Contains("moved to extractor.merge_angle"));
  CHECK_THROWS_WITH(load("tentative_sightings: 1\n"),
                    Catch::Contains("moved to ekf.tentative_sightings"));
}
