// Tests for the navigator and goal_sequencer actors through the mock-mailbox harness: a closed
// loop on a kinematic robot reaches its goal, stale localisation stops the base, bad goals are
// refused, a depth frame marks a table top, goals files and random goals.
#include <tessera/msg/image.capnp.h>
#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/navigation/base_controller_actor.hpp>
#include <tessera/navigation/goal_sequencer_actor.hpp>
#include <tessera/navigation/navigation_actor.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <catch2/catch.hpp>

#include "nav_test_inputs.hpp"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

using namespace tessera;
using navigation::GoalSequencerActor;
using navigation::GoalSequencerOptions;
using navigation::NavigationActor;
using navigation::NavigationActorOptions;

namespace {

// The shared inputs take the place of what this file used to define here itself.
using tessera::test::nav::placeRobot;
using tessera::test::nav::pushGoal;
using tessera::test::nav::pushOdom;
using tessera::test::nav::pushPose;
using tessera::test::nav::pushRoom;
using tessera::test::nav::roomOptions;

namespace fs = std::filesystem;
constexpr Nanos kStep = 50'000'000;  // the navigator's default 20 Hz

template <class T>
T summaryValue(Actor& a, const std::string& key) {
  Summary s;
  a.summarize(s);
  const auto it = s.find(key);
  if (it == s.end()) return T{};
  return std::get<T>(it->second);
}

std::string lastState(ActorHarness& h) {
  const auto st = h.published<msg::NavStatus>("nav_status");
  if (st.empty()) return "none";
  switch (st.back()->getState()) {
    case msg::NavStatus::State::REACHED:
      return "reached";
    case msg::NavStatus::State::FAILED:
      return "failed";
    case msg::NavStatus::State::REFUSED:
      return "refused";
    case msg::NavStatus::State::IDLE:
      return "idle";
    default:
      return "active";
  }
}

/// Drives a perfect kinematic robot with the navigator's commands for up to `seconds`.
Pose2 driveLoop(ActorHarness& h, Pose2 pose, double seconds) {
  double v = 0, w = 0;
  for (int k = 0; k < static_cast<int>(seconds * 20); ++k) {
    const double dt = 0.05;
    pose = pose * Pose2(v * dt, 0, 0) * Pose2(0, 0, w * dt);
    pushPose(h, h.now(), pose);
    pushOdom(h, h.now(), pose, v, w);
    h.runUntilIdle();
    h.advance(kStep);
    const auto cmds = h.published<msg::Twist>("cmd_vel");
    if (!cmds.empty()) {
      v = cmds.back()->getTwist().getVx();
      w = cmds.back()->getTwist().getOmega();
    }
    if (lastState(h) == "reached") break;
  }
  return pose;
}

}  // namespace

TEST_CASE("navigator drives a kinematic robot to its goal on a map topic", "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  pushRoom(h);
  const Pose2 start(1.5, 1.5, 0.0);
  placeRobot(h, start);
  pushGoal(h, 7, Pose2(8.0, 6.0, 1.57));
  const Pose2 end = driveLoop(h, start, 60);
  CHECK(lastState(h) == "reached");
  CHECK((end.translation() - Eigen::Vector2d(8.0, 6.0)).norm() < 0.2);
  CHECK(h.published<msg::NavStatus>("nav_status").back()->getGoalId() == 7);
  CHECK(h.publishedCount("path") >= 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "reached") == 1);
  // The map got landmark bounds (on by default) and the plans used them: the obstacle layer
  // only ever adds cost.
  CHECK(summaryValue<std::int64_t>(h.actor(), "plans") >= 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "landmark_plans") ==
        summaryValue<std::int64_t>(h.actor(), "plans"));
  CHECK(summaryValue<double>(h.actor(), "landmarks_ms") > 0);
  CHECK(summaryValue<std::int64_t>(h.actor(), "landmark_builds") == 1);
  // Every command was finite and within the dynamic window's limits.
  for (const auto& c : h.published<msg::Twist>("cmd_vel")) {
    REQUIRE(std::isfinite(c->getTwist().getVx()));
    CHECK(std::abs(c->getTwist().getVx()) <= 0.5 + 1e-9);
  }
}

TEST_CASE("navigator keeps its landmark bounds when the same map comes again", "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  pushRoom(h);
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "landmark_builds") == 1);
  pushRoom(h);  // a map server publishing the same map again
  h.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(h.actor(), "maps") == 2);
  CHECK(summaryValue<std::int64_t>(h.actor(), "landmark_builds") == 1);
  auto off = roomOptions();
  off.landmarks = 0;
  ActorHarness none(std::make_unique<NavigationActor>(off));
  pushRoom(none);
  none.runUntilIdle();
  CHECK(summaryValue<std::int64_t>(none.actor(), "landmark_builds") == 0);
}

