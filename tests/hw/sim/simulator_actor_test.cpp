#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/runtime/runtime.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/simulator_actor.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numbers>
#include <random>

using namespace tessera;
using tessera::sim::SimulatorActor;
using tessera::sim::SimulatorOptions;

namespace {

// A 5 m leg along the bottom corridor of the office: about 12 s of driving.
SimulatorOptions shortRun() {
  SimulatorOptions o;
  o.route = {{7.5, 7.5}, {12.5, 7.5}};
  return o;
}

std::unique_ptr<SimulatorActor> make(const SimulatorOptions& o) {
  return std::make_unique<SimulatorActor>(o);
}

// Advances in 1 s slices until the simulator stops publishing (it finished) or `limit_s`.
void runToEnd(ActorHarness& h, double limit_s) {
  std::size_t last = h.publishedCount("ground_truth");
  for (double t = 0; t < limit_s; t += 1.0) {
    h.advance(kNanosPerSecond);
    const std::size_t now = h.publishedCount("ground_truth");
    if (now == last) return;
    last = now;
  }
}

std::string configErrorOf(const SimulatorOptions& o) {
  try {
    SimulatorActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

SimulatorOptions optionsFromYaml(const std::string& yaml) {
  return loadOptions<SimulatorOptions>(Params(YAML::Load(yaml), "test"));
}

}  // namespace

TEST_CASE("SimulatorActor: publishes scans at 10 Hz, odometry at 50 Hz, ground truth with them",
          "[sim][actor]") {
  SimulatorOptions o = shortRun();
  ActorHarness h(make(o));
  h.advance(kNanosPerSecond);  // ticks at 0, 10 ms, ..., 1000 ms

  const auto scans = h.published<msg::LaserScan>("scan");
  const auto odom = h.published<msg::Odometry>("odom");
  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  REQUIRE(scans.size() == 11);
  REQUIRE(odom.size() == 51);
  REQUIRE(gt.size() == 51);  // every odometry or scan step; scan steps are odometry steps here

  std::map<std::int64_t, tessera::Pose2> truth;
  for (std::size_t i = 0; i < gt.size(); ++i) {
    const auto hdr = gt[i]->getHeader();
    CHECK(hdr.getStampNs() == static_cast<std::int64_t>(i) * 20'000'000);
    CHECK(hdr.getSeq() == i);
    CHECK(std::string(hdr.getFrameId().cStr()) == "map");
    CHECK(std::string(gt[i]->getChildFrameId().cStr()) == "base_link");
    truth[hdr.getStampNs()] = toPose2(gt[i]->getPose());
  }
  CHECK(truth.at(0).x == 7.5);
  CHECK(truth.at(0).y == 7.5);
  CHECK(truth.at(0).theta == 0.0);

  for (std::size_t i = 0; i < scans.size(); ++i) {
    const auto& s = *scans[i];
    const auto hdr = s.getHeader();
    CHECK(hdr.getStampNs() == static_cast<std::int64_t>(i) * 100'000'000);  // exact 10 Hz
    CHECK(hdr.getSeq() == i);
    CHECK(std::string(hdr.getFrameId().cStr()) == "laser");
    CHECK(truth.count(hdr.getStampNs()) == 1);  // a ground-truth pose with the same stamp
    CHECK(s.getRanges().size() == 181);
    CHECK(s.getAngleMin() == Approx(-std::numbers::pi / 2));
    CHECK(s.getAngleIncrement() == Approx(std::numbers::pi / 180));
    CHECK(s.getRangeMin() == Approx(0.05f));
    CHECK(s.getRangeMax() == Approx(30.0f));
    CHECK(s.getMountX() == 0.0f);
  }
  for (std::size_t i = 0; i < odom.size(); ++i) {
    const auto hdr = odom[i]->getHeader();
    CHECK(hdr.getStampNs() == static_cast<std::int64_t>(i) * 20'000'000);
    CHECK(std::string(hdr.getFrameId().cStr()) == "odom");
    CHECK(std::string(odom[i]->getChildFrameId().cStr()) == "base_link");
    CHECK(odom[i]->getTwistCovariance().size() == 9);
  }
  // The robot moves forward at no more than v_max, and odometry reports it.
  const tessera::Pose2 last = truth.rbegin()->second;
  CHECK(last.x > 7.6);
  CHECK(last.x <= 7.5 + 0.5 * 1.0 + 1e-9);
  CHECK(odom.back()->getTwist().getVx() > 0.1);
}

TEST_CASE("SimulatorActor: noiseless scans are ray casts from the true pose", "[sim][actor]") {
  SimulatorOptions o = shortRun();
  o.laser.range_noise = 0;
  o.laser.mount = {0.2, 0.0, 0.0};
  ActorHarness h(make(o));
  h.advance(secondsToNanos(3.0));
  const auto scans = h.published<msg::LaserScan>("scan");
  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  std::map<std::int64_t, tessera::Pose2> truth;
  for (const auto& g : gt) truth[g->getHeader().getStampNs()] = toPose2(g->getPose());

  const auto world = tessera::sim::World::builtinOffice();
  const tessera::sim::RayCaster rc(world);
  REQUIRE(scans.size() == 31);
  for (const auto& s : scans) {
    CHECK(s->getMountX() == Approx(0.2f));
    const tessera::Pose2 p = truth.at(s->getHeader().getStampNs());
    const Eigen::Vector2d laser(p.x + 0.2 * std::cos(p.theta), p.y + 0.2 * std::sin(p.theta));
    const auto ranges = view<float>(s->getRanges());
    for (std::size_t i = 0; i < ranges.size(); i += 10) {
      const double a = p.theta + s->getAngleMin() + i * static_cast<double>(s->getAngleIncrement());
      const double expected = rc.cast(laser, a, 30.0);
      if (std::isinf(expected))
        CHECK(std::isinf(ranges[i]));
      else
        CHECK(ranges[i] == Approx(expected).epsilon(1e-5));
    }
  }
}

TEST_CASE("SimulatorActor: odometry equals ground truth without noise and drifts with it",
          "[sim][actor]") {
  // A route with turns, so heading noise matters: along the corridor and into a room.
  SimulatorOptions o;
  o.route = {{7.5, 7.5}, {21.0, 7.5}, {21.0, 4.0}, {24.0, 2.5}};

  auto drive = [&](double sigma) {
    o.odometry.sigma_d = o.odometry.sigma_theta = sigma;
    auto h = std::make_unique<ActorHarness>(make(o));
    runToEnd(*h, 200);
    return h;
  };

  auto exact = drive(0.0);
  {
    const auto odom = exact->published<msg::Odometry>("odom");
    const auto gt = exact->published<msg::GroundTruthPose>("ground_truth");
    REQUIRE(odom.size() == gt.size());  // scan steps are odometry steps: one gt per odometry
    REQUIRE(odom.size() > 100);
    for (std::size_t i = 0; i < odom.size(); ++i) {
      REQUIRE(odom[i]->getHeader().getStampNs() == gt[i]->getHeader().getStampNs());
      const tessera::Pose2 a = toPose2(odom[i]->getPose()), b = toPose2(gt[i]->getPose());
      REQUIRE(a.x == b.x);
      REQUIRE(a.y == b.y);
      REQUIRE(a.theta == b.theta);
    }
    Summary s;
    exact->actor().summarize(s);
    CHECK(std::get<double>(s.at("odom_drift_m")) == 0.0);
  }

  auto noisy = drive(0.05);
  {
    const auto odom = noisy->published<msg::Odometry>("odom");
    const auto gt = noisy->published<msg::GroundTruthPose>("ground_truth");
    REQUIRE(odom.size() == gt.size());
    const tessera::Pose2 a = toPose2(odom.back()->getPose()), b = toPose2(gt.back()->getPose());
    const double drift = std::hypot(a.x - b.x, a.y - b.y);
    CHECK(drift > 1e-3);  // noise accumulates...
    CHECK(drift < 2.0);   // ...but stays plausible over ~22 m
    Summary s;
    noisy->actor().summarize(s);
    CHECK(std::get<double>(s.at("odom_drift_m")) == Approx(drift));
    // The reported covariance grows with the distance driven.
    Eigen::Matrix3d first, final;
    REQUIRE(readCovariance(odom[1]->getPose(), first));
    REQUIRE(readCovariance(odom.back()->getPose(), final));
    CHECK(final(0, 0) + final(1, 1) > 10 * (first(0, 0) + first(1, 1)));
  }
}

TEST_CASE("SimulatorActor: finishes after the route and then publishes nothing", "[sim][actor]") {
  SimulatorOptions o = shortRun();
  o.laps = 2;  // there and back: the open route is closed between laps
  ActorHarness h(make(o));
  runToEnd(h, 200);
  const std::size_t scans = h.publishedCount("scan");
  const std::size_t gts = h.publishedCount("ground_truth");
  h.advance(secondsToNanos(5.0));
  CHECK(h.publishedCount("scan") == scans);
  CHECK(h.publishedCount("ground_truth") == gts);
  CHECK(h.publishedCount("odom") > 0);

  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  const tessera::Pose2 end = toPose2(gt.back()->getPose());
  CHECK(std::hypot(end.x - 12.5, end.y - 7.5) < 0.15);  // lap 2 ends on the last waypoint

  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("route_completed")) == 1);
  CHECK(std::get<double>(s.at("route_length_m")) == Approx(15.0));
  CHECK(std::get<double>(s.at("distance_travelled_m")) == Approx(15.0).epsilon(0.05));
  CHECK(std::get<std::int64_t>(s.at("scans_published")) == static_cast<std::int64_t>(scans));
  CHECK(std::get<std::int64_t>(s.at("wall_contacts")) == 0);
  const double sim_time = std::get<double>(s.at("sim_time_s"));
  CHECK(sim_time > 15.0 / 0.5);
  CHECK(static_cast<double>(scans) == Approx(sim_time * 10 + 1).margin(1.0));
}

