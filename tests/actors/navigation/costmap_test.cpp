// Tests for the costmap: static layer thresholds, the obstacle distance transform, inflation.
#include <tessera/navigation/costmap.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

using namespace tessera;
using namespace tessera::navigation;

namespace {

Costmap randomObstacles(int w, int h, double density, std::uint64_t seed) {
  Costmap map(w, h, 0.1);
  std::mt19937_64 rng(seed);
  std::bernoulli_distribution obstacle(density);
  for (auto& c : map.cells) c = obstacle(rng) ? cost::kLethal : cost::kFree;
  return map;
}

}  // namespace

TEST_CASE("obstacle distance equals the brute-force nearest lethal cell", "[navigation]") {
  for (const double density : {0.002, 0.05, 0.3}) {
    const Costmap map = randomObstacles(37, 23, density, 7);
    const auto d = obstacleDistance(map);
    for (int r = 0; r < map.height; ++r)
      for (int c = 0; c < map.width; ++c) {
        double best = std::numeric_limits<double>::infinity();
        for (int r2 = 0; r2 < map.height; ++r2)
          for (int c2 = 0; c2 < map.width; ++c2)
            if (map.at(c2, r2) == cost::kLethal)
              best = std::min(best, std::hypot(c - c2, r - r2) * map.resolution);
        INFO("cell " << c << "," << r << " density " << density);
        REQUIRE(d[map.index(c, r)] == Approx(best).margin(1e-5));
      }
  }
}

TEST_CASE("obstacle distance is infinite on a map without obstacles", "[navigation]") {
  const Costmap map(5, 4, 0.05);
  for (const float d : obstacleDistance(map)) REQUIRE(std::isinf(d));
}

TEST_CASE("inflation marks the inscribed disc and decays beyond it", "[navigation]") {
  Costmap map(41, 41, 0.05);
  map.at(20, 20) = cost::kLethal;
  map.at(0, 0) = cost::kUnknown;
  map.at(20, 30) = 200;  // a cost a layer already wrote, higher than inflation gives there
  InflationOptions o;
  o.inscribed_radius = 0.2;
  o.inflation_radius = 0.6;
  o.cost_scaling = 5;
  inflate(map, o);
  CHECK(map.at(20, 20) == cost::kLethal);
  CHECK(int(map.at(24, 20)) == cost::kInscribed);  // 0.20 m
  CHECK(map.at(25, 20) == std::lround(252 * std::exp(-5 * 0.05)));
  CHECK(map.at(32, 20) == std::lround(252 * std::exp(-5 * 0.4)));  // 0.60 m: the last ring
  CHECK(map.at(33, 20) == cost::kFree);                            // 0.65 m
  CHECK(map.at(20, 30) == 200);                                    // never lowered
  CHECK(map.at(0, 0) == cost::kUnknown);
  // Monotone decay along a ray.
  for (int c = 25; c < 33; ++c) CHECK(int(map.at(c, 20)) >= int(map.at(c + 1, 20)));
}

TEST_CASE("static layer applies the occupancy thresholds", "[navigation]") {
  grid::OccupancyMap occ;
  occ.width = 5;
  occ.height = 1;
  occ.resolution = 0.1;
  occ.cells = {-1, 0, 25, 50, 65};
  const Costmap a = fromOccupancy(occ);
  CHECK(a.at(0, 0) == cost::kUnknown);
  CHECK(a.at(1, 0) == cost::kFree);
  CHECK(a.at(2, 0) == cost::kFree);
  CHECK(a.at(3, 0) == cost::kUnknown);
  CHECK(a.at(4, 0) == cost::kLethal);
  StaticLayerOptions o;
  o.unknown_is_free = true;
  CHECK(fromOccupancy(occ, o).at(0, 0) == cost::kFree);
}

TEST_CASE("costmap construction rejects bad input with the field named", "[navigation]") {
  grid::OccupancyMap empty;
  CHECK_THROWS_WITH(fromOccupancy(empty), Catch::Contains("empty"));
  grid::OccupancyMap truncated;
  truncated.width = 4;
  truncated.height = 4;
  truncated.cells.assign(15, 0);
  CHECK_THROWS_WITH(fromOccupancy(truncated), Catch::Contains("width x height"));
  StaticLayerOptions bad;
  bad.free_threshold = 80;
  CHECK_THROWS_WITH(fromOccupancy(truncated, bad), Catch::Contains("free_threshold"));
  CHECK_THROWS_WITH(Costmap(0, 3, 0.1), Catch::Contains("size"));
  CHECK_THROWS_WITH(Costmap(3, 3, std::nan("")), Catch::Contains("resolution"));
  Costmap map(3, 3, 0.1);
  InflationOptions o;
  o.inflation_radius = 0.1;
  o.inscribed_radius = 0.2;
  CHECK_THROWS_WITH(inflate(map, o), Catch::Contains("inflation_radius"));
  o = {};
  o.cost_scaling = std::nan("");
  CHECK_THROWS_WITH(inflate(map, o), Catch::Contains("cost_scaling"));
}
