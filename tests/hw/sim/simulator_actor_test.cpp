#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/runtime/runtime.hpp>
#include <tessera/sim/furniture.hpp>
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
  // The default body (0.2 m radius, 1 m tall) touches neither walls nor furniture on the way.
  CHECK(std::get<std::int64_t>(s.at("collisions")) == 0);
  CHECK(std::get<double>(s.at("min_clearance_m")) > 0.0);
  CHECK(s.count("watchdog_stops") == 0);  // route mode has no commands
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
  // 32 + base (2) + gyro (6) + encoders (9) + start_pause_s + drive, command_timeout_s,
  // start_pose and footprint (2), kidnap_at_s, kidnap_pose, kidnap_route_m and kidnap_turn.
  CHECK(rows.size() == 59);
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

// ---- drive: commands ----

namespace {

// A 6 m x 4 m room (one 0.05 m wall cell thick) with a 0.75 m table over [2, 3.5] x [1.5, 2.5]:
// 0.05 m legs at the corners, the top from 0.71 m to 0.75 m.
tessera::sim::World roomWithTable() {
  auto w = tessera::sim::World::box(6.0, 4.0, 0.05);
  w.addFurniture(tessera::sim::makeTable(2.0, 1.5, 3.5, 2.5));
  return w;
}

// Commands mode from (x, y, theta), noiseless odometry so its twist is the base's velocity.
SimulatorOptions commandsAt(double x, double y, double theta) {
  SimulatorOptions o;
  o.drive = "commands";
  o.start_pose = {x, y, theta};
  o.odometry.sigma_d = o.odometry.sigma_theta = 0;
  return o;
}

std::unique_ptr<SimulatorActor> inRoom(const SimulatorOptions& o) {
  return std::make_unique<SimulatorActor>(o, roomWithTable());
}

void command(ActorHarness& h, double vx, double omega) {
  h.push<msg::Twist>("cmd_vel", [&](auto& b) {
    setHeader(b.initHeader(), h.now(), "base_link", 0);
    b.initTwist().setVx(vx);
    b.getTwist().setVy(0.7);  // ignored: a differential drive has no lateral motion
    b.getTwist().setOmega(omega);
  });
}

// Sends (vx, omega) every 0.1 s for `seconds`, well within the watchdog's 0.5 s.
void keepCommanding(ActorHarness& h, double vx, double omega, double seconds) {
  const int n = static_cast<int>(std::lround(seconds * 10));
  for (int i = 0; i < n; ++i) {
    command(h, vx, omega);
    h.advance(secondsToNanos(0.1));
  }
}

tessera::Pose2 lastTruth(const ActorHarness& h) {
  return toPose2(h.published<msg::GroundTruthPose>("ground_truth").back()->getPose());
}

std::int64_t summaryInt(ActorHarness& h, const std::string& key) {
  Summary s;
  h.actor().summarize(s);
  return std::get<std::int64_t>(s.at(key));
}

double summaryDouble(ActorHarness& h, const std::string& key) {
  Summary s;
  h.actor().summarize(s);
  return std::get<double>(s.at(key));
}

}  // namespace

TEST_CASE("SimulatorActor commands: a constant cmd_vel drives along the heading at that speed",
          "[sim][actor][commands]") {
  ActorHarness h(inRoom(commandsAt(1.0, 1.0, 0.3)));
  h.advance(0);  // the start: step 0 at the start pose
  CHECK(lastTruth(h).x == 1.0);
  CHECK(lastTruth(h).y == 1.0);
  CHECK(lastTruth(h).theta == Approx(0.3));
  keepCommanding(h, 0.3, 0.0, 2.0);
  // 200 steps of 10 ms at 0.3 m/s (vy ignored), straight along theta = 0.3.
  const tessera::Pose2 p = lastTruth(h);
  CHECK(p.x == Approx(1.0 + 0.6 * std::cos(0.3)).margin(1e-9));
  CHECK(p.y == Approx(1.0 + 0.6 * std::sin(0.3)).margin(1e-9));
  CHECK(p.theta == Approx(0.3).margin(1e-12));
  CHECK(h.published<msg::Odometry>("odom").back()->getTwist().getVx() == Approx(0.3));
  CHECK(summaryInt(h, "commands_received") == 20);
  CHECK(summaryInt(h, "watchdog_stops") == 0);
  CHECK(summaryInt(h, "collisions") == 0);
  CHECK(summaryDouble(h, "distance_travelled_m") == Approx(0.6));
  // Scans and odometry at their usual rates, ground truth with them.
  CHECK(h.publishedCount("scan") == 21);
  CHECK(h.publishedCount("odom") == 101);
}

