// Tests for landmark bounds (ALT): exact landmark costs, A* with them equal to Dijkstra on maps
// costlier than the reference, the check that refuses maps where they would not hold.
#include <tessera/navigation/landmark_bounds.hpp>

#include <catch2/catch.hpp>

#include "planning_test_maps.hpp"

#include <random>
#include <stdexcept>

using namespace tessera;
using namespace tessera::navigation;

namespace {

/// A 70 x 50 map of random obstacles plus two walls with gaps, inflated so costs vary.
Costmap landmarkWorld(std::uint64_t seed) {
  Costmap map(70, 50, 0.05);
  std::mt19937_64 rng(seed);
  std::bernoulli_distribution obstacle(0.05);
  for (auto& c : map.cells) c = obstacle(rng) ? cost::kLethal : cost::kFree;
  for (int row = 0; row < 50; ++row)
    if (row < 20 || row > 23) map.at(23, row) = cost::kLethal;
  for (int row = 0; row < 50; ++row)
    if (row < 40 || row > 43) map.at(47, row) = cost::kLethal;
  planning_test::inflateGently(map);
  return map;
}

std::int64_t units(const GridPath& p, const Costmap& map) {
  return std::llround(p.cost / map.resolution * static_cast<double>(kStraightUnits));
}

}  // namespace

TEST_CASE("landmark costs are the planner's exact costs from and to each landmark",
          "[navigation]") {
  const Costmap map = landmarkWorld(1);
  GridPlannerOptions dijkstra_options;
  dijkstra_options.algorithm = SearchAlgorithm::kDijkstra;
  const LandmarkBounds bounds(map, dijkstra_options, 3);
  REQUIRE(bounds.count() == 3);
  GridPlanner dijkstra(dijkstra_options);
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector2i x = planning_test::randomTraversableCell(map, rng);
    const std::size_t i = map.index(x.x(), x.y());
    for (int j = 0; j < bounds.count(); ++j) {
      const Eigen::Vector2i l = bounds.landmarks()[static_cast<std::size_t>(j)];
      const GridPath out = dijkstra.plan(map, l, x), back = dijkstra.plan(map, x, l);
      if (!out.ok()) {
        CHECK(bounds.from(j, i) == LandmarkBounds::kUnreachable);
        CHECK(bounds.to(j, i) == LandmarkBounds::kUnreachable);
        continue;
      }
      CHECK(bounds.from(j, i) == units(out, map));
      CHECK(bounds.to(j, i) == units(back, map));
    }
  }
}

TEST_CASE("A* with landmark bounds finds Dijkstra's cost, also with obstacles added later",
          "[navigation]") {
  GridPlannerOptions dijkstra_options;
  dijkstra_options.algorithm = SearchAlgorithm::kDijkstra;
  GridPlanner dijkstra(dijkstra_options), plain, alt;
  std::mt19937_64 rng(9);
  std::size_t expanded_plain = 0, expanded_alt = 0;
  int solved = 0;
  for (int world = 0; world < 6; ++world) {
    const Costmap reference = landmarkWorld(static_cast<std::uint64_t>(world));
    alt.setLandmarks(std::make_shared<const LandmarkBounds>(reference, GridPlannerOptions{}, 4));
    for (int trial = 0; trial < 8; ++trial) {
      // Half the plans on the reference, half with extra obstacles (only ever costlier).
      Costmap map = reference;
      if (trial % 2 == 1) {
        std::bernoulli_distribution extra(0.03);
        for (auto& c : map.cells)
          if (extra(rng)) c = cost::kLethal;
      }
      const auto s = planning_test::randomTraversableCell(map, rng),
                 g = planning_test::randomTraversableCell(map, rng);
      const GridPath d = dijkstra.plan(map, s, g), p = plain.plan(map, s, g),
                     a = alt.plan(map, s, g);
      REQUIRE(a.status == d.status);
      CHECK(a.landmarks_used);
      if (!a.ok()) continue;
      ++solved;
      CHECK(units(a, map) == units(d, map));
      CHECK(a.cells.front() == s);
      CHECK(a.cells.back() == g);
      expanded_plain += p.expanded;
      expanded_alt += a.expanded;
    }
  }
  CHECK(solved > 30);
  CHECK(expanded_alt < expanded_plain);
}

