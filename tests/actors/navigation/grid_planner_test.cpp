// Tests for the global planner: A* equals Dijkstra's cost, statuses, line-of-sight shortening.
#include <tessera/navigation/grid_planner.hpp>

#include <catch2/catch.hpp>

#include "planning_test_maps.hpp"

#include <cmath>
#include <random>

using namespace tessera;
using namespace tessera::navigation;

namespace {

/// A 60 x 40 map with random obstacles, inflated so costs vary.
Costmap clutter(std::uint64_t seed) {
  Costmap map(60, 40, 0.05);
  std::mt19937_64 rng(seed);
  std::bernoulli_distribution obstacle(0.06);
  for (auto& c : map.cells) c = obstacle(rng) ? cost::kLethal : cost::kFree;
  planning_test::inflateGently(map);
  return map;
}

Eigen::Vector2i freeCell(const Costmap& map, std::mt19937_64& rng) {
  return planning_test::randomTraversableCell(map, rng);
}

}  // namespace

TEST_CASE("A* finds paths as cheap as Dijkstra's while expanding fewer cells", "[navigation]") {
  GridPlannerOptions dijkstra_options;
  dijkstra_options.algorithm = SearchAlgorithm::kDijkstra;
  GridPlanner astar, dijkstra(dijkstra_options);
  std::mt19937_64 rng(3);
  int solved = 0;
  std::size_t expanded_astar = 0, expanded_dijkstra = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Costmap map = clutter(static_cast<std::uint64_t>(trial));
    const auto s = freeCell(map, rng), g = freeCell(map, rng);
    const GridPath a = astar.plan(map, s, g), d = dijkstra.plan(map, s, g);
    REQUIRE(a.status == d.status);
    if (!a.ok()) continue;
    ++solved;
    CHECK(a.cost == Approx(d.cost).epsilon(1e-9));
    CHECK(a.cells.front() == s);
    CHECK(a.cells.back() == g);
    for (std::size_t i = 1; i < a.cells.size(); ++i) {
      const Eigen::Vector2i step = a.cells[i] - a.cells[i - 1];
      CHECK(step.cwiseAbs().maxCoeff() == 1);
      CHECK(map.at(a.cells[i]) <= cost::kMaxTraversable);
    }
    expanded_astar += a.expanded;
    expanded_dijkstra += d.expanded;
  }
  CHECK(solved >= 30);
  CHECK(expanded_astar < expanded_dijkstra);
}

TEST_CASE("the reported cost is the path's cost under the step model, and reuse changes nothing",
          "[navigation]") {
  // One planner reused over many maps of one size (its search state carries over between
  // plans) against a fresh planner per plan; the cost summed in metres along the cells.
  GridPlanner reused;
  std::mt19937_64 rng(5);
  int solved = 0;
  for (int trial = 0; trial < 25; ++trial) {
    const Costmap map = clutter(200 + static_cast<std::uint64_t>(trial));
    const auto s = freeCell(map, rng), g = freeCell(map, rng);
    const GridPath a = reused.plan(map, s, g), fresh = GridPlanner().plan(map, s, g);
    REQUIRE(a.status == fresh.status);
    CHECK(a.cells == fresh.cells);
    CHECK(a.expanded == fresh.expanded);
    if (!a.ok()) continue;
    ++solved;
    double cost = 0;
    for (std::size_t i = 1; i < a.cells.size(); ++i) {
      const double step = (a.cells[i] - a.cells[i - 1]).cast<double>().norm() * map.resolution;
      cost += step * (1 + GridPlannerOptions{}.cost_weight * map.at(a.cells[i]) / 252.0);
    }
    // Step costs are rounded to 1/169 of a cell side's cost: at most 0.3 % off per step.
    CHECK(a.cost == Approx(cost).epsilon(3e-3));
  }
  CHECK(solved >= 15);
}

TEST_CASE("a planner reused over more plans than its marks have generations plans as a fresh one",
          "[navigation]") {
  // The marks wrap after 127 plans and are reset: plans on either side of that agree with a
  // fresh planner's, including a search that ends without a path.
  const Costmap map = clutter(77);
  Costmap walled = map;
  for (int r = 0; r < walled.height; ++r) walled.at(30, r) = cost::kLethal;
  GridPlanner reused;
  std::mt19937_64 rng(9);
  for (int trial = 0; trial < 300; ++trial) {
    const Costmap& m = trial % 7 == 3 ? walled : map;
    const auto s = freeCell(m, rng), g = freeCell(m, rng);
    const GridPath a = reused.plan(m, s, g), fresh = GridPlanner().plan(m, s, g);
    REQUIRE(a.status == fresh.status);
    REQUIRE(a.cells == fresh.cells);
    REQUIRE(a.cost == fresh.cost);
  }
}

TEST_CASE("a path too costly for the search's 32-bit costs is an error, not a wrong path",
          "[navigation]") {
  // A serpentine of 450 lanes, 600 cells each, every cell at the highest traversable cost and
  // cost_weight 100: ~270 000 steps of 101 x 169 units, beyond 2^32.
  Costmap map(600, 900, 0.05, {}, 252);
  for (int r = 1; r < map.height; r += 2)
    for (int c = 0; c < map.width; ++c)
      if (c != ((r / 2) % 2 == 0 ? map.width - 1 : 0)) map.at(c, r) = cost::kLethal;
  GridPlannerOptions o;
  o.cost_weight = 100;
  GridPlanner planner(o);
  CHECK_THROWS_AS(planner.plan(map, {0, 0}, {0, map.height - 1}), std::overflow_error);
  // A short path on the same map still plans, and the long one at the default weight.
  CHECK(planner.plan(map, {0, 0}, {50, 0}).ok());
  const GridPath snake = GridPlanner().plan(map, {0, 0}, {0, map.height - 1});
  REQUIRE(snake.ok());
  CHECK(snake.cells.size() > 260000);
}