TEST_CASE("SimulatorActor: a run ends by itself when the route is done", "[sim][actor]") {
  RuntimeOptions ro;
  ro.threads = 1;
  ro.show_progress = false;
  ro.max_sim_duration = secondsToNanos(300);
  Runtime rt(ro);
  rt.add("sim", make(shortRun()));
  rt.configure();
  const RunReport report = rt.run();
  CHECK_FALSE(report.interrupted);
  CHECK(report.stop_reason == "all inputs finished");
  REQUIRE(report.actors.size() == 1);
  const Summary& s = report.actors[0].summary;
  CHECK(std::get<std::int64_t>(s.at("route_completed")) == 1);
  CHECK(std::get<std::int64_t>(s.at("scans_published")) > 100);
  CHECK(report.sim_duration_s < 60);
}

TEST_CASE("SimulatorActor: the default office route with default options", "[sim][actor]") {
  RuntimeOptions ro;
  ro.threads = 1;
  ro.show_progress = false;
  ro.max_sim_duration = secondsToNanos(1500);
  Runtime rt(ro);
  rt.add("sim", make(SimulatorOptions{}));
  rt.configure();
  const RunReport report = rt.run();
  CHECK(report.stop_reason == "all inputs finished");
  const Summary& s = report.actors.at(0).summary;
  const double length = std::get<double>(s.at("route_length_m"));
  const double sim_time = std::get<double>(s.at("sim_time_s"));
  CHECK(length > 150);
  CHECK(length < 250);
  CHECK(std::get<std::int64_t>(s.at("route_completed")) == 1);
  CHECK(std::get<std::int64_t>(s.at("wall_contacts")) == 0);
  CHECK(std::get<double>(s.at("distance_travelled_m")) == Approx(length).epsilon(0.02));
  CHECK(sim_time < 1.6 * length / 0.5);
  CHECK(std::get<std::int64_t>(s.at("scans_published")) ==
        static_cast<std::int64_t>(std::floor(sim_time * 10 + 1e-6)) + 1);
  // Default noise drifts noticeably over ~200 m (a mapper has something to correct), but not
  // absurdly.
  const double drift = std::get<double>(s.at("odom_drift_m"));
  CHECK(drift > 0.05);
  CHECK(drift < 10.0);
}

