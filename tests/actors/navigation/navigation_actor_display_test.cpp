// Tests for what the navigator publishes for display, through the mock-mailbox harness: the
// planning costmap on `costmap` (costmap_2d values, sent again only when it changed) and the
// dynamic window's arcs on `local_plan` (at local_plan_hz while driving, matching cmd_vel).
#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/navigation/navigation_actor.hpp>
#include <tessera/runtime/harness.hpp>

#include <catch2/catch.hpp>

#include "nav_test_inputs.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <variant>
#include <vector>

namespace nav_display_topics_test {

using namespace tessera;
using navigation::NavigationActor;
using navigation::NavigationActorOptions;
using test::nav::placeRobot;
using test::nav::pushGoal;
using test::nav::pushOdom;
using test::nav::pushPose;
using test::nav::roomOptions;

constexpr Nanos kTick = 50'000'000;  // the navigator's default 20 Hz

std::int64_t summaryCount(Actor& a, const std::string& key) {
  Summary s;
  a.summarize(s);
  const auto it = s.find(key);
  return it == s.end() ? -1 : std::get<std::int64_t>(it->second);
}

/// The room with an unknown square and, with `block`, an obstacle (nav_test_inputs.hpp).
void pushRoom(ActorHarness& h, bool block = false) {
  test::nav::pushRoom(h, {.topic = "map", .unknown_square = true, .block = block});
}

/// The costmap_2d value of a cost, computed independently of the actor's table.
int expectedValue(std::uint8_t c) {
  if (c == navigation::cost::kUnknown) return -1;
  if (c == navigation::cost::kLethal) return 100;
  if (c == navigation::cost::kInscribed) return 99;
  if (c == 0) return 0;
  return 1 + static_cast<int>(std::lround((c - 1) * 97.0 / 251.0));
}

/// The robot's pose at each control tick (what the tick's map pose is), with the commands it
/// followed: a perfect kinematic robot driven for `seconds`.
std::vector<std::pair<Nanos, Pose2>> drive(ActorHarness& h, Pose2 pose, double seconds) {
  std::vector<std::pair<Nanos, Pose2>> at_tick;
  double v = 0, w = 0;
  for (int k = 0; k < static_cast<int>(seconds * 20); ++k) {
    const double dt = 0.05;
    pose = pose * Pose2(v * dt, 0, 0) * Pose2(0, 0, w * dt);
    pushPose(h, h.now(), pose);
    pushOdom(h, h.now(), pose, v, w);
    h.runUntilIdle();
    h.advance(kTick);
    at_tick.emplace_back(h.now(), pose);
    const auto cmds = h.published<msg::Twist>("cmd_vel");
    if (!cmds.empty()) {
      v = cmds.back()->getTwist().getVx();
      w = cmds.back()->getTwist().getOmega();
    }
  }
  return at_tick;
}

TEST_CASE("navigator publishes its planning costmap in costmap_2d values, again only on change",
          "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  auto& actor = static_cast<NavigationActor&>(h.actor());
  pushRoom(h);
  h.runUntilIdle();
  h.advance(kTick);  // the first tick builds the planning costmap
  auto maps = h.published<msg::OccupancyGrid>("costmap");
  REQUIRE(maps.size() == 1);
  const auto& m = maps[0];
  const navigation::Costmap& costmap = actor.costmap();
  CHECK(std::string(m->getHeader().getFrameId()) == "map");
  // Stamped with the tick that rebuilt it.
  CHECK(m->getHeader().getStampNs() ==
        h.published<msg::Twist>("cmd_vel").front()->getHeader().getStampNs());
  CHECK(m->getWidth() == 100);
  CHECK(m->getHeight() == 80);
  CHECK(m->getResolution() == 0.1f);
  CHECK(m->getOrigin().getX() == 0.0);
  CHECK(m->getOrigin().getY() == 0.0);
  CHECK(m->getOrigin().getTheta() == 0.0);
  const auto cells = viewInt8(m->getCells());
  REQUIRE(cells.size() == costmap.cells.size());
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < cells.size(); ++i)
    if (cells[i] != expectedValue(costmap.cells[i])) ++mismatches;
  CHECK(mismatches == 0);
  const auto value = [&](int col, int row) { return static_cast<int>(cells[row * 100 + col]); };
  CHECK(value(0, 40) == 100);  // the wall: lethal
  CHECK(value(65, 35) == -1);  // the unknown square
  CHECK(value(50, 40) == 0);   // the middle of the room: free
  CHECK(value(2, 40) == 99);   // 0.1 m from the wall: inscribed
  CHECK(value(5, 40) >= 1);    // 0.4 m from the wall: inflated
  CHECK(value(5, 40) <= 98);
  CHECK(summaryCount(h.actor(), "costmaps_published") == 1);

