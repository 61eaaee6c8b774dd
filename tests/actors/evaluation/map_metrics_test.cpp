// Map quality against true walls (evaluation/map_metrics.hpp).
#include <tessera/evaluation/map_metrics.hpp>

#include <catch2/catch.hpp>

#include "../../shared_data.hpp"

#include <filesystem>
#include <fstream>

namespace map_metrics_test {

using namespace tessera::evaluation;

/// A 10 x 10 m map at 0.1 m, free everywhere, origin (-5, -5).
tessera::grid::OccupancyMap freeMap() {
  tessera::grid::OccupancyMap m;
  m.resolution = 0.1;
  m.width = m.height = 100;
  m.origin = tessera::Pose2(-5, -5, 0);
  m.cells.assign(100 * 100, 0);
  return m;
}

void occupy(tessera::grid::OccupancyMap& m, double x, double y) {
  const int c = static_cast<int>(std::floor((x + 5) / 0.1)),
            r = static_cast<int>(std::floor((y + 5) / 0.1));
  m.cells[static_cast<std::size_t>(r) * 100 + c] = 100;
}

TEST_CASE("map quality finds true walls, false walls and doubled walls", "[evaluation][map]") {
  // One true wall along y = 0 from x = -2 to 2.
  const std::vector<WallSegment> walls = {{{-2, 0}, {2, 0}}};
  auto m = freeMap();
  for (int k = 0; k < 20; ++k) occupy(m, -1.95 + 0.1 * k, 0.05);  // the left half drawn
  for (int k = 0; k < 10; ++k) occupy(m, -1.95 + 0.1 * k, 0.45);  // 1 m doubled 0.4 m beside
  occupy(m, 3.05, 3.05);                                          // a wall in free space
  const auto s = scoreMapAgainstWalls(m, walls);
  CHECK(s.wall_points_seen == 81);  // every 5 cm over 4 m, all in observed (free) area
  CHECK(s.wall_cells_found == Approx(0.54).margin(0.03));  // 2 m + the tolerance of 4 m
  CHECK(s.doubled_wall_cells == 10);
  CHECK(s.false_wall_cells == 11);
  // Unobserved space does not count against the map.
  auto unknown = freeMap();
  std::fill(unknown.cells.begin(), unknown.cells.end(), -1);
  CHECK(scoreMapAgainstWalls(unknown, walls).wall_points_seen == 0);
  CHECK_THROWS(scoreMapAgainstWalls(tessera::grid::OccupancyMap{}, walls));
}

TEST_CASE("a wall drawn once beside its place is displaced, not doubled", "[evaluation][map]") {
  // Two true walls along y = 0 and y = 3. The first drawn in place and again 0.4 m beside it
  // (a misaligned pass), the second only 0.4 m off (the map bent there).
  const std::vector<WallSegment> walls = {{{-2, 0}, {2, 0}}, {{-2, 3}, {2, 3}}};
  auto m = freeMap();
  for (int k = 0; k < 40; ++k) {
    occupy(m, -1.95 + 0.1 * k, 0.05);
    occupy(m, -1.95 + 0.1 * k, 0.45);
    occupy(m, -1.95 + 0.1 * k, 3.45);
  }
  const auto s = scoreMapAgainstWalls(m, walls);
  CHECK(s.false_wall_cells == 80);
  CHECK(s.doubled_wall_cells == 40);
  CHECK(s.displaced_wall_cells == 40);
  CHECK(s.wall_cells_found == Approx(0.5).margin(0.03));
}

TEST_CASE("walls files: comments, malformed, NaN, truncated and empty", "[evaluation][map]") {
  const auto dir = tessera::test::scratchDir("map_metrics_walls");
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return (dir / name).string();
  };
  const auto ok = readWalls(write("ok.txt", "# walls\n0 0 1 0\n\n1 0 1 1  # right\n"));
  REQUIRE(ok.size() == 2);
  CHECK(ok[1].b.y() == 1);
  CHECK(readWalls(write("empty.txt", "")).empty());
  CHECK_THROWS_WITH(readWalls(write("short.txt", "0 0 1 0\n0 0 1\n")),
                    Catch::Contains("short.txt:2") && Catch::Contains("x0 y0 x1 y1"));
  CHECK_THROWS_WITH(readWalls(write("bad.txt", "0 0 one 0\n")), Catch::Contains("bad.txt:1"));
  CHECK_THROWS_WITH(readWalls(write("nan.txt", "0 0 nan 0\n")), Catch::Contains("nan.txt:1"));
  CHECK_THROWS_WITH(readWalls((dir / "missing.txt").string()), Catch::Contains("cannot read"));
  std::filesystem::remove_all(dir);
}

}  // namespace map_metrics_test