TEST_CASE("navigator stops the base when localisation goes stale", "[navigator]") {
  auto o = roomOptions();
  o.pose_timeout_s = 0.5;
  ActorHarness h(std::make_unique<NavigationActor>(o));
  pushRoom(h);
  const Pose2 start(1.5, 1.5, 0.0);
  placeRobot(h, start);
  pushGoal(h, 1, Pose2(8.0, 1.5, 0.0));
  driveLoop(h, start, 1.0);  // starts moving
  const auto moving = h.published<msg::Twist>("cmd_vel");
  CHECK(moving.back()->getTwist().getVx() > 0.05);
  for (int k = 0; k < 20; ++k) h.advance(kStep);  // 1 s without a pose
  const auto after = h.published<msg::Twist>("cmd_vel");
  CHECK(after.back()->getTwist().getVx() == 0.0);
  CHECK(after.back()->getTwist().getOmega() == 0.0);
  CHECK(summaryValue<std::int64_t>(h.actor(), "stale_stops") == 1);
  const auto status = h.published<msg::NavStatus>("nav_status");
  CHECK(std::string(status.back()->getReason()).find("stale localisation") != std::string::npos);
}

TEST_CASE("navigator refuses goals off the map, in a wall or in another frame", "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  pushRoom(h);
  pushPose(h, 0, Pose2(1.5, 1.5, 0));
  pushOdom(h, 0, Pose2(1.5, 1.5, 0), 0, 0);
  h.runUntilIdle();
  h.advance(kStep);
  for (const auto& [goal, frame, words] :
       {std::tuple{Pose2(20, 3, 0), std::string("map"), std::string("off the map")},
        std::tuple{Pose2(0.05, 3, 0), std::string("map"), std::string("obstacle")},
        std::tuple{Pose2(5, 3, 0), std::string("odom"), std::string("frame 'odom'")},
        std::tuple{Pose2(std::numeric_limits<double>::quiet_NaN(), 3, 0), std::string("map"),
                   std::string("finite")}}) {
    INFO(words);
    pushGoal(h, 3, goal, frame);
    h.runUntilIdle();
    h.advance(kStep);
    CHECK(lastState(h) == "refused");
    const std::string reason = h.published<msg::NavStatus>("nav_status").back()->getReason();
    CHECK_THAT(reason, Catch::Contains(words));
  }
  // The base never moved.
  for (const auto& c : h.published<msg::Twist>("cmd_vel")) CHECK(c->getTwist().getVx() == 0.0);
}

TEST_CASE("navigator marks a table top seen in depth, and skips malformed depth", "[navigator]") {
  auto o = roomOptions();
  o.use_depth = true;
  o.depth_stride = 1;
  o.depth_camera = {};
  o.depth_camera.x = 0;
  o.depth_camera.z = 0.9;
  o.depth_camera.pitch = 0;  // looking straight ahead
  ActorHarness h(std::make_unique<NavigationActor>(o));
  pushRoom(h);
  const Pose2 robot(2.0, 4.0, 0.0);
  pushPose(h, 0, robot);
  pushOdom(h, 0, robot, 0, 0);
  h.runUntilIdle();
  // A 20 x 20 depth image: the lower half sees a surface 1.5 m ahead between 0.9 m (the
  // camera's height) and 0.2 m, the upper half nothing (NaN).
  auto pushDepth = [&](std::uint32_t rows_given, float value_low) {
    h.push<msg::RgbdFrame>("rgbd", [&](auto& b) {
      setHeader(b.initHeader(), 0, "camera", 0);
      auto d = b.initDepth();
      d.setWidth(20);
      d.setHeight(20);
      d.setEncoding("32FC1");
      d.setStep(80);
      auto data = d.initData(rows_given * 80);
      for (std::uint32_t v = 0; v < rows_given; ++v)
        for (std::uint32_t u = 0; u < 20; ++u) {
          const float z = v >= 10 ? value_low : std::numeric_limits<float>::quiet_NaN();
          std::memcpy(data.begin() + v * 80 + u * 4, &z, 4);
        }
      auto k = b.initIntrinsics();
      k.setFx(40);
      k.setFy(40);
      k.setCx(9.5);
      k.setCy(9.5);
      b.setDepthScale(1.0);
    });
    h.runUntilIdle();
    h.advance(kStep);
  };
  pushDepth(20, 1.5f);
  const auto& map = dynamic_cast<NavigationActor&>(h.actor()).costmap();
  const Eigen::Vector2i ahead = map.cellOf(Eigen::Vector2d(3.55, 4.0));
  CHECK(map.at(ahead) == navigation::cost::kLethal);
  const Eigen::Vector2i beside = map.cellOf(Eigen::Vector2d(3.55, 6.0));  // outside the view
  CHECK(map.at(beside) < navigation::cost::kInscribed);
  CHECK(summaryValue<std::int64_t>(h.actor(), "depth_frames") == 1);
  pushDepth(7, 1.5f);  // truncated: fewer rows than the header says
  CHECK(summaryValue<std::int64_t>(h.actor(), "bad_depth_size") == 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "depth_frames") == 1);
}

