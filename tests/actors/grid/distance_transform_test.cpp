// Tests for the grid distance transform's edge cases (its accuracy is checked against brute force
// through navigation's obstacleDistance).
#include <tessera/grid/distance_transform.hpp>

#include <catch2/catch.hpp>

#include <cmath>

using namespace tessera::grid;

TEST_CASE("distance transform of a single marked cell is the Euclidean distance", "[grid]") {
  std::vector<std::uint8_t> marked(7 * 5, 0);
  marked[2 * 7 + 3] = 1;  // (col 3, row 2)
  const auto d = distanceTransform(marked, 7, 5);
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 7; ++c) CHECK(d[r * 7 + c] == Approx(std::hypot(c - 3, r - 2)));
}

TEST_CASE("distance transform handles empty and unmarked grids and rejects bad sizes", "[grid]") {
  CHECK(distanceTransform({}, 0, 0).empty());
  for (const float x : distanceTransform(std::vector<std::uint8_t>(6, 0), 3, 2))
    CHECK(std::isinf(x));
  CHECK_THROWS_WITH(distanceTransform(std::vector<std::uint8_t>(5, 0), 3, 2),
                    Catch::Contains("3 x 2"));
  CHECK_THROWS_WITH(distanceTransform(std::vector<std::uint8_t>(6, 0), -3, -2),
                    Catch::Contains("-3 x -2"));
}
