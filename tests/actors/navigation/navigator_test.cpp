// Navigator: a unicycle driven by its commands in small walled worlds reaches goals without
// touching an obstacle, replans around a wall that appears on its path, refuses goals it cannot
// take and fails with a reason (after its recoveries) when the goal is enclosed.
#include <tessera/navigation/navigator.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace nav = tessera::navigation;
using tessera::Pose2;

namespace {

// A 10 x 8 m room (5 cm cells) with a border wall and a wall at x = 5 m from y = 0 up to
// `wall_top`, leaving a gap above it.
nav::Costmap room(double wall_top = 5.0) {
  nav::Costmap m(200, 160, 0.05);
  for (int r = 0; r < m.height; ++r)
    for (int c = 0; c < m.width; ++c) {
      const bool border = c == 0 || r == 0 || c == m.width - 1 || r == m.height - 1;
      const bool wall = (c == 100 || c == 101) && r * 0.05 < wall_top;
      if (border || wall) m.at(c, r) = nav::cost::kLethal;
    }
  return m;
}

// Lethal cells on the segment from a to b (map frame, 5 cm steps).
void wall(nav::Costmap& m, Eigen::Vector2d a, Eigen::Vector2d b) {
  const int n = static_cast<int>((b - a).norm() / 0.025) + 1;
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector2i c = m.cellOf(a + (b - a) * (static_cast<double>(i) / n));
    if (m.contains(c)) m.at(c.x(), c.y()) = nav::cost::kLethal;
  }
}

nav::Costmap inflated(nav::Costmap m) {
  nav::inflate(m, nav::InflationOptions{});
  return m;
}

struct Drive {
  Pose2 pose;
  nav::Velocity velocity;
  double time = 0, min_clearance = 1e9, travelled = 0;
  nav::NavCommand last;
  int steps = 0;
};

// Runs the navigator at 20 Hz on a unicycle that follows each command within the dynamic
// window's acceleration limits, until a final state or `seconds`. `change`, when given, may edit
// the obstacles at each step (returns true when it did).
template <class Change>
Drive run(nav::Navigator& navigator, nav::Costmap obstacles, Pose2 start, double seconds,
          Change&& change) {
  Drive d;
  d.pose = start;
  nav::Costmap costmap = inflated(obstacles);
  nav::DistanceField field(costmap);
  const nav::DynamicWindowOptions& w = navigator.options().dwa;
  const double dt = 0.05;
  for (; d.time < seconds; d.time += dt, ++d.steps) {
    if (change(d.time, obstacles)) {
      costmap = inflated(obstacles);
      field = nav::DistanceField(costmap);
    }
    d.last = navigator.step(d.time, d.pose, d.velocity, costmap, field);
    if (nav::isFinal(d.last.state)) break;
    const auto approach = [&](double now, double want, double rate) {
      return now + std::clamp(want - now, -rate * dt, rate * dt);
    };
    d.velocity.v = approach(d.velocity.v, d.last.velocity.v, w.acceleration);
    d.velocity.w = approach(d.velocity.w, d.last.velocity.w, w.turn_acceleration);
    const double th = d.pose.theta + 0.5 * d.velocity.w * dt;
    const Pose2 next(d.pose.x + d.velocity.v * dt * std::cos(th),
                     d.pose.y + d.velocity.v * dt * std::sin(th), d.pose.theta + d.velocity.w * dt);
    d.travelled += (next.translation() - d.pose.translation()).norm();
    d.pose = next;
    // Clearance against the true obstacles (not inflated): distance to the nearest lethal cell
    // centre minus half a cell.
    d.min_clearance =
        std::min(d.min_clearance, nav::DistanceField(obstacles).at(d.pose.translation()) - 0.025);
  }
  return d;
}

Drive run(nav::Navigator& navigator, const nav::Costmap& obstacles, Pose2 start, double seconds) {
  return run(navigator, obstacles, start, seconds, [](double, nav::Costmap&) { return false; });
}

}  // namespace