TEST_CASE("navigator rejects bad options and unreadable map files", "[navigator]") {
  auto o = roomOptions();
  o.control_hz = 0;
  CHECK_THROWS_WITH(NavigationActor(o), Catch::Contains("control_hz"));
  o = roomOptions();
  o.pose_message = "telepathy";
  CHECK_THROWS_WITH(NavigationActor(o), Catch::Contains("pose_message"));
  o = roomOptions();
  o.map_file = "/nonexistent/map.yaml";
  CHECK_THROWS_WITH(NavigationActor(o), Catch::Contains("/nonexistent/map.yaml"));
  o = roomOptions();
  o.inflation.inflation_radius = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(NavigationActor(o), Catch::Contains("inflation"));
  o = roomOptions();
  o.landmarks = 17;
  CHECK_THROWS_WITH(NavigationActor(o), Catch::Contains("landmarks"));
}

TEST_CASE("goals files parse, and malformed ones name the line", "[goal_sequencer]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_goals_test";
  fs::create_directories(dir);
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return (dir / name).string();
  };
  const auto good = navigation::readGoalsFile(
      write("good.txt", "# x y theta\n1 2 0.5\n\n3 4 0 0.3 0.2  # with tolerances\n"));
  REQUIRE(good.size() == 2);
  CHECK(good[1].pose.x == 3.0);
  CHECK(good[1].tolerance_xy == 0.3);
  CHECK(good[1].tolerance_yaw == 0.2);
  CHECK_THROWS_WITH(navigation::readGoalsFile(write("short.txt", "1 2 0\n1 2\n")),
                    Catch::Contains("short.txt:2") && Catch::Contains("2 numbers"));
  CHECK_THROWS_WITH(navigation::readGoalsFile(write("nan.txt", "1 nan 0\n")),
                    Catch::Contains("nan.txt:1") && Catch::Contains("'nan'"));
  CHECK_THROWS_WITH(navigation::readGoalsFile(write("word.txt", "1 2 north\n")),
                    Catch::Contains("'north'"));
  CHECK_THROWS_WITH(navigation::readGoalsFile(write("empty.txt", "# nothing\n")),
                    Catch::Contains("no goal"));
  CHECK_THROWS_WITH(navigation::readGoalsFile((dir / "missing.txt").string()),
                    Catch::Contains("cannot open"));
  GoalSequencerOptions o;
  o.goals_file = (dir / "short.txt").string();
  CHECK_THROWS_AS(GoalSequencerActor(o), ConfigError);
  fs::remove_all(dir);
}

TEST_CASE("reachable cells stop at walls and keep the clearance", "[goal_sequencer]") {
  navigation::Costmap map(60, 40, 0.1);
  for (int r = 0; r < 40; ++r) map.at(30, r) = navigation::cost::kLethal;  // a full wall at x=3
  navigation::Costmap eroded;
  const auto cells = navigation::reachableCells(map, 0.3, Eigen::Vector2d(1.0, 2.0), &eroded);
  REQUIRE(!cells.empty());
  for (const auto& c : cells) {
    const Eigen::Vector2d p = map.cellCenter(c);
    CHECK(p.x() < 3.0 - 0.3 + 1e-9);  // this side of the wall, clear of it
  }
  // Through a door the other side is reachable, and the shortest path goes through it.
  for (int r = 18; r < 26; ++r) map.at(30, r) = navigation::cost::kFree;
  const auto both = navigation::reachableCells(map, 0.3, Eigen::Vector2d(1.0, 2.0), &eroded);
  CHECK(both.size() > cells.size() * 3 / 2);
  // Straight through the door (y in [1.8, 2.6]); to a goal below the door, a detour through it.
  const double through = navigation::shortestPathLength(eroded, {1.0, 2.2}, {5.0, 2.2});
  CHECK(through == Approx(4.0).margin(0.15));
  const double detour = navigation::shortestPathLength(eroded, {1.0, 2.2}, {5.0, 0.5});
  CHECK(detour > std::hypot(4.0, 1.7) + 0.1);
  CHECK(std::isnan(navigation::shortestPathLength(eroded, {1.0, 2.0}, {3.0, 0.1})));
}

