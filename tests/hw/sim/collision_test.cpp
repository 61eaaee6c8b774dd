#include <tessera/sim/collision.hpp>
#include <tessera/sim/furniture.hpp>
#include <tessera/sim/world.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

using tessera::sim::footprintClearance;
using tessera::sim::footprintOccupancy;
using tessera::sim::FootprintOptions;
using tessera::sim::FurnitureBox;
using tessera::sim::makeTable;
using tessera::sim::wallOccupancy;
using tessera::sim::World;

namespace {

// A 6 m x 4 m room (one 0.05 m wall cell thick) with a 0.75 m table over [2, 3.5] x [1.5, 2.5]:
// legs of 0.05 m at the corners, the top from 0.71 m to 0.75 m.
World roomWithTable() {
  World w = World::box(6.0, 4.0, 0.05);
  w.addFurniture(makeTable(2.0, 1.5, 3.5, 2.5));
  return w;
}

std::int8_t cellAt(const World& w, const std::vector<std::int8_t>& cells, double x, double y) {
  const Eigen::Vector2i c = w.cellOf({x, y});
  return cells.at(static_cast<std::size_t>(c.y()) * w.width() + c.x());
}

}  // namespace

TEST_CASE("footprintClearance: walls and the map border as World::clearance", "[sim][collision]") {
  const World box = World::box(6.0, 4.0, 0.05);
  // The wall ring's inner edge is at 0.05 m.
  CHECK(footprintClearance(box, {0.3, 2.0}, 1.0, 1.0) == Approx(0.25));
  CHECK(footprintClearance(box, {3.0, 3.8}, 1.0, 1.0) == Approx(0.15));
  CHECK(footprintClearance(box, {3.0, 2.0}, 1.0, 0.7) == 0.7);   // capped
  CHECK(footprintClearance(box, {0.02, 2.0}, 1.0, 1.0) == 0.0);  // in a wall cell

  const World open(40, 40, 0.05);  // 2 m x 2 m, no walls: the border bounds it
  CHECK(footprintClearance(open, {0.1, 1.0}, 1.0, 1.0) == Approx(0.1));
  CHECK(footprintClearance(open, {1.0, 1.9}, 1.0, 1.0) == Approx(0.1));
  CHECK(footprintClearance(open, {-0.5, 1.0}, 1.0, 1.0) == 0.0);  // outside the map
}

TEST_CASE("footprintClearance: furniture counts only below the body's top", "[sim][collision]") {
  const World w = roomWithTable();
  // Below the table's edge, 0.1 m short of it in y, between the legs in x.
  const Eigen::Vector2d p(2.75, 1.4);
  CHECK(footprintClearance(w, p, 1.0, 1.0) == Approx(0.1));  // the top (0.71 m) is in reach
  // A 0.5 m body passes under the top; the nearest leg corner is at (2.05, 1.5) or (3.45, 1.5).
  CHECK(footprintClearance(w, p, 0.5, 1.0) == Approx(std::hypot(0.7, 0.1)));
  // The same body beside a leg: 0.05 m from its face.
  CHECK(footprintClearance(w, {1.95, 1.52}, 0.5, 1.0) == Approx(0.05));
  // Inside a box: 0, at any height that reaches it.
  CHECK(footprintClearance(w, {2.02, 1.52}, 0.5, 1.0) == 0.0);
  CHECK(footprintClearance(w, {2.75, 2.0}, 1.0, 1.0) == 0.0);  // under the top, tall body
  // The short body under the top: the nearest leg is at a corner.
  CHECK(footprintClearance(w, {2.75, 2.0}, 0.5, 1.0) == Approx(std::hypot(0.7, 0.45)));
  // A box starting exactly at the body's top is passed under.
  World shelf = World::box(6.0, 4.0, 0.05);
  shelf.addFurniture({FurnitureBox{{1.0, 1.0, 0.8}, {2.0, 2.0, 1.2}}});
  CHECK(footprintClearance(shelf, {1.5, 1.5}, 0.8, 0.5) == 0.5);
  CHECK(footprintClearance(shelf, {1.5, 1.5}, 0.81, 0.5) == 0.0);
}