TEST_CASE("SimulatorActor commands: a kidnapping moves the true robot but not its odometry",
          "[sim][actor][commands]") {
  SimulatorOptions o = commandsAt(1.0, 1.0, 0.0);
  o.kidnap_at_s = 1.0;
  o.kidnap_pose = {4.5, 3.0, 3.0};
  ActorHarness h(inRoom(o));
  keepCommanding(h, 0.2, 0.0, 0.9);
  CHECK(lastTruth(h).x == Approx(1.0 + 0.2 * 0.9).margin(1e-9));
  CHECK(summaryInt(h, "kidnapped") == 0);
  keepCommanding(h, 0.2, 0.0, 1.1);
  // Carried at 1.0 s and stopped there; it then drives on at its new heading for 1.0 s less
  // the acceleration-free step it lost.
  const tessera::Pose2 p = lastTruth(h);
  CHECK(p.theta == Approx(3.0).margin(1e-9));
  CHECK(std::hypot(p.x - 4.5, p.y - 3.0) == Approx(0.2).margin(0.01));
  CHECK(summaryInt(h, "kidnapped") == 1);
  // The odometry went straight on along x as if nothing had happened.
  const auto odom = toPose2(h.published<msg::Odometry>("odom").back()->getPose());
  CHECK(odom.theta == Approx(0.0).margin(1e-9));
  CHECK(odom.x == Approx(1.0 + 0.2 * 2.0).margin(0.01));
}

TEST_CASE("SimulatorActor commands: the watchdog stops the base when commands stop coming",
          "[sim][actor][commands]") {
  SimulatorOptions o = commandsAt(1.0, 1.0, 0.0);
  o.command_timeout_s = 0.5;
  ActorHarness h(inRoom(o));
  command(h, 0.3, 0.2);
  h.advance(secondsToNanos(2.0));
  // Followed while at most 0.5 s old: the steps at 10, 20, ..., 500 ms; then (0, 0).
  const tessera::Pose2 p = lastTruth(h);
  CHECK(p.theta == Approx(50 * 0.2 * 0.01));
  CHECK(std::hypot(p.x - 1.0, p.y - 1.0) == Approx(50 * 0.3 * 0.01).epsilon(1e-3));
  const auto odom = h.published<msg::Odometry>("odom");
  CHECK(odom.back()->getTwist().getVx() == 0.0);
  CHECK(odom.back()->getTwist().getOmega() == 0.0);
  CHECK(summaryInt(h, "watchdog_stops") == 1);

  // Standing still it stays: the watchdog does not count again without a new command.
  h.advance(secondsToNanos(1.0));
  CHECK(lastTruth(h).x == p.x);
  CHECK(summaryInt(h, "watchdog_stops") == 1);
  // A new command drives again, and its silence engages the watchdog a second time.
  command(h, 0.3, 0.0);
  h.advance(secondsToNanos(1.0));
  CHECK(lastTruth(h).x > p.x + 0.1);
  CHECK(summaryInt(h, "watchdog_stops") == 2);
}

TEST_CASE("SimulatorActor commands: a non-finite command is ignored and counted",
          "[sim][actor][commands]") {
  ActorHarness h(inRoom(commandsAt(1.0, 1.0, 0.0)));
  command(h, 0.3, 0.0);
  h.advance(secondsToNanos(0.3));
  command(h, std::numeric_limits<double>::quiet_NaN(), 0.0);
  h.advance(secondsToNanos(0.1));
  // The previous command still drives: 40 steps at 0.3 m/s.
  CHECK(lastTruth(h).x == Approx(1.0 + 40 * 0.003));
  command(h, 0.3, std::numeric_limits<double>::infinity());
  h.advance(secondsToNanos(2.0));
  // Then the watchdog stops it 0.5 s after the last good command: 50 steps.
  const tessera::Pose2 p = lastTruth(h);
  CHECK(p.x == Approx(1.0 + 50 * 0.003));
  CHECK(p.y == 1.0);
  CHECK(p.theta == 0.0);
  for (const auto& gt : h.published<msg::GroundTruthPose>("ground_truth")) {
    const tessera::Pose2 q = toPose2(gt->getPose());
    REQUIRE((std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.theta)));
  }
  CHECK(summaryInt(h, "bad_commands") == 2);
  CHECK(summaryInt(h, "commands_received") == 3);
  CHECK(summaryInt(h, "watchdog_stops") == 1);
}