TEST_CASE("landmark bounds are not used on a map cheaper than their reference", "[navigation]") {
  const Costmap reference = landmarkWorld(2);
  GridPlannerOptions dijkstra_options;
  dijkstra_options.algorithm = SearchAlgorithm::kDijkstra;
  const auto bounds = std::make_shared<const LandmarkBounds>(reference, GridPlannerOptions{}, 2);
  CHECK(bounds->holdsFor(reference, GridPlannerOptions{}));

  SECTION("a wall opened: the bounds would overestimate, so A* plans without them") {
    Costmap opened = reference;
    for (int row = 0; row < 50; ++row)
      for (int col = 20; col <= 26; ++col) opened.at(col, row) = cost::kFree;
    CHECK_FALSE(bounds->holdsFor(opened, GridPlannerOptions{}));
    GridPlanner alt, dijkstra(dijkstra_options);
    alt.setLandmarks(bounds);
    const Eigen::Vector2i s(5, 5), g(40, 5);
    const GridPath a = alt.plan(opened, s, g), d = dijkstra.plan(opened, s, g);
    REQUIRE(a.ok());
    CHECK_FALSE(a.landmarks_used);
    CHECK(units(a, opened) == units(d, opened));
  }
  SECTION("another size or cost model") {
    const Costmap other(71, 50, 0.05);
    CHECK_FALSE(bounds->holdsFor(other, GridPlannerOptions{}));
    GridPlannerOptions heavier;
    heavier.cost_weight = 5;
    CHECK_FALSE(bounds->holdsFor(reference, heavier));
    GridPlannerOptions unknown_allowed;
    unknown_allowed.allow_unknown = true;
    CHECK_FALSE(bounds->holdsFor(reference, unknown_allowed));
  }
  SECTION("unknown cells where the reference had free ones only hold when unknown is refused") {
    Costmap unknown = reference;
    unknown.at(10, 10) = cost::kUnknown;
    CHECK(bounds->holdsFor(unknown, GridPlannerOptions{}));
  }
}

TEST_CASE("a goal in another component is refused without searching the start's", "[navigation]") {
  Costmap map(40, 20, 0.05);
  for (int row = 0; row < 20; ++row) map.at(20, row) = cost::kLethal;
  const auto bounds = std::make_shared<const LandmarkBounds>(map, GridPlannerOptions{}, 2);
  GridPlanner alt;
  alt.setLandmarks(bounds);
  // The goal in the landmarks' half (they are picked in one component), the start in the other:
  // the start cannot reach a landmark the goal reaches, so nothing is searched.
  const bool left = bounds->landmarks()[0].x() < 20;
  const Eigen::Vector2i goal(left ? 2 : 37, 2), start(left ? 37 : 2, 10);
  const GridPath p = alt.plan(map, start, goal);
  CHECK(p.status == PlanStatus::kNoPath);
  CHECK(p.expanded == 0);
  // The other way round the goal reaches no landmark: A* falls back to the octile distance.
  const GridPath q = alt.plan(map, goal, start);
  CHECK(q.status == PlanStatus::kNoPath);
  CHECK_FALSE(q.landmarks_used);
}

TEST_CASE("landmark bounds refuse bad arguments", "[navigation]") {
  const Costmap map(10, 10, 0.05);
  CHECK_THROWS_AS(LandmarkBounds(map, GridPlannerOptions{}, 0), std::invalid_argument);
  CHECK_THROWS_AS(LandmarkBounds(map, GridPlannerOptions{}, 17), std::invalid_argument);
  const Costmap blocked(10, 10, 0.05, {}, cost::kLethal);
  CHECK_THROWS_WITH(LandmarkBounds(blocked, GridPlannerOptions{}, 2),
                    Catch::Contains("no passable cell"));
  GridPlannerOptions bad;
  bad.cost_weight = -1;
  CHECK_THROWS_AS(LandmarkBounds(map, bad, 2), std::invalid_argument);
  // A map smaller than the landmark count: as many landmarks as distinct cells allow.
  const Costmap tiny(2, 1, 0.05);
  const LandmarkBounds few(tiny, GridPlannerOptions{}, 5);
  CHECK(few.count() == 2);
  CHECK(few.from(0, 0) + few.from(1, 0) == kStraightUnits);
}
