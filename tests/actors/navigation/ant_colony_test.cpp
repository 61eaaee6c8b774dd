// Tests for the ant-colony refinement: never longer than its input, never through obstacles.
#include <tessera/navigation/ant_colony.hpp>
#include <tessera/navigation/grid_planner.hpp>

#include <catch2/catch.hpp>

#include <random>

using namespace tessera;
using namespace tessera::navigation;

namespace {

Costmap rooms(std::uint64_t seed) {
  Costmap map(80, 60, 0.05);
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> col(5, 74), row(5, 54), len(5, 20);
  for (int k = 0; k < 8; ++k) {  // random wall pieces
    const int c = col(rng), r = row(rng), l = len(rng);
    const bool horizontal = k % 2 == 0;
    for (int i = 0; i < l; ++i) {
      const int cc = horizontal ? c + i : c, rr = horizontal ? r : r + i;
      if (map.contains(cc, rr)) map.at(cc, rr) = cost::kLethal;
    }
  }
  return map;
}

}  // namespace

TEST_CASE("ant colony refinement never lengthens the path nor crosses obstacles", "[navigation]") {
  GridPlanner planner;
  AntColonyRefiner refiner;
  int checked = 0, improved = 0;
  for (std::uint64_t trial = 0; trial < 12; ++trial) {
    const Costmap map = rooms(trial);
    const GridPath path = planner.plan(map, {1, 1}, {78, 58});
    if (!path.ok()) continue;
    ++checked;
    AntColonySummary summary;
    const auto refined = refiner.refine(map, path.cells, &summary);
    REQUIRE(refined.size() >= 2);
    CHECK(refined.front() == path.cells.front());
    CHECK(refined.back() == path.cells.back());
    CHECK(pathLength(map, refined) == Approx(summary.output_length));
    CHECK(summary.output_length <= summary.input_length + 1e-9);
    CHECK(summary.input_length <= path.length + 1e-9);
    for (std::size_t i = 1; i < refined.size(); ++i)
      CHECK(lineOfSight(map, refined[i - 1], refined[i], cost::kMaxTraversable));
    if (summary.improvements > 0) ++improved;
    CHECK(summary.ants_arrived > 0);
  }
  CHECK(checked >= 8);
  CHECK(improved >= checked / 3);  // 8 of 12 when written: the colony does find shorter cuts
}

TEST_CASE("ant colony refinement is deterministic for a seed", "[navigation]") {
  const Costmap map = rooms(5);
  const GridPath path = GridPlanner().plan(map, {1, 1}, {78, 58});
  REQUIRE(path.ok());
  const AntColonyRefiner a, b;
  CHECK(a.refine(map, path.cells) == b.refine(map, path.cells));
}

TEST_CASE("ant colony options are checked", "[navigation]") {
  AntColonyOptions o;
  o.evaporation = 1.5;
  CHECK_THROWS_WITH(AntColonyRefiner(o), Catch::Contains("evaporation"));
  o = {};
  o.ants = 0;
  CHECK_THROWS_WITH(AntColonyRefiner(o), Catch::Contains("ants"));
  o = {};
  o.max_cost = 253;
  CHECK_THROWS_WITH(AntColonyRefiner(o), Catch::Contains("max_cost"));
}