TEST_CASE("SimulatorActor: the same seed gives the same run", "[sim][actor]") {
  auto finalOdom = [](std::uint64_t seed) {
    SimulatorOptions o = shortRun();
    o.seed = seed;
    ActorHarness h(make(o));
    h.advance(secondsToNanos(5.0));
    const auto odom = h.published<msg::Odometry>("odom");
    const auto scans = h.published<msg::LaserScan>("scan");
    return std::pair{toPose2(odom.back()->getPose()).y, view<float>(scans.back()->getRanges())[90]};
  };
  CHECK(finalOdom(3) == finalOdom(3));
  CHECK(finalOdom(3).first != finalOdom(4).first);
  CHECK(finalOdom(3).second != finalOdom(4).second);
}

TEST_CASE("SimulatorActor: laser options", "[sim][actor]") {
  SimulatorOptions o = shortRun();
  o.laser.fov = 2 * std::numbers::pi;
  o.laser.beams = 720;
  o.laser.range_max = 4.0;
  o.laser.dropout = 1.0;
  o.scan_hz = 20;
  ActorHarness h(make(o));
  h.advance(secondsToNanos(0.5));
  const auto scans = h.published<msg::LaserScan>("scan");
  REQUIRE(scans.size() == 11);
  CHECK(scans[1]->getHeader().getStampNs() == 50'000'000);
  CHECK(scans[0]->getRanges().size() == 720);
  CHECK(scans[0]->getAngleMin() == Approx(-std::numbers::pi));
  CHECK(scans[0]->getAngleIncrement() == Approx(std::numbers::pi / 360));
  CHECK(scans[0]->getRangeMax() == Approx(4.0f));
  for (float r : view<float>(scans[0]->getRanges())) CHECK(std::isinf(r));  // all dropped
}