TEST_CASE("footprintOccupancy: walls and the furniture a body of that height meets",
          "[sim][collision]") {
  const World w = roomWithTable();
  const auto walls = wallOccupancy(w);
  const auto low = footprintOccupancy(w, 0.5);
  const auto tall = footprintOccupancy(w, 1.0);
  REQUIRE(walls.size() == static_cast<std::size_t>(w.width()) * w.height());
  REQUIRE(low.size() == walls.size());
  REQUIRE(tall.size() == walls.size());

  for (const auto* cells : {&walls, &low, &tall}) {
    CHECK(cellAt(w, *cells, 0.02, 0.02) == 100);  // wall corner
    CHECK(cellAt(w, *cells, 5.98, 2.0) == 100);   // wall
    CHECK(cellAt(w, *cells, 1.0, 1.0) == 0);      // free floor
    CHECK(cellAt(w, *cells, 4.5, 3.0) == 0);
  }
  // A leg: an obstacle to both bodies, invisible in the wall map.
  CHECK(cellAt(w, walls, 2.02, 1.52) == 0);
  CHECK(cellAt(w, low, 2.02, 1.52) == 100);
  CHECK(cellAt(w, tall, 2.02, 1.52) == 100);
  CHECK(cellAt(w, low, 3.47, 2.47) == 100);
  // Under the top, between the legs: free for the short body only.
  CHECK(cellAt(w, low, 2.75, 2.0) == 0);
  CHECK(cellAt(w, tall, 2.75, 2.0) == 100);
  // The leg covers exactly its cell: the neighbours are free for the short body.
  CHECK(cellAt(w, low, 1.97, 1.52) == 0);
  CHECK(cellAt(w, low, 2.07, 1.52) == 0);
  CHECK(cellAt(w, tall, 1.97, 2.0) == 0);  // the top ends at x = 2.0
  CHECK(cellAt(w, tall, 3.52, 2.0) == 0);  // and at x = 3.5

  // Counts: the short body adds the four legs (one cell each), the tall one the whole top
  // (30 x 20 cells).
  auto count = [](const std::vector<std::int8_t>& cells) {
    return std::count(cells.begin(), cells.end(), std::int8_t{100});
  };
  CHECK(count(low) == count(walls) + 4);
  CHECK(count(tall) == count(walls) + 30 * 20);
}

TEST_CASE("footprintOccupancy: a leg thinner than a cell still marks its cell",
          "[sim][collision]") {
  World w = World::box(2.0, 2.0, 0.05);
  // 0.02 m wide, inside cell (20, 20) = [1.0, 1.05)^2 but off its centre (1.025).
  w.addFurniture({FurnitureBox{{1.028, 1.028, 0.0}, {1.048, 1.048, 0.45}}});
  const auto cells = footprintOccupancy(w, 1.0);
  CHECK(cellAt(w, cells, 1.04, 1.04) == 100);
  CHECK(cellAt(w, cells, 0.99, 1.04) == 0);
  CHECK(cellAt(w, cells, 1.06, 1.04) == 0);
  CHECK(cellAt(w, cells, 1.04, 1.06) == 0);
  const auto walls = wallOccupancy(w);
  CHECK(std::count(cells.begin(), cells.end(), std::int8_t{100}) ==
        std::count(walls.begin(), walls.end(), std::int8_t{100}) + 1);
  // A box outside the map marks nothing and does not crash.
  w.addFurniture({FurnitureBox{{-3.0, -3.0, 0.0}, {-2.0, -2.0, 1.0}},
                  FurnitureBox{{5.0, 1.0, 0.0}, {7.0, 1.5, 1.0}}});
  CHECK(footprintOccupancy(w, 1.0) == cells);
}

TEST_CASE("FootprintOptions: radius and height must be positive and finite", "[sim][collision]") {
  CHECK_FALSE(FootprintOptions{}.check().problem());
  auto keyOf = [](FootprintOptions o) {
    const tessera::ConfigCheck c = o.check();
    return c.problem() ? c.problem()->key : std::string();
  };
  CHECK(keyOf({0.0, 1.0}) == "radius");
  CHECK(keyOf({std::numeric_limits<double>::quiet_NaN(), 1.0}) == "radius");
  CHECK(keyOf({0.2, -1.0}) == "height");
  CHECK(keyOf({0.2, std::numeric_limits<double>::infinity()}) == "height");
}