  // The same map again: the costmap is rebuilt, unchanged, and not sent again.
  const std::int64_t builds = summaryCount(h.actor(), "costmap_builds");
  pushRoom(h);
  h.runUntilIdle();
  for (int k = 0; k < 20; ++k) h.advance(kTick);
  CHECK(summaryCount(h.actor(), "costmap_builds") > builds);
  CHECK(h.publishedCount("costmap") == 1);

  // A new obstacle changes it: sent again.
  pushRoom(h, true);
  h.runUntilIdle();
  for (int k = 0; k < 20; ++k) h.advance(kTick);
  maps = h.published<msg::OccupancyGrid>("costmap");
  REQUIRE(maps.size() == 2);
  CHECK(viewInt8(maps[1]->getCells())[62 * 100 + 32] == 100);
  CHECK(summaryCount(h.actor(), "costmaps_published") == 2);

  auto off = roomOptions();
  off.publish_costmap = false;
  ActorHarness none(std::make_unique<NavigationActor>(off));
  pushRoom(none);
  none.runUntilIdle();
  none.advance(kTick);
  CHECK(none.publishedCount("costmap") == 0);
}

TEST_CASE("navigator publishes the dynamic window's arcs at local_plan_hz while driving",
          "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  pushRoom(h);
  const Pose2 start(1.5, 1.5, 0.0);
  placeRobot(h, start);
  for (int k = 0; k < 10; ++k) h.advance(kTick);
  CHECK(h.publishedCount("local_plan") == 0);  // no goal: nothing to show
  pushGoal(h, 7, Pose2(8.0, 6.0, 1.57));
  const auto poses = drive(h, start, 4.0);
  const auto plans = h.published<msg::LocalPlan>("local_plan");
  // 4 s at 5 Hz.
  CHECK(plans.size() >= 19);
  CHECK(plans.size() <= 21);
  CHECK(summaryCount(h.actor(), "local_plans_published") ==
        static_cast<std::int64_t>(plans.size()));
  const auto cmds = h.published<msg::Twist>("cmd_vel");
  std::size_t largest = 0;
  for (std::size_t i = 0; i < plans.size(); ++i) {
    const auto& p = plans[i];
    const Nanos stamp = p->getHeader().getStampNs();
    INFO("local plan " << i << " at " << stamp);
    if (i > 0) CHECK(stamp - plans[i - 1]->getHeader().getStampNs() >= 200'000'000);
    CHECK(std::string(p->getHeader().getFrameId()) == "map");
    CHECK(p->getGoalId() == 7);
    largest = std::max(largest, p.storage()->sizeInBytes());
    const auto arcs = p->getArcs();
    REQUIRE(arcs.size() == 11 * 21);
    const int chosen = p->getChosen();
    REQUIRE(chosen >= 0);
    REQUIRE(chosen < static_cast<int>(arcs.size()));
    const auto arc = arcs[static_cast<unsigned>(chosen)];
    CHECK(arc.getAdmissible());
    // The chosen pair is the command of the same period.
    const auto cmd = std::find_if(cmds.begin(), cmds.end(), [&](const auto& c) {
      return c->getHeader().getStampNs() == stamp;
    });
    REQUIRE(cmd != cmds.end());
    CHECK(arc.getV() == Approx((*cmd)->getTwist().getVx()).margin(1e-6));
    CHECK(arc.getW() == Approx((*cmd)->getTwist().getOmega()).margin(1e-6));
    CHECK(p->getCommand().getVx() == Approx((*cmd)->getTwist().getVx()).margin(1e-9));
    CHECK(p->getCommand().getOmega() == Approx((*cmd)->getTwist().getOmega()).margin(1e-9));
    // Every arc starts at the robot's pose of that period; 16 points each (the default).
    const auto robot =
        std::find_if(poses.begin(), poses.end(), [&](const auto& tp) { return tp.first == stamp; });
    REQUIRE(robot != poses.end());
    int admissible = 0;
    for (const auto a : arcs) {
      REQUIRE(a.getXy().size() == 32);
      CHECK(a.getXy()[0] == Approx(robot->second.x).margin(1e-5));
      CHECK(a.getXy()[1] == Approx(robot->second.y).margin(1e-5));
      if (a.getAdmissible()) ++admissible;
      if (a.getAdmissible()) CHECK(a.getScore() <= arc.getScore());
      if (!a.getAdmissible()) CHECK(a.getScore() == 0.0f);
    }
    CHECK(admissible >= 1);
  }
  INFO("largest local plan " << largest << " bytes");
  CHECK(largest > 0);
  CHECK(largest < 100'000);
}

TEST_CASE("navigator ends the local plan with an empty one when the goal is reached",
          "[navigator]") {
  ActorHarness h(std::make_unique<NavigationActor>(roomOptions()));
  pushRoom(h);
  const Pose2 start(1.5, 1.5, 0.0);
  placeRobot(h, start);
  h.advance(kTick);
  pushGoal(h, 3, Pose2(2.3, 1.5, 0.0));
  drive(h, start, 12.0);
  const auto status = h.published<msg::NavStatus>("nav_status");
  REQUIRE_FALSE(status.empty());
  REQUIRE(status.back()->getState() == msg::NavStatus::State::REACHED);
  const auto plans = h.published<msg::LocalPlan>("local_plan");
  REQUIRE(plans.size() >= 2);
  CHECK(plans.front()->getArcs().size() > 0);
  CHECK(plans.back()->getArcs().size() == 0);  // the end marker
  CHECK(plans.back()->getChosen() == -1);
  CHECK(plans.back()->getGoalId() == 3);
  // Exactly one end marker: nothing more while idle.
  CHECK(plans[plans.size() - 2]->getArcs().size() > 0);
}

TEST_CASE("navigator publishes no local plan with local_plan_hz 0", "[navigator]") {
  auto o = roomOptions();
  o.local_plan_hz = 0;
  ActorHarness h(std::make_unique<NavigationActor>(o));
  pushRoom(h);
  const Pose2 start(1.5, 1.5, 0.0);
  placeRobot(h, start);
  pushGoal(h, 1, Pose2(8.0, 1.5, 0.0));
  drive(h, start, 2.0);
  const auto cmds = h.published<msg::Twist>("cmd_vel");
  REQUIRE_FALSE(cmds.empty());
  CHECK(cmds.back()->getTwist().getVx() > 0.05);  // it drives
  CHECK(h.publishedCount("local_plan") == 0);
  CHECK(summaryCount(h.actor(), "local_plans_published") == 0);
  auto bad = roomOptions();
  bad.local_plan_hz = -1;
  CHECK_THROWS_WITH(NavigationActor(bad), Catch::Contains("local_plan_hz"));
  bad = roomOptions();
  bad.local_plan_points = 1;
  CHECK_THROWS_WITH(NavigationActor(bad), Catch::Contains("local_plan_points"));
}

}  // namespace nav_display_topics_test