TEST_CASE("SimulatorActor: options from YAML and the registry", "[sim][actor][options]") {
  const SimulatorOptions o = optionsFromYaml(
      "{route: [[7.5, 7.5], [12, 7.5]], laps: 2, odometry: {sigma_d: 0.1}, seed: 9,"
      " laser: {beams: 361, mount: {x: 0.2}}, follower: {v_max: 0.3}}");
  REQUIRE(o.route.size() == 2);
  CHECK(o.route[1][0] == 12.0);
  CHECK(o.laps == 2);
  CHECK(o.odometry.sigma_d == 0.1);
  CHECK(o.odometry.sigma_theta == 0.05);  // default kept inside the group
  CHECK(o.laser.beams == 361);
  CHECK(o.laser.mount.x == 0.2);
  CHECK(o.laser.mount.theta == 0);
  CHECK(o.follower.v_max == 0.3);
  CHECK(o.seed == 9u);
  CHECK(o.scan_hz == 10);  // default kept

  CHECK_THROWS_AS(optionsFromYaml("{bogus: 1}"), ConfigError);
  CHECK_THROWS_AS(optionsFromYaml("{laps: many}"), ConfigError);
  // A flat key of earlier versions names its new place.
  CHECK_THROWS_WITH(optionsFromYaml("{laser_max_range: 4}"), Catch::Contains("laser.range_max"));
  CHECK_THROWS_WITH(optionsFromYaml("{odom_bias_d: 0.1}"), Catch::Contains("odometry.bias_d"));

  const auto* entry = ActorRegistry::instance().find("simulator");
  REQUIRE(entry != nullptr);
  const auto rows = entry->options();
  // 32 + base (2) + gyro (6) + encoders (9) + start_pause_s.
  CHECK(rows.size() == 50);
  for (const auto& row : rows) CHECK_FALSE(row[2].empty());  // every key documented
  auto actor = ActorRegistry::instance().create(
      "simulator", Params(YAML::Load("{route: [[7.5, 7.5], [12, 7.5]]}"), "test"));
  CHECK(dynamic_cast<SimulatorActor*>(actor.get()) != nullptr);
}