TEST_CASE("Navigator drives through the gap to the goal without touching a wall", "[navigation]") {
  nav::Navigator navigator;
  const nav::Costmap map = room();
  REQUIRE(navigator.setGoal(Pose2(8, 2, M_PI / 2), inflated(map)).empty());
  const Drive d = run(navigator, map, Pose2(2, 2, 0), 120);
  INFO("state " << nav::stateName(d.last.state) << " reason " << d.last.reason << " at ("
                << d.pose.x << ", " << d.pose.y << ") after " << d.time << " s");
  REQUIRE(d.last.state == nav::NavState::kReached);
  CHECK((d.pose.translation() - Eigen::Vector2d(8, 2)).norm() <= 0.15);
  CHECK(std::abs(tessera::normalizeAngle(d.pose.theta - M_PI / 2)) <= 0.25);
  CHECK(d.min_clearance > navigator.options().dwa.footprint_radius);
  // Through the gap above the wall: the straight line is 6 m, the way round about 10 m.
  CHECK(d.travelled > 8.0);
  CHECK(d.travelled < 14.0);
  CHECK(navigator.stats().recoveries == 0);
}

TEST_CASE("Navigator replans when a wall appears across its path", "[navigation]") {
  // Two ways from the left half to the right one: the gap above the wall (y > 6) and a door at
  // y 1-2 below it. The door closes once the robot is on its way.
  nav::Costmap map = room(6.0);
  for (int r = 20; r < 40; ++r) map.at(100, r) = map.at(101, r) = nav::cost::kFree;
  nav::Navigator navigator;
  REQUIRE(navigator.setGoal(Pose2(8, 1.5, 0), inflated(map)).empty());
  bool closed = false;
  const Drive d = run(navigator, map, Pose2(2, 1.5, 0), 150, [&](double t, nav::Costmap& m) {
    if (closed || t < 2.0) return false;
    wall(m, {5.0, 0.9}, {5.0, 2.1});
    closed = true;
    return true;
  });
  INFO("state " << nav::stateName(d.last.state) << " reason " << d.last.reason);
  REQUIRE(closed);
  REQUIRE(d.last.state == nav::NavState::kReached);
  CHECK(d.min_clearance > navigator.options().dwa.footprint_radius);
  CHECK(d.travelled > 12.0);  // round by the gap at the top
  CHECK(navigator.stats().plans >= 2);
}

TEST_CASE("Navigator refuses goals off the map, on obstacles and non-finite", "[navigation]") {
  nav::Navigator navigator;
  const nav::Costmap map = inflated(room());
  const std::string off = navigator.setGoal(Pose2(20, 2, 0), map);
  CHECK(off.find("off the map") != std::string::npos);
  CHECK(navigator.state() == nav::NavState::kRefused);
  CHECK(navigator.setGoal(Pose2(5.02, 2, 0), map).find("obstacle") != std::string::npos);
  CHECK(navigator.setGoal(Pose2(4.9, 2, 0), map).find("inscribed") != std::string::npos);
  CHECK_FALSE(navigator.setGoal(Pose2(NAN, 2, 0), map).empty());
  // A refused goal commands nothing.
  const nav::DistanceField field(map);
  const auto c = navigator.step(0, Pose2(2, 2, 0), {}, map, field);
  CHECK(c.state == nav::NavState::kRefused);
  CHECK(c.velocity.v == 0);
  CHECK(c.velocity.w == 0);
  // A good goal after a refused one is taken.
  CHECK(navigator.setGoal(Pose2(2, 4, 0), map).empty());
  CHECK(navigator.state() == nav::NavState::kDriving);
}

TEST_CASE("Navigator fails with a reason after its recoveries when the goal is enclosed",
          "[navigation]") {
  nav::Costmap map = room();
  wall(map, {7, 1}, {9, 1});
  wall(map, {9, 1}, {9, 3});
  wall(map, {9, 3}, {7, 3});
  wall(map, {7, 3}, {7, 1});
  nav::NavigatorOptions o;
  o.recovery.max_attempts = 2;
  nav::Navigator navigator(o);
  REQUIRE(navigator.setGoal(Pose2(8, 2, 0), inflated(map)).empty());
  const Drive d = run(navigator, map, Pose2(2, 2, 0), 120);
  INFO("reason " << d.last.reason);
  REQUIRE(d.last.state == nav::NavState::kFailed);
  CHECK(d.last.reason.find("no path") != std::string::npos);
  CHECK(d.last.reason.find("gave up after 2 recoveries") != std::string::npos);
  CHECK(navigator.stats().recoveries == 2);
  CHECK(d.min_clearance > o.dwa.footprint_radius);
  CHECK(d.last.velocity.v == 0);
}

