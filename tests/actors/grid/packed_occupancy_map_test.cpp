// Tests for PackedOccupancyMap: an OccupancyMap with its cells kept zstd-compressed.
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/grid/packed_occupancy_map.hpp>

#include <catch2/catch.hpp>

#include <cstddef>
#include <cstdint>
#include <random>
#include <stdexcept>

using tessera::Pose2;
using tessera::grid::OccupancyMap;
using tessera::grid::PackedOccupancyMap;

namespace {

OccupancyMap packedTestMap(int width, int height, std::int8_t fill) {
  OccupancyMap m;
  m.resolution = 0.05;
  m.width = width;
  m.height = height;
  m.origin = Pose2(-3.25, 1.5, 0.3);
  m.cells.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), fill);
  return m;
}

void requireSameMap(const OccupancyMap& a, const OccupancyMap& b) {
  CHECK(a.resolution == b.resolution);
  CHECK(a.width == b.width);
  CHECK(a.height == b.height);
  CHECK(a.origin.x == b.origin.x);
  CHECK(a.origin.y == b.origin.y);
  CHECK(a.origin.theta == b.origin.theta);
  REQUIRE(a.cells.size() == b.cells.size());
  CHECK(a.cells == b.cells);
}

}  // namespace

TEST_CASE("packed occupancy map round trips random cells exactly", "[grid][packed_map]") {
  OccupancyMap m = packedTestMap(173, 91, 0);  // odd sizes: no alignment to rely on
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> value(-1, 100);
  for (auto& c : m.cells) c = static_cast<std::int8_t>(value(rng));
  const PackedOccupancyMap packed(m);
  CHECK_FALSE(packed.empty());
  CHECK(packed.width() == 173);
  CHECK(packed.height() == 91);
  CHECK(packed.cellCount() == m.cells.size());
  CHECK(packed.resolution() == m.resolution);
  CHECK(packed.origin().theta == m.origin.theta);
  requireSameMap(packed.unpack(), m);
  // Copies hold the same bytes and unpack to the same map.
  const PackedOccupancyMap copy = packed;
  CHECK(copy.bytes() == packed.bytes());
  requireSameMap(copy.unpack(), m);
}

TEST_CASE("packed occupancy map round trips an all-unknown grid in a few bytes",
          "[grid][packed_map]") {
  const OccupancyMap m = packedTestMap(400, 300, OccupancyMap::kUnknown);
  const PackedOccupancyMap packed(m);
  requireSameMap(packed.unpack(), m);
  CHECK(packed.bytes() > 0);
  CHECK(packed.bytes() < m.cells.size() / 100);
}

TEST_CASE("an empty packed occupancy map holds nothing and unpacks to an empty map",
          "[grid][packed_map]") {
  const PackedOccupancyMap none;
  CHECK(none.empty());
  CHECK(none.bytes() == 0);
  CHECK(none.cellCount() == 0);
  CHECK(none.unpack().empty());
  CHECK(none.unpack().cells.empty());

  OccupancyMap zero = packedTestMap(0, 5, 0);  // 0 x 5: no cells, geometry kept
  const PackedOccupancyMap packed(zero);
  CHECK(packed.empty());
  CHECK(packed.bytes() == 0);
  const OccupancyMap back = packed.unpack();
  CHECK(back.empty());
  CHECK(back.width == 0);
  CHECK(back.height == 5);
  CHECK(back.cells.empty());
  CHECK(back.origin.x == zero.origin.x);
}

TEST_CASE("packed occupancy map refuses cells that do not match width x height",
          "[grid][packed_map]") {
  OccupancyMap m = packedTestMap(20, 10, 0);
  m.cells.pop_back();
  CHECK_THROWS_AS(PackedOccupancyMap(m), std::invalid_argument);
  CHECK_THROWS_WITH(PackedOccupancyMap(m), Catch::Contains("199 cells") &&
                                               Catch::Contains("20x10") &&
                                               Catch::Contains("200 expected"));
  m.cells.assign(201, 0);
  CHECK_THROWS_AS(PackedOccupancyMap(m), std::invalid_argument);
  OccupancyMap negative = packedTestMap(0, 0, 0);
  negative.width = -2;
  negative.height = -3;  // -2 x -3 = 6: must not pass for 6 cells
  negative.cells.assign(6, 0);
  CHECK_THROWS_WITH(PackedOccupancyMap(negative), Catch::Contains("negative"));
}

TEST_CASE("packed occupancy map of a typical submap is much smaller than its cells",
          "[grid][packed_map]") {
  // A mostly unknown 400 x 400 grid (a 20 m submap at 5 cm): a free room with walls, a few
  // noisy occupancy values near the walls, as a laser submap looks.
  OccupancyMap m = packedTestMap(400, 400, OccupancyMap::kUnknown);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> noise(0, 20);
  for (int r = 120; r < 300; ++r)
    for (int c = 100; c < 320; ++c) {
      const bool wall = r == 120 || r == 299 || c == 100 || c == 319;
      const bool near_wall = r < 124 || r > 295 || c < 104 || c > 315;
      m.at(c, r) = static_cast<std::int8_t>(wall ? 100 - noise(rng) : near_wall ? noise(rng) : 0);
    }
  const PackedOccupancyMap packed(m);
  INFO("packed " << packed.bytes() << " bytes for " << m.cells.size() << " cells");
  CHECK(packed.bytes() * 10 < m.cells.size());
  requireSameMap(packed.unpack(), m);
}