TEST_CASE("SimulatorActor: bad options are ConfigErrors that say what is wrong",
          "[sim][actor][options]") {
  auto with = [](auto change) {
    SimulatorOptions o = shortRun();
    change(o);
    return configErrorOf(o);
  };
  auto contains = [](const std::string& msg, const std::string& part) {
    INFO("message: " << msg);
    CHECK(msg.find(part) != std::string::npos);
  };

  SECTION("world") {
    contains(with([](auto& o) { o.world = "/nonexistent/floor.pgm"; }), "/nonexistent/floor.pgm");
    contains(with([](auto& o) { o.world = "/nonexistent/floor.pgm"; }), "not found");
    contains(with([](auto& o) { o.world = "builtin:moon"; }), "office");

    // A readable image world: zero resolution is refused, and it has no default route.
    const auto dir = std::filesystem::temp_directory_path() /
                     ("tessera_sim_test_" + std::to_string(std::random_device{}()));
    std::filesystem::create_directories(dir);
    const std::string pgm = (dir / "room.pgm").string();
    {
      std::ofstream f(pgm, std::ios::binary);
      f << "P5\n4 4\n255\n";
      for (int i = 0; i < 16; ++i) f.put(static_cast<char>(255));
    }
    contains(with([&](auto& o) {
               o.world = pgm;
               o.world_resolution = 0;
             }),
             "world_resolution");
    contains(with([&](auto& o) {
               o.world = pgm;
               o.route.clear();
             }),
             "no default route");
    const std::string text = (dir / "notes.pgm").string();
    std::ofstream(text) << "hello";
    contains(with([&](auto& o) { o.world = text; }), "not a readable image");
    std::filesystem::remove_all(dir);
  }

  SECTION("route") {
    contains(with([](auto& o) { o.route = {{7.5, 7.5}}; }), "at least two waypoints");
    const std::string in_wall = with([](auto& o) { o.route = {{7.5, 7.5}, {15, 8.5}}; });
    contains(in_wall, "option 'route'");
    contains(in_wall, "waypoint 1 at (15, 8.5) is inside a wall");
    contains(with([](auto& o) { o.route = {{7.5, 7.5}, {7.5, 7.5}, {9, 7.5}}; }), "coincide");
    contains(with([](auto& o) { o.route = {{12, 7.5}, {12, 3}}; }), "crosses a wall");
    contains(with([](auto& o) { o.laps = 0; }), "laps");
  }

  SECTION("rates") {
    contains(with([](auto& o) { o.step_hz = 0; }), "step_hz");
    contains(with([](auto& o) { o.step_hz = 300; }), "whole-nanosecond");
    contains(with([](auto& o) { o.scan_hz = 7; }), "must divide step_hz");
    contains(with([](auto& o) { o.odom_hz = -5; }), "odom_hz");
    contains(with([](auto& o) { o.scan_hz = 200; }), "scan_hz");
  }

  SECTION("robot and laser") {
    // Errors name the full dotted key.
    contains(with([](auto& o) { o.follower.v_max = 0; }), "option 'follower.v_max'");
    contains(with([](auto& o) { o.follower.w_max = -1; }), "option 'follower.w_max'");
    contains(with([](auto& o) { o.odometry.sigma_d = -0.1; }), "option 'odometry.sigma_d'");
    contains(with([](auto& o) { o.odometry.bias_theta = 0.7; }), "option 'odometry.bias_theta'");
    contains(with([](auto& o) { o.laser.beams = 0; }), "option 'laser.beams'");
    contains(with([](auto& o) { o.laser.fov = 0; }), "option 'laser.fov'");
    contains(with([](auto& o) { o.laser.dropout = 2; }), "option 'laser.dropout'");
    contains(with([](auto& o) { o.laser.range_max = 0.01; }), "option 'laser.range_max'");
    contains(with([](auto& o) { o.laser.range_min = -1; }), "option 'laser.range_min'");
    contains(with([](auto& o) { o.laser.range_noise = -0.01; }), "option 'laser.range_noise'");
    contains(with([](auto& o) {
               o.laser.mount = {0, 0, std::numeric_limits<double>::quiet_NaN()};
             }),
             "option 'laser.mount'");
  }
}

