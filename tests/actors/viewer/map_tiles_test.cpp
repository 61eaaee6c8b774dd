// Tests for MapTiler: tiles on the world's cell lattice, only changed tiles per update, new
// epochs when tiles cannot be updated in place, and refused grids.
#include <tessera/viewer/map_tiles.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

// Everything in a namespace of its own: unity builds put test files together.
namespace map_tiles_test {

using namespace tessera::viewer;

namespace {

struct Grid {
  std::vector<std::int8_t> cells;
  GridView view;
  Grid(int w, int h, double ox, double oy, double res = 0.05) : cells(w * h, -1) {
    view.resolution = res;
    view.width = w;
    view.height = h;
    view.origin_x = ox;
    view.origin_y = oy;
    view.cells = cells.data();
    view.cell_count = cells.size();
  }
  std::int8_t& at(int x, int y) { return cells[y * view.width + x]; }
};

std::int32_t i32(const std::string& s, std::size_t at) {
  std::int32_t v;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}

}  // namespace

TEST_CASE("a grid becomes lattice-anchored tiles with its cells in place", "[viewer][tiles]") {
  MapTiler tiler(4);
  Grid g(6, 5, /*ox=*/-0.10, /*oy=*/0.0);  // lattice cells -2..3 in x, 0..4 in y
  g.at(0, 0) = 100;                        // lattice (-2, 0): tile (-1, 0), cell (2, 0)
  g.at(5, 4) = 0;                          // lattice (3, 4): tile (0, 1), cell (3, 0)
  const auto u = tiler.update(g.view, 7, 8);
  CHECK(u.new_epoch);
  REQUIRE(u.tiles.size() == 4);  // tiles x -1..0, y 0..1
  CHECK(u.header.size() == 44);
  double res;
  std::memcpy(&res, u.header.data(), 8);
  CHECK(res == 0.05);
  bool seen_a = false, seen_b = false;
  for (const auto& [key, bytes] : u.tiles) {
    REQUIRE(bytes.size() == 8 + 16);
    const int tx = i32(bytes, 0), ty = i32(bytes, 4);
    CHECK(key == tileKey(tx, ty));
    const auto* c = reinterpret_cast<const std::int8_t*>(bytes.data() + 8);
    if (tx == -1 && ty == 0) {
      CHECK(c[0 * 4 + 2] == 100);
      CHECK(c[0 * 4 + 1] == -1);  // outside the grid
      seen_a = true;
    }
    if (tx == 0 && ty == 1) {
      CHECK(c[0 * 4 + 3] == 0);
      seen_b = true;
    }
  }
  CHECK(seen_a);
  CHECK(seen_b);
}

TEST_CASE("only changed tiles are sent, and a growing map keeps its old tiles", "[viewer][tiles]") {
  MapTiler tiler(4);
  Grid g(8, 8, 0.0, 0.0);
  CHECK(tiler.update(g.view, 0, 0).tiles.size() == 4);
  CHECK(tiler.update(g.view, 1, 0).tiles.empty());  // nothing changed
  g.at(5, 1) = 50;
  auto u = tiler.update(g.view, 2, 0);
  CHECK_FALSE(u.new_epoch);
  REQUIRE(u.tiles.size() == 1);
  CHECK(u.tiles[0].first == tileKey(1, 0));
  // The map grows by 4 cells to the left (origin moves by whole cells): same tiles, one more
  // column of them, all unknown.
  Grid bigger(12, 8, -0.20, 0.0);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) bigger.at(x + 4, y) = g.at(x, y);
  u = tiler.update(bigger.view, 3, 0);
  CHECK_FALSE(u.new_epoch);
  CHECK(u.tiles.size() == 2);  // the new column only
  for (const auto& t : u.tiles) CHECK(i32(t.second, 0) == -1);
  CHECK(tiler.tiles() == 6);
}

TEST_CASE("a new resolution, a sub-cell shift or a shrinking map starts a new epoch",
          "[viewer][tiles]") {
  MapTiler tiler(4);
  Grid g(8, 8, 0.0, 0.0);
  const auto first = tiler.update(g.view, 0, 0).epoch;
  Grid shifted(8, 8, 0.02, 0.0);
  auto u = tiler.update(shifted.view, 1, 0);
  CHECK(u.new_epoch);
  CHECK(u.epoch == first + 1);
  CHECK(u.tiles.size() == 4);
  Grid coarse(8, 8, 0.02, 0.0, 0.1);
  CHECK(tiler.update(coarse.view, 2, 0).new_epoch);
  Grid smaller(4, 4, 0.02, 0.0, 0.1);
  u = tiler.update(smaller.view, 3, 0);
  CHECK(u.new_epoch);
  CHECK(u.tiles.size() == 1);
}

TEST_CASE("grids that cannot be drawn are refused with the reason", "[viewer][tiles]") {
  MapTiler tiler(4);
  Grid g(4, 4, 0, 0);
  g.view.resolution = 0;
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("resolution"));
  g.view.resolution = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("resolution"));
  g.view.resolution = 0.05;
  g.view.origin_x = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("finite"));
  g.view.origin_x = 0;
  g.view.origin_theta = 0.3;
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("rotated"));
  g.view.origin_theta = 0;
  g.view.cell_count = 15;  // a message whose cells do not fill its width x height
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("4 x 4 cells carries 15"));
  g.view.cell_count = 17;
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("carries 17"));
  g.view.cell_count = 16;
  g.view.cells = nullptr;
  CHECK_THROWS_WITH(tiler.update(g.view, 0, 0), Catch::Contains("without cells"));
  g.view.width = 0;  // an empty grid is fine: no tiles
  g.view.cell_count = 0;
  CHECK(tiler.update(g.view, 0, 0).tiles.empty());
  CHECK_THROWS(MapTiler(0));
}

}  // namespace map_tiles_test