TEST_CASE("goal_sequencer sends goals in order and counts their ends", "[goal_sequencer]") {
  const fs::path file = fs::temp_directory_path() / "tessera_goal_sequence.txt";
  std::ofstream(file) << "2 2 0\n5 3 1.0\n6 1 0\n";
  GoalSequencerOptions o;
  o.goals_file = file.string();
  o.pose_message = "pose_stamped";
  o.start_delay_s = 0.5;
  o.goal_timeout_s = 5;
  ActorHarness h(std::make_unique<GoalSequencerActor>(o));
  pushPose(h, 0, Pose2(1, 1, 0));
  h.runUntilIdle();
  h.advance(kNanosPerSecond);
  auto goals = h.published<msg::NavGoal>("goal");
  REQUIRE(goals.size() == 1);
  CHECK(goals[0]->getId() == 1);
  auto status = [&](std::uint64_t id, msg::NavStatus::State s) {
    h.push<msg::NavStatus>("nav_status", [&](auto& b) {
      setHeader(b.initHeader(), h.now(), "map", 0);
      b.setGoalId(id);
      b.setState(s);
    });
    h.runUntilIdle();
  };
  pushPose(h, h.now(), Pose2(2, 2, 0));  // drove sqrt(2) m
  status(1, msg::NavStatus::State::DRIVING);
  CHECK(h.published<msg::NavGoal>("goal").size() == 1);
  status(1, msg::NavStatus::State::REACHED);
  goals = h.published<msg::NavGoal>("goal");
  REQUIRE(goals.size() == 2);
  CHECK(goals[1]->getPose().getX() == 5.0);
  status(1, msg::NavStatus::State::FAILED);  // a stale status of goal 1: ignored
  status(2, msg::NavStatus::State::FAILED);
  REQUIRE(h.published<msg::NavGoal>("goal").size() == 3);
  for (int k = 0; k < 60; ++k) h.advance(kNanosPerSecond / 10);  // goal 3 times out
  CHECK(summaryValue<std::int64_t>(h.actor(), "reached") == 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "failed") == 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "timed_out") == 1);
  CHECK(summaryValue<double>(h.actor(), "path_length_ratio") > 0.9);
  fs::remove(file);
}

TEST_CASE("base_controller ramps to commands, brakes when they stop and never passes NaN",
          "[base_controller]") {
  navigation::BaseControllerOptions o;
  o.limits.max_speed = 0.5;
  o.limits.acceleration = 1.0;
  o.limits.max_turn_rate = 1.0;
  o.limits.turn_acceleration = 2.0;
  o.rate_hz = 50;
  o.timeout_s = 0.3;
  ActorHarness h(std::make_unique<navigation::BaseControllerActor>(o));
  auto command = [&](double v, double w) {
    h.push<msg::Twist>("cmd_vel", [&](auto& b) {
      setHeader(b.initHeader(), h.now(), "base_link", 0);
      b.initTwist().setVx(v);
      b.getTwist().setOmega(w);
    });
    h.runUntilIdle();
  };
  auto last = [&] {
    const auto out = h.published<msg::Twist>("base_cmd");
    REQUIRE(!out.empty());
    return std::pair{out.back()->getTwist().getVx(), out.back()->getTwist().getOmega()};
  };
  const Nanos tick = 20'000'000;
  // Asked for 2 m/s: clamped to 0.5, reached at 1 m/s² after 0.5 s, not before.
  for (int k = 0; k < 10; ++k) {
    command(2.0, 3.0);
    h.advance(tick);
  }
  CHECK(last().first == Approx(0.2).margin(0.021));
  CHECK(last().second == Approx(0.4).margin(0.041));
  for (int k = 0; k < 20; ++k) {
    command(2.0, 3.0);
    h.advance(tick);
  }
  CHECK(last().first == Approx(0.5));
  CHECK(last().second == Approx(1.0));
  // Commands stop: after the timeout it brakes within the limit and stands still.
  for (int k = 0; k < 15; ++k) h.advance(tick);  // 0.3 s
  CHECK(last().first > 0.2);
  for (int k = 0; k < 50; ++k) h.advance(tick);
  CHECK(last().first == 0.0);
  CHECK(last().second == 0.0);
  // A NaN command is a stop request; every output stays finite.
  command(0.3, 0.0);
  h.advance(tick);
  command(std::numeric_limits<double>::quiet_NaN(), 0.2);
  for (int k = 0; k < 10; ++k) h.advance(tick);
  for (const auto& m : h.published<msg::Twist>("base_cmd")) {
    REQUIRE(std::isfinite(m->getTwist().getVx()));
    REQUIRE(std::isfinite(m->getTwist().getOmega()));
  }
  CHECK(last().first == 0.0);
  CHECK(summaryValue<std::int64_t>(h.actor(), "nonfinite_commands") == 1);
  CHECK(summaryValue<std::int64_t>(h.actor(), "clamped_commands") == 30);
  CHECK(summaryValue<std::int64_t>(h.actor(), "timeouts") == 1);
  o.timeout_s = 0;
  CHECK_THROWS_WITH(navigation::BaseControllerActor(o), Catch::Contains("timeout_s"));
}