TEST_CASE("SimulatorActor: gyro and wheel encoders are off by default and publish when enabled",
          "[sim][actor][wheel_sensors]") {
  {
    ActorHarness h(make(shortRun()));
    h.advance(kNanosPerSecond);
    CHECK(h.publishedCount("imu") == 0);
    CHECK(h.publishedCount("wheel_ticks") == 0);
  }
  SimulatorOptions o = shortRun();
  o.gyro.enabled = true;
  o.encoders.enabled = true;
  o.encoders.slip = 0;
  o.gyro.bias_walk = 0;
  o.start_pause_s = 1.0;
  ActorHarness h(make(o));
  h.advance(secondsToNanos(3.0));
  const auto imu = h.published<msg::ImuSample>("imu");
  const auto ticks = h.published<msg::WheelTicks>("wheel_ticks");
  REQUIRE(imu.size() == 301);    // 100 Hz, from 0 s
  REQUIRE(ticks.size() == 151);  // 50 Hz
  std::map<std::int64_t, tessera::Pose2> truth;
  for (const auto& g : h.published<msg::GroundTruthPose>("ground_truth"))
    truth[g->getHeader().getStampNs()] = toPose2(g->getPose());
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const auto hdr = ticks[i]->getHeader();
    CHECK(hdr.getStampNs() == static_cast<std::int64_t>(i) * 20'000'000);
    CHECK(truth.count(hdr.getStampNs()) == 1);  // ground truth with every tick message
    CHECK(ticks[i]->getTicksPerRevolution() == o.encoders.ticks_per_revolution);
    CHECK(ticks[i]->getWheelRadius() == o.encoders.wheel_radius);
    CHECK(ticks[i]->getWheelBase() == o.encoders.wheel_base);
  }
  // Standing still for the first second: the counters do not move, the gyro reads its bias.
  CHECK(ticks[50]->getLeft() == 0);
  CHECK(ticks[50]->getRight() == 0);
  double mean = 0;
  for (std::size_t i = 0; i <= 100; ++i) mean += imu[i]->getAngularVelocityZ() / 101;
  // White noise 2.5e-4 / sqrt(0.01 s) = 2.5e-3 rad/s per sample: the mean's std is 2.5e-4.
  CHECK(mean == Approx(o.gyro.bias).margin(1e-3));
  for (std::size_t i = 0; i <= 100; ++i)
    CHECK(imu[i]->getLinearAccelerationX() == Approx(0).margin(0.1));
  // Then driving straight along the corridor: the counts follow the true distance through the
  // true (larger) wheels.
  const double distance = truth.rbegin()->second.x - 7.5;
  REQUIRE(distance > 0.2);
  const double per_metre = o.encoders.ticks_per_revolution / (2 * std::numbers::pi * 0.05);
  CHECK(ticks.back()->getLeft() ==
        Approx(distance * per_metre / (1 + o.encoders.left_radius_error)).margin(2));
  CHECK(ticks.back()->getRight() ==
        Approx(distance * per_metre / (1 + o.encoders.right_radius_error)).margin(2));
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("imu_published")) == 301);
  CHECK(std::get<std::int64_t>(s.at("wheel_ticks_published")) == 151);
}

TEST_CASE("SimulatorActor: the base follows the follower under its acceleration limits",
          "[sim][actor][wheel_sensors]") {
  SimulatorOptions o = shortRun();
  o.base.a_max = 0.1;  // slower than the follower's own 0.5 m/s^2
  ActorHarness h(make(o));
  h.advance(secondsToNanos(2.0));
  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  const double x = toPose2(gt.back()->getPose()).x - 7.5;
  // At most 0.1 m/s^2 from rest: 0.5 a t^2 = 0.2 m after 2 s; the follower alone would do 1 m.
  CHECK(x <= 0.1 * 0.01 * 0.01 * 200 * 201 / 2 + 1e-9);  // the discrete ramp
  CHECK(x > 0.9 * 0.5 * 0.1 * 4);
  const auto odom = h.published<msg::Odometry>("odom");
  CHECK(odom.back()->getTwist().getVx() == Approx(0.2).margin(0.01));
}

TEST_CASE("SimulatorActor: gyro, encoder and base options from YAML; bad ones named",
          "[sim][actor][wheel_sensors][options]") {
  const SimulatorOptions o = optionsFromYaml(
      "gyro: {enabled: true, rate_hz: 50, bias: 0.01}\n"
      "encoders: {enabled: true, ticks_per_revolution: 2048, left_radius_error: 0.01}\n"
      "base: {a_max: 0.3, alpha_max: 1.5}\nstart_pause_s: 2\n");
  CHECK(o.gyro.enabled);
  CHECK(o.gyro.rate_hz == 50);
  CHECK(o.gyro.bias == 0.01);
  CHECK(o.encoders.ticks_per_revolution == 2048);
  CHECK(o.encoders.left_radius_error == 0.01);
  CHECK(o.base.alpha_max == 1.5);
  CHECK(o.start_pause_s == 2);

  SimulatorOptions bad = shortRun();
  bad.gyro.enabled = true;
  bad.gyro.rate_hz = 30;  // does not divide 100
  CHECK_THAT(configErrorOf(bad), Catch::Contains("gyro.rate_hz"));
  bad = shortRun();
  bad.gyro.rate_hz = 30;  // off: not checked
  CHECK(configErrorOf(bad).empty());
  bad.encoders.slip = -1;
  CHECK_THAT(configErrorOf(bad), Catch::Contains("encoders.slip"));
  bad = shortRun();
  bad.base.a_max = -1;
  CHECK_THAT(configErrorOf(bad), Catch::Contains("base.a_max"));
  bad = shortRun();
  bad.start_pause_s = std::numeric_limits<double>::quiet_NaN();
  CHECK_THAT(configErrorOf(bad), Catch::Contains("start_pause_s"));
}
