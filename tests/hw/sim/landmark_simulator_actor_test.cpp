#include <tessera/msg/landmark.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/landmark_simulator_actor.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>

using namespace tessera;
using tessera::sim::LandmarkSimulatorActor;
using tessera::sim::LandmarkSimulatorOptions;

namespace {

std::string configErrorOf(const LandmarkSimulatorOptions& o) {
  try {
    LandmarkSimulatorActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("LandmarkSimulatorActor: the seed 004 run", "[sim][actor][landmarks]") {
  LandmarkSimulatorOptions o;
  o.car.sigma_speed = 0;
  o.car.sigma_steer = 0;
  o.sensor.range_noise = 0;
  o.sensor.bearing_noise = 0;
  ActorHarness h(std::make_unique<LandmarkSimulatorActor>(o));
  h.advance(200 * kNanosPerSecond);

  const auto maps = h.published<msg::LandmarkMap>("landmark_map");
  REQUIRE(maps.size() == 1);
  REQUIRE(maps[0]->getLandmarks().size() == 27);
  CHECK(maps[0]->getHeader().getStampNs() == 0);

  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  const auto odom = h.published<msg::Odometry>("odom");
  const auto ctl = h.published<msg::DriveControl>("control");
  const auto scans = h.published<msg::LandmarkScan>("landmarks");
  REQUIRE(gt.size() > 3000);  // ~290 m at 3 m/s in 0.03 s steps
  CHECK(odom.size() == gt.size());
  CHECK(ctl.size() == gt.size() - 1);  // no control after the last waypoint
  CHECK(scans.size() == (gt.size() - 1) / 8 + 1);
  CHECK(gt[1]->getHeader().getStampNs() == 30'000'000);

  // Controls: speed 3, |steering| <= 30 deg, steps of at most 36 deg/s * 0.03 s; applying them
  // to ground-truth pose k gives pose k+1 (no noise).
  double prev = 0;
  for (std::size_t k = 0; k < ctl.size(); ++k) {
    const double g = ctl[k]->getSteering();
    CHECK(ctl[k]->getSpeed() == 3.0);
    CHECK(ctl[k]->getWheelbase() == 1.0);
    CHECK(ctl[k]->getDtS() == Approx(0.03));
    CHECK(std::abs(g) <= std::numbers::pi / 6 + 1e-12);
    CHECK(std::abs(g - prev) <= 0.2 * std::numbers::pi * 0.03 + 1e-12);
    prev = g;
    const tessera::Pose2 a = toPose2(gt[k]->getPose()), b = toPose2(gt[k + 1]->getPose());
    CHECK(b.x == Approx(a.x + 0.09 * std::cos(a.theta + g)));
    CHECK(b.y == Approx(a.y + 0.09 * std::sin(a.theta + g)));
  }
  // Observations match the geometry from the true pose at their stamp.
  const auto lms = maps[0]->getLandmarks();
  std::size_t checked = 0;
  for (std::size_t i = 0; i < scans.size(); i += 10) {
    const std::size_t k = i * 8;
    const tessera::Pose2 p = toPose2(gt[k]->getPose());
    CHECK(scans[i]->getHeader().getStampNs() == gt[k]->getHeader().getStampNs());
    for (const auto z : scans[i]->getObservations()) {
      const auto lm = lms[static_cast<unsigned>(z.getId())];
      CHECK(z.getRange() == Approx(std::hypot(lm.getX() - p.x, lm.getY() - p.y)));
      CHECK(z.getRange() <= 30.0);
      CHECK(std::abs(z.getBearing()) <= std::numbers::pi / 2 + 1e-9);
      ++checked;
    }
  }
  CHECK(checked > 50);

  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("route_completed")) == 1);
  CHECK(std::get<std::int64_t>(s.at("waypoints_reached")) == 14);
  CHECK(std::get<std::int64_t>(s.at("landmarks_seen")) == 27);
  CHECK(std::get<double>(s.at("odom_drift_m")) == 0.0);
}

TEST_CASE("LandmarkSimulatorActor: noisy controls drive the odometry, same seed same run",
          "[sim][actor][landmarks]") {
  LandmarkSimulatorOptions o;
  o.sensor.with_ids = false;
  auto run = [&](std::uint64_t seed) {
    o.seed = seed;
    ActorHarness h(std::make_unique<LandmarkSimulatorActor>(o));
    h.advance(20 * kNanosPerSecond);
    const auto odom = h.published<msg::Odometry>("odom");
    const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
    for (const auto& sc : h.published<msg::LandmarkScan>("landmarks"))
      for (const auto z : sc->getObservations()) CHECK(z.getId() == -1);
    return std::pair{toPose2(odom.back()->getPose()), toPose2(gt.back()->getPose())};
  };
  const auto [o1, t1] = run(3);
  const auto [o2, t2] = run(3);
  const auto [o3, t3] = run(4);
  CHECK(o1.x == o2.x);
  CHECK(o1.x != o3.x);
  CHECK(t1.x == t3.x);  // the truth does not depend on the noise
  CHECK(std::hypot(o1.x - t1.x, o1.y - t1.y) > 0.01);
}

TEST_CASE("LandmarkSimulatorActor: options from YAML, and bad options", "[sim][actor][landmarks]") {
  const auto o = loadOptions<LandmarkSimulatorOptions>(
      Params(YAML::Load("{speed: 2, observe_every: 1, sensor: {with_ids: false, mount: {y: 1}},"
                        " car: {max_steer: 0.4}}"),
             "test"));
  CHECK(o.speed == 2);
  CHECK_FALSE(o.sensor.with_ids);
  CHECK(o.sensor.mount.y == 1);
  CHECK(o.sensor.max_range == 30);  // default kept inside the group
  CHECK(o.car.max_steer == 0.4);
  // A flat key of earlier versions names its new place.
  CHECK_THROWS_WITH(
      loadOptions<LandmarkSimulatorOptions>(Params(YAML::Load("{landmark_max_range: 20}"), "test")),
      Catch::Contains("sensor.max_range"));
  CHECK_THROWS_WITH(
      loadOptions<LandmarkSimulatorOptions>(Params(YAML::Load("{max_steer_deg: 20}"), "test")),
      Catch::Contains("car.max_steer"));
  CHECK(ActorRegistry::instance().find("landmark_simulator") != nullptr);

  LandmarkSimulatorOptions b;
  b.step_s = 1e-10;
  CHECK(configErrorOf(b).find("step_s") != std::string::npos);
  b = {};
  b.car.max_steer = 1.6;
  CHECK(configErrorOf(b).find("option 'car.max_steer'") != std::string::npos);
  b = {};
  b.world = "builtin:office";  // no landmarks
  CHECK(configErrorOf(b).find("landmarks") != std::string::npos);
  b = {};
  b.route = {{10, 10}, {200, 10}};
  CHECK(configErrorOf(b).find("route") != std::string::npos);
  b = {};
  b.observe_every = 0;
  CHECK(configErrorOf(b).find("observe_every") != std::string::npos);
  b = {};
  b.sensor.mount.x = std::numeric_limits<double>::quiet_NaN();
  CHECK(configErrorOf(b).find("option 'sensor.mount'") != std::string::npos);
  b = {};
  b.sensor.max_range = -1;
  CHECK(configErrorOf(b).find("option 'sensor.max_range'") != std::string::npos);
}
