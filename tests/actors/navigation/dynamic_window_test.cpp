// Tests for the dynamic window: admissibility (stops before obstacles), heading to the target,
// and a closed loop around a wall without contact.
#include <tessera/navigation/dynamic_window.hpp>
#include <tessera/navigation/grid_planner.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

using namespace tessera;
using namespace tessera::navigation;

namespace {

/// A 10 x 6 m map (5 cm cells) with origin (-2, -3), and optionally a wall across x = wall_x for
/// |y| <= half_width.
Costmap field(double wall_x, double half_width) {
  Costmap map(200, 120, 0.05, Pose2(-2, -3, 0));
  if (half_width > 0)
    for (int r = 0; r < map.height; ++r)
      for (int c = 0; c < map.width; ++c) {
        const Eigen::Vector2d p = map.cellCenter(c, r);
        if (std::abs(p.x() - wall_x) < 0.05 && std::abs(p.y()) <= half_width)
          map.at(c, r) = cost::kLethal;
      }
  return map;
}

}  // namespace

TEST_CASE("in free space the window heads for the target and speeds up", "[navigation]") {
  const DistanceField free_space(field(0, 0));
  DynamicWindow dwa;
  const auto left = dwa.choose(Pose2(0, 0, 0), {0.3, 0.0}, {2.0, 1.5}, free_space);
  REQUIRE(left.ok);
  CHECK(left.command.w > 0);
  CHECK(left.command.v >= 0.3);
  const auto right = dwa.choose(Pose2(0, 0, 0), {0.3, 0.0}, {2.0, -1.5}, free_space);
  REQUIRE(right.ok);
  CHECK(right.command.w < 0);
  CHECK(left.admissible == left.sampled);
}

TEST_CASE("pairs that cannot stop before the obstacle are not admissible", "[navigation]") {
  // Wall 0.45 m ahead of the centre: 0.2 m footprint leaves ~0.2 m of travel.
  const DistanceField wall(field(0.45, 1.0));
  DynamicWindowOptions o;
  o.max_speed = 1.0;
  const DynamicWindow dwa(o);
  const auto r = dwa.choose(Pose2(0, 0, 0), {0.6, 0.0}, {3.0, 0.0}, wall);
  CHECK(r.admissible < r.sampled);
  if (r.ok) {
    CHECK(r.command.v <= std::sqrt(2 * r.clearance * o.brake) + 1e-12);
    CHECK(r.command.v < 0.6);
  }
}

TEST_CASE("driving the window's commands around a wall never touches it", "[navigation]") {
  const Costmap map = field(2.0, 0.6);
  const DistanceField obstacles(map);
  // The global path around the wall (inflated by the footprint); the window heads for a point
  // 0.8 m ahead on it, as the navigation actor does.
  Costmap inflated = map;
  inflate(inflated, InflationOptions{0.25, 0.6, 5.0});
  const Eigen::Vector2d goal(4.0, 0.0);
  const GridPath path =
      GridPlanner().plan(inflated, inflated.cellOf({0, 0}), inflated.cellOf(goal));
  REQUIRE(path.ok());
  DynamicWindowOptions o;
  const DynamicWindow dwa(o);
  Pose2 pose(0, 0, 0);
  Velocity vel;
  double closest = std::numeric_limits<double>::infinity();
  bool reached = false;
  std::size_t along = 0;  // the path cell nearest the robot so far
  for (int k = 0; k < 1200 && !reached; ++k) {
    const Eigen::Vector2d here(pose.x, pose.y);
    while (along + 1 < path.cells.size() && (map.cellCenter(path.cells[along + 1]) - here).norm() <
                                                (map.cellCenter(path.cells[along]) - here).norm())
      ++along;
    std::size_t ahead = along;
    while (ahead + 1 < path.cells.size() && (map.cellCenter(path.cells[ahead]) - here).norm() < 0.8)
      ++ahead;
    const auto r = dwa.choose(pose, vel, map.cellCenter(path.cells[ahead]), obstacles);
    vel = r.ok ? r.command : Velocity{};
    // Integrate exactly what was commanded over one period.
    REQUIRE(r.rollout.size() >= 2);
    const double dt = o.period;
    if (std::abs(vel.w) < 1e-9)
      pose = Pose2(pose.x + vel.v * dt * std::cos(pose.theta),
                   pose.y + vel.v * dt * std::sin(pose.theta), pose.theta);
    else
      pose =
          Pose2(pose.x + vel.v / vel.w * (std::sin(pose.theta + vel.w * dt) - std::sin(pose.theta)),
                pose.y - vel.v / vel.w * (std::cos(pose.theta + vel.w * dt) - std::cos(pose.theta)),
                pose.theta + vel.w * dt);
    closest = std::min(closest, obstacles.at({pose.x, pose.y}));
    reached = (Eigen::Vector2d(pose.x, pose.y) - goal).norm() < 0.25;
  }
  INFO("final pose " << pose.x << " " << pose.y << " " << pose.theta);
  CHECK(closest > o.footprint_radius);
  CHECK(reached);
}