TEST_CASE("SimulatorActor commands: speeds above the follower's limits are clamped",
          "[sim][actor][commands]") {
  SimulatorOptions o = commandsAt(3.0, 1.0, 0.0);
  o.follower.v_max = 0.5;
  o.follower.w_max = 1.0;
  ActorHarness h(inRoom(o));
  keepCommanding(h, -2.0, 5.0, 1.0);  // backwards, turning left
  const auto odom = h.published<msg::Odometry>("odom");
  CHECK(odom.back()->getTwist().getVx() == Approx(-0.5));
  CHECK(odom.back()->getTwist().getOmega() == Approx(1.0));
  CHECK(lastTruth(h).theta == Approx(1.0));  // 1 s at 1 rad/s
  CHECK(summaryInt(h, "clamped_commands") == 10);
  keepCommanding(h, 0.2, -0.5, 0.5);  // within the limits
  CHECK(h.published<msg::Odometry>("odom").back()->getTwist().getVx() == Approx(0.2));
  CHECK(summaryInt(h, "clamped_commands") == 10);
}

TEST_CASE("SimulatorActor commands: the base follows them under its acceleration limits",
          "[sim][actor][commands]") {
  SimulatorOptions o = commandsAt(1.0, 2.0, 0.0);
  o.base.a_max = 0.2;
  o.base.alpha_max = 0.5;
  ActorHarness h(inRoom(o));
  keepCommanding(h, 0.4, 1.0, 1.0);
  // After 1 s the base has reached 0.2 m/s and 0.5 rad/s, not the commanded 0.4 and 1.0; odometry
  // reports the mean of the last two steps.
  const auto twist = h.published<msg::Odometry>("odom").back()->getTwist();
  CHECK(twist.getVx() == Approx((0.198 + 0.2) / 2));
  CHECK(twist.getOmega() == Approx((0.495 + 0.5) / 2));
  // The heading is the sum of the ramp: sum over k = 1..100 of 0.005 k * 0.01 s.
  CHECK(lastTruth(h).theta == Approx(0.005 * 0.01 * 5050));
  keepCommanding(h, 0.4, 1.0, 1.5);
  CHECK(h.published<msg::Odometry>("odom").back()->getTwist().getVx() == Approx(0.4));
}

TEST_CASE("SimulatorActor commands: without start_pose it starts on the route's start",
          "[sim][actor][commands]") {
  SimulatorOptions o;
  o.drive = "commands";
  o.route = {{7.5, 7.5}, {7.5, 12.0}};
  SimulatorActor a(o);
  CHECK(a.startPose().x == 7.5);
  CHECK(a.startPose().y == 7.5);
  CHECK(a.startPose().theta == Approx(std::numbers::pi / 2));
  o.route.clear();  // the office's default route
  SimulatorActor b(o);
  CHECK(b.startPose().x == 7.5);
  CHECK(b.startPose().theta == 0.0);
}

TEST_CASE("SimulatorActor commands: not a finite source, the run goes on without commands",
          "[sim][actor][commands]") {
  SimulatorOptions o = commandsAt(1.0, 1.0, 0.0);
  RuntimeOptions ro;
  ro.threads = 1;
  ro.show_progress = false;
  ro.max_sim_duration = secondsToNanos(3);
  Runtime rt(ro);
  rt.add("sim", inRoom(o));
  rt.configure(/*allow_unpublished=*/true);  // nobody publishes cmd_vel here
  CHECK(rt.subscriptionsOf("sim") == std::vector<std::string>{"cmd_vel"});
  const RunReport report = rt.run();
  CHECK(report.stop_reason == "reached max_duration_s");
  const Summary& s = report.actors.at(0).summary;
  CHECK(std::get<std::int64_t>(s.at("scans_published")) >= 30);
  CHECK(std::get<double>(s.at("distance_travelled_m")) == 0.0);
  CHECK(s.count("route_completed") == 0);

  // Route mode subscribes to nothing.
  ActorHarness route(make(shortRun()));
  CHECK(route.runtime().subscriptionsOf("actor_under_test").empty());
  CHECK_THROWS_AS(command(route, 0.3, 0.0), std::invalid_argument);
}