TEST_CASE("Navigator ignores non-finite poses and rejects bad options", "[navigation]") {
  nav::Navigator navigator;
  const nav::Costmap map = inflated(room());
  const nav::DistanceField field(map);
  REQUIRE(navigator.setGoal(Pose2(2, 4, 0), map).empty());
  const auto c = navigator.step(0, Pose2(NAN, 2, 0), {}, map, field);
  CHECK(c.velocity.v == 0);
  CHECK(c.velocity.w == 0);
  CHECK(navigator.state() == nav::NavState::kDriving);
  nav::NavigatorOptions o;
  o.lookahead = 0;
  CHECK_THROWS_WITH(nav::Navigator(o), Catch::Contains("lookahead"));
  o = {};
  o.recovery.rotate_rate = -1;
  CHECK_THROWS_WITH(nav::Navigator(o), Catch::Contains("rotate_rate"));
}

TEST_CASE("Navigator drives through unknown space it may plan across without replanning there",
          "[navigation]") {
  nav::NavigatorOptions o;
  o.planner.allow_unknown = true;
  o.replan_period = 0;  // replan only when the path is blocked
  nav::Navigator navigator(o);
  nav::Costmap map = room(8.0);  // the wall at x = 5 closes the room: only unknown space beyond
  for (int r = 1; r < map.height - 1; ++r)
    for (int c = 100; c < 102; ++c) map.at(c, r) = nav::cost::kFree;  // the wall is unknown...
  for (int r = 1; r < map.height - 1; ++r)
    for (int c = 90; c < 130; ++c) map.at(c, r) = nav::cost::kUnknown;  // ... and around it
  REQUIRE(navigator.setGoal(Pose2(8, 4, 0), inflated(map)).empty());
  const Drive d = run(navigator, map, Pose2(2, 4, 0), 60);
  CHECK(d.last.state == nav::NavState::kReached);
  // One plan: the unknown cells on the path do not count as blocking it.
  CHECK(navigator.stats().plans == 1);
}

TEST_CASE("Navigator keeps the dynamic window's arcs of the last step when asked", "[navigation]") {
  nav::Navigator navigator;
  const nav::Costmap map = inflated(room());
  const nav::DistanceField field(map);
  CHECK(navigator.lastWindow() == nullptr);
  REQUIRE(navigator.setGoal(Pose2(2, 4, 0), map).empty());
  const Pose2 pose(2, 2, M_PI / 2);
  auto c = navigator.step(0, pose, {}, map, field);
  REQUIRE(c.state == nav::NavState::kDriving);
  REQUIRE(navigator.lastWindow() != nullptr);
  CHECK(navigator.lastWindow()->arcs.empty());  // not kept by default
  navigator.setKeepArcs(true);
  c = navigator.step(0.05, pose, {c.velocity.v, c.velocity.w}, map, field);
  REQUIRE(c.state == nav::NavState::kDriving);
  const nav::DynamicWindowResult* w = navigator.lastWindow();
  REQUIRE(w != nullptr);
  REQUIRE(w->ok);
  REQUIRE(static_cast<int>(w->arcs.size()) == w->sampled);
  const auto& chosen = w->arcs.at(static_cast<std::size_t>(w->chosen));
  CHECK(chosen.velocity.v == c.velocity.v);
  CHECK(chosen.velocity.w == c.velocity.w);
  CHECK(chosen.poses.front().x == pose.x);
  CHECK(chosen.poses.front().y == pose.y);
  // A step that does not run the window (no goal) leaves no result.
  navigator.cancel();
  navigator.step(0.1, pose, {}, map, field);
  CHECK(navigator.lastWindow() == nullptr);
}