TEST_CASE("the window refuses bad options and survives bad inputs", "[navigation]") {
  DynamicWindowOptions o;
  o.min_speed = 2.0;
  CHECK_THROWS_WITH(DynamicWindow(o), Catch::Contains("min_speed"));
  o = {};
  o.step = 0;
  CHECK_THROWS_WITH(DynamicWindow(o), Catch::Contains("step"));
  const DistanceField free_space(field(0, 0));
  const DynamicWindow dwa;
  const double nan = std::nan("");
  CHECK_FALSE(dwa.choose(Pose2(nan, 0, 0), {}, {1, 0}, free_space).ok);
  CHECK_FALSE(dwa.choose(Pose2(0, 0, 0), {}, {nan, 0}, free_space).ok);
  const auto r = dwa.choose(Pose2(0, 0, 0), {nan, nan}, {1, 0}, free_space);
  REQUIRE(r.ok);
  CHECK(std::isfinite(r.command.v));
  CHECK(std::isfinite(r.command.w));
  // Outside the distance field nothing is admissible but turning on the spot.
  const auto outside = dwa.choose(Pose2(50, 50, 0), {}, {51, 50}, free_space);
  if (outside.ok) CHECK(outside.command.v == 0);
}

TEST_CASE("the window returns every sampled arc, only when asked", "[navigation]") {
  // A wide window (0-1 m/s) before a wall 0.6 m ahead: the slow pairs can stop, the fast cannot.
  const DistanceField wall(field(0.6, 1.0));
  DynamicWindowOptions o;
  o.max_speed = 1.0;
  o.acceleration = 10.0;
  const DynamicWindow dwa(o);
  const Pose2 pose(0, 0, 0.05);
  const Velocity current{0.5, 0.0};
  const Eigen::Vector2d target(3.0, 0.5);
  const auto plain = dwa.choose(pose, current, target, wall);
  CHECK(plain.arcs.empty());
  const auto r = dwa.choose(pose, current, target, wall, true);
  REQUIRE(r.ok);
  CHECK(r.command.v == plain.command.v);
  CHECK(r.command.w == plain.command.w);
  CHECK(r.sampled == o.speed_samples * o.turn_samples);
  REQUIRE(static_cast<int>(r.arcs.size()) == r.sampled);
  CHECK(r.admissible > 0);
  CHECK(r.admissible < r.sampled);
  const int steps = static_cast<int>(std::ceil(o.horizon / o.step - 1e-9));
  int admissible = 0;
  double best = -1;
  for (const DynamicWindowArc& a : r.arcs) {
    admissible += a.admissible ? 1 : 0;
    if (a.admissible) best = std::max(best, a.score);
    if (!a.admissible) CHECK(a.score == 0);
    CHECK(a.clearance >= 0);
    CHECK(a.clearance <= std::abs(a.velocity.v) * o.step * steps + 1e-12);
    REQUIRE(a.poses.size() == static_cast<std::size_t>(steps) + 1);
    CHECK(a.poses.front().x == pose.x);
    CHECK(a.poses.front().y == pose.y);
    CHECK(a.poses.front().theta == pose.theta);
  }
  CHECK(admissible == r.admissible);
  // The chosen arc is the command, the best score and the result's rollout.
  REQUIRE(r.chosen >= 0);
  REQUIRE(r.chosen < r.sampled);
  const DynamicWindowArc& chosen = r.arcs[static_cast<std::size_t>(r.chosen)];
  CHECK(chosen.velocity.v == r.command.v);
  CHECK(chosen.velocity.w == r.command.w);
  CHECK(chosen.admissible);
  CHECK(chosen.score == best);
  REQUIRE(chosen.poses.size() == r.rollout.size());
  for (std::size_t k = 0; k < r.rollout.size(); ++k) {
    CHECK(chosen.poses[k].x == r.rollout[k].x);
    CHECK(chosen.poses[k].y == r.rollout[k].y);
  }
  // Too fast to stop before the wall whatever the pair: the arcs come back, none chosen.
  o.acceleration = 0.5;
  const auto none = DynamicWindow(o).choose(Pose2(0.1, 0, 0), {0.9, 0.0}, target, wall, true);
  CHECK_FALSE(none.ok);
  CHECK(none.chosen == -1);
  CHECK(none.admissible == 0);
  REQUIRE(static_cast<int>(none.arcs.size()) == none.sampled);
  for (const DynamicWindowArc& a : none.arcs) {
    CHECK_FALSE(a.admissible);
    CHECK(a.score == 0);
  }
}