TEST_CASE("SimulatorActor: collisions with furniture depend on the body's height",
          "[sim][actor][commands][collision]") {
  // Driving along y = 2 under the table: 0.45 m from the legs, right under the top (0.71 m).
  auto drive = [](double height) {
    SimulatorOptions o = commandsAt(1.0, 2.0, 0.0);
    o.footprint.height = height;
    auto h = std::make_unique<ActorHarness>(inRoom(o));
    keepCommanding(*h, 0.3, 0.0, 6.0);  // to x = 2.8
    return h;
  };
  auto tall = drive(1.0);
  CHECK(lastTruth(*tall).x == Approx(2.8));
  CHECK(summaryInt(*tall, "collisions") == 1);
  // In contact from x = 1.8 (the top's edge at 2.0 minus the radius) on: ~1 m at 0.3 m/s.
  CHECK(summaryInt(*tall, "collision_steps") == Approx(100.0 / 0.3).margin(2));
  CHECK(summaryDouble(*tall, "min_clearance_m") == Approx(-0.2));
  CHECK(summaryInt(*tall, "wall_contacts") == 0);  // the laser's world has no table

  auto low = drive(0.5);  // below the top: only the legs count
  CHECK(summaryInt(*low, "collisions") == 0);
  CHECK(summaryInt(*low, "collision_steps") == 0);
  CHECK(summaryDouble(*low, "min_clearance_m") == Approx(0.45 - 0.2));
}

TEST_CASE("SimulatorActor: every contact episode counts once",
          "[sim][actor][commands][collision]") {
  ActorHarness h(inRoom(commandsAt(1.0, 2.0, 0.0)));
  keepCommanding(h, 0.3, 0.0, 4.0);   // under the table's edge, to x = 2.2
  keepCommanding(h, -0.3, 0.0, 3.0);  // back out, to x = 1.3
  CHECK(summaryInt(h, "collisions") == 1);
  keepCommanding(h, 0.3, 0.0, 3.0);  // in again
  CHECK(summaryInt(h, "collisions") == 2);
  // Into the east wall: x from 2.2 to ~5.8 at 0.3 m/s, the wall's inner face at 5.95.
  keepCommanding(h, 0.3, 0.0, 12.0);
  CHECK(summaryInt(h, "collisions") == 3);  // out from under the table, then the wall
  CHECK(summaryInt(h, "wall_contacts") == 0);
}

TEST_CASE("SimulatorActor: route mode counts collisions too", "[sim][actor][collision]") {
  SimulatorOptions o;
  o.route = {{1.0, 2.0}, {5.0, 2.0}};  // straight under the table top
  ActorHarness h(std::make_unique<SimulatorActor>(o, roomWithTable()));
  runToEnd(h, 60);
  CHECK(summaryInt(h, "route_completed") == 1);
  CHECK(summaryInt(h, "collisions") == 1);
  // In contact for x in (1.8, 3.7) at the follower's 0.5 m/s: 3.8 s.
  CHECK(summaryInt(h, "collision_steps") == Approx(380).margin(3));
}