TEST_CASE("costs make the planner detour around inflated cells when it is cheap", "[navigation]") {
  Costmap map(30, 11, 0.1);
  for (int c = 10; c < 20; ++c) map.at(c, 5) = 200;  // an expensive band across the straight line
  GridPlannerOptions o;
  o.cost_weight = 0;
  const GridPath straight = GridPlanner(o).plan(map, {0, 5}, {29, 5});
  REQUIRE(straight.ok());
  CHECK(straight.length == Approx(2.9));
  o.cost_weight = 3;
  const GridPath around = GridPlanner(o).plan(map, {0, 5}, {29, 5});
  REQUIRE(around.ok());
  for (const auto& c : around.cells) CHECK(map.at(c) == cost::kFree);
  CHECK(around.length > straight.length);
}

TEST_CASE("the planner reports why it found no path", "[navigation]") {
  Costmap map(20, 20, 0.1);
  for (int r = 0; r < 20; ++r) map.at(10, r) = cost::kLethal;  // a wall across the map
  map.at(3, 3) = cost::kInscribed;
  map.at(4, 4) = cost::kUnknown;
  GridPlanner planner;
  CHECK(planner.plan(map, {-1, 0}, {5, 5}).status == PlanStatus::kStartOutside);
  CHECK(planner.plan(map, {0, 0}, {5, 20}).status == PlanStatus::kGoalOutside);
  CHECK(planner.plan(map, {3, 3}, {5, 5}).status == PlanStatus::kStartBlocked);
  CHECK(planner.plan(map, {0, 0}, {10, 5}).status == PlanStatus::kGoalBlocked);
  CHECK(planner.plan(map, {0, 0}, {4, 4}).status == PlanStatus::kGoalBlocked);
  const GridPath none = planner.plan(map, {0, 0}, {15, 5});
  CHECK(none.status == PlanStatus::kNoPath);
  CHECK(none.cells.empty());
  CHECK(statusName(none.status) == "no path");
  GridPlannerOptions o;
  o.allow_unknown = true;
  CHECK(GridPlanner(o).plan(map, {0, 0}, {4, 4}).ok());
  o.unknown_cost = 300;
  CHECK_THROWS_WITH(GridPlanner(o), Catch::Contains("unknown_cost"));
  o.unknown_cost = 128;
  o.cost_weight = 101;
  CHECK_THROWS_WITH(GridPlanner(o), Catch::Contains("cost_weight"));
}

TEST_CASE("diagonal steps never squeeze between two blocked cells", "[navigation]") {
  Costmap map(3, 3, 0.1);
  map.at(1, 0) = cost::kLethal;
  map.at(0, 1) = cost::kLethal;
  map.at(2, 1) = cost::kLethal;
  map.at(1, 2) = cost::kLethal;
  // (0,0) and (1,1) touch only at a corner between two obstacles.
  CHECK(GridPlanner().plan(map, {0, 0}, {1, 1}).status == PlanStatus::kNoPath);
}

TEST_CASE("line-of-sight shortening never crosses obstacles and never lengthens", "[navigation]") {
  GridPlanner planner;
  std::mt19937_64 rng(11);
  int checked = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const Costmap map = clutter(100 + static_cast<std::uint64_t>(trial));
    const GridPath path = planner.plan(map, freeCell(map, rng), freeCell(map, rng));
    if (!path.ok()) continue;
    ++checked;
    const auto short_path = shortenPath(map, path.cells, cost::kMaxTraversable);
    CHECK(short_path.front() == path.cells.front());
    CHECK(short_path.back() == path.cells.back());
    CHECK(pathLength(map, short_path) <= path.length + 1e-9);
    for (std::size_t i = 1; i < short_path.size(); ++i) {
      CHECK(lineOfSight(map, short_path[i - 1], short_path[i], cost::kMaxTraversable));
      // Densely sampled, the segment stays off obstacles.
      const Eigen::Vector2d a = short_path[i - 1].cast<double>().array() + 0.5;
      const Eigen::Vector2d b = short_path[i].cast<double>().array() + 0.5;
      for (int k = 0; k <= 200; ++k) {
        const Eigen::Vector2d p = a + (b - a) * (k / 200.0);
        CHECK(map.at(static_cast<int>(std::floor(p.x())), static_cast<int>(std::floor(p.y()))) <=
              cost::kMaxTraversable);
      }
    }
  }
  CHECK(checked >= 20);
}

TEST_CASE("line of sight is blocked by a cell the segment only grazes at a corner",
          "[navigation]") {
  Costmap map(3, 3, 0.1);
  map.at(1, 0) = cost::kLethal;
  CHECK_FALSE(lineOfSight(map, {0, 0}, {1, 1}, cost::kMaxTraversable));  // through (1,0)'s corner
  CHECK_FALSE(lineOfSight(map, {0, 0}, {2, 2}, cost::kMaxTraversable));
  CHECK(lineOfSight(map, {0, 1}, {1, 2}, cost::kMaxTraversable));
  CHECK(lineOfSight(map, {0, 1}, {2, 1}, cost::kMaxTraversable));
  CHECK_FALSE(lineOfSight(map, {0, 0}, {2, 0}, cost::kMaxTraversable));
  CHECK_FALSE(lineOfSight(map, {0, 0}, {5, 0}, cost::kMaxTraversable));
}