TEST_CASE("SimulatorActor commands: options from YAML; bad ones are ConfigErrors naming them",
          "[sim][actor][commands][options]") {
  const SimulatorOptions o = optionsFromYaml(
      "{drive: commands, command_timeout_s: 0.25, start_pose: [7.5, 7.5, 1.0],"
      " footprint: {radius: 0.3, height: 0.6}}");
  CHECK(o.drive == "commands");
  CHECK(o.command_timeout_s == 0.25);
  CHECK(o.start_pose == std::vector<double>{7.5, 7.5, 1.0});
  CHECK(o.footprint.radius == 0.3);
  CHECK(o.footprint.height == 0.6);
  const SimulatorOptions d;
  CHECK(d.drive == "route");
  CHECK(d.command_timeout_s == 0.5);
  CHECK(d.start_pose.empty());
  CHECK(d.footprint.radius == 0.2);
  CHECK(d.footprint.height == 1.0);

  auto with = [](auto change) {
    SimulatorOptions c = commandsAt(7.5, 7.5, 0.0);  // in the office's bottom corridor
    change(c);
    return configErrorOf(c);
  };
  auto contains = [](const std::string& msg, const std::string& part) {
    INFO("message: " << msg);
    CHECK(msg.find(part) != std::string::npos);
  };
  CHECK(with([](auto&) {}).empty());
  const std::string fly = with([](auto& c) { c.drive = "fly"; });
  contains(fly, "simulator: option 'drive'");
  contains(fly, "'route' or 'commands'");
  contains(fly, "fly");
  const std::string in_wall = with([](auto& c) { c.start_pose = {15, 8.5, 0}; });  // a pillar
  contains(in_wall, "option 'start_pose'");
  contains(in_wall, "[15, 8.5, 0]");
  contains(in_wall, "in a wall");
  contains(with([](auto& c) { c.start_pose = {-1, 7.5, 0}; }), "outside world 'builtin:office'");
  const std::string two = with([](auto& c) { c.start_pose = {7.5, 7.5}; });
  contains(two, "option 'start_pose'");
  contains(two, "3 numbers");
  contains(with([](auto& c) {
             c.start_pose = {7.5, std::numeric_limits<double>::quiet_NaN(), 0};
           }),
           "option 'start_pose': must be finite");
  contains(with([](auto& c) { c.start_pose = {7.5, 7.5, 0, 1}; }), "3 numbers");
  contains(with([](auto& c) {
             c.drive = "route";  // a route starts on its first waypoint
           }),
           "option 'start_pose': is only used with drive: commands");
  const std::string kidnap_wall = with([](auto& c) {
    c.kidnap_at_s = 5;
    c.kidnap_pose = {15, 8.5, 0};
  });
  contains(kidnap_wall, "option 'kidnap_pose'");
  contains(kidnap_wall, "in a wall");
  contains(with([](auto& c) { c.kidnap_at_s = 5; }), "option 'kidnap_pose': must be 3 numbers");
  contains(with([](auto& c) { c.kidnap_at_s = std::numeric_limits<double>::quiet_NaN(); }),
           "option 'kidnap_at_s'");
  contains(with([](auto& c) {
             c.kidnap_pose = {7.5, 7.5, 0};
           }),
           "option 'kidnap_pose': is only used with kidnap_at_s > 0");
  contains(with([](auto& c) {
             c.drive = "route";
             c.start_pose.clear();
             c.kidnap_at_s = 5;
             c.kidnap_pose = {7.5, 7.5, 0};
           }),
           "option 'kidnap_pose': is only used with drive: commands");
  contains(with([](auto& c) {
             c.drive = "route";
             c.start_pose.clear();
             c.kidnap_at_s = 5;
           }),
           "option 'kidnap_route_m': must be the distance along the route");
  contains(with([](auto& c) {
             c.drive = "route";
             c.start_pose.clear();
             c.kidnap_at_s = 5;
             c.kidnap_route_m = 1e6;
           }),
           "option 'kidnap_route_m': is beyond the route's end");
  contains(with([](auto& c) {
             c.drive = "route";
             c.start_pose.clear();
             c.kidnap_at_s = 5;
             c.kidnap_route_m = 3;
             c.kidnap_turn = std::numeric_limits<double>::quiet_NaN();
           }),
           "option 'kidnap_turn': must be finite");
  contains(with([](auto& c) { c.kidnap_route_m = 3; }),
           "option 'kidnap_route_m': is only used with kidnap_at_s > 0");
  contains(with([](auto& c) {
             c.kidnap_at_s = 5;
             c.kidnap_pose = {7.5, 7.5, 0};
             c.kidnap_route_m = 3;
           }),
           "option 'kidnap_route_m': is only used with drive: route");
  contains(with([](auto& c) { c.command_timeout_s = 0; }), "option 'command_timeout_s'");
  contains(with([](auto& c) { c.command_timeout_s = std::numeric_limits<double>::quiet_NaN(); }),
           "option 'command_timeout_s'");
  contains(with([](auto& c) { c.command_timeout_s = -1; }), "option 'command_timeout_s'");
  contains(with([](auto& c) { c.footprint.radius = 0; }), "option 'footprint.radius'");
  contains(with([](auto& c) { c.footprint.height = std::numeric_limits<double>::infinity(); }),
           "option 'footprint.height'");
  CHECK_THROWS_WITH(optionsFromYaml("{start_pose: [1, two, 3]}"), Catch::Contains("start_pose"));
  CHECK_THROWS_WITH(optionsFromYaml("{footprint: {width: 1}}"), Catch::Contains("width"));
}
