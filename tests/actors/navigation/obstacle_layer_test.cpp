// Tests for the obstacle layer: laser marking and clearing, 3D points in the robot's height band,
// a table top the laser cannot see.
#include <tessera/navigation/obstacle_layer.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

using namespace tessera;
using namespace tessera::navigation;
using Cell = ObstacleLayer::Cell;

namespace {

/// 6 x 4 m at 5 cm, origin (-1, -2): cell of (x, y) = ((x + 1) / 0.05, (y + 2) / 0.05).
Costmap area() {
  return Costmap(120, 80, 0.05, Pose2(-1, -2, 0), cost::kUnknown);
}

Cell cellAt(const ObstacleLayer& layer, const Costmap& map, double x, double y) {
  const Eigen::Vector2i c = map.cellOf({x, y});
  return layer.at(c.x(), c.y());
}

}  // namespace

TEST_CASE("a laser beam clears what it crosses and marks where it ends", "[navigation]") {
  const Costmap map = area();
  ObstacleLayer layer(map);
  const Eigen::Vector3d laser(0, 0, 0.2);
  const std::vector<Eigen::Vector2d> hits = {{2.0, 0.0}, {0.0, 1.5}, {3.5, -1.0}};
  const std::vector<std::uint8_t> no_return = {0, 1, 0};
  layer.addScan(laser, hits, no_return);
  CHECK(cellAt(layer, map, 2.01, 0.01) == Cell::kObstacle);
  CHECK(cellAt(layer, map, 1.0, 0.01) == Cell::kFree);
  CHECK(cellAt(layer, map, 0.01, 1.51) == Cell::kUnknown);  // no return: the endpoint stays
  CHECK(cellAt(layer, map, 0.01, 1.0) == Cell::kFree);
  CHECK(cellAt(layer, map, 3.51, -0.99) == Cell::kUnknown);  // beyond mark_range (2.5 m)
  CHECK(cellAt(layer, map, -0.5, 1.0) == Cell::kUnknown);    // never observed
  // The obstacle moves away: a later beam through its cell clears it.
  layer.addScan(laser, std::vector<Eigen::Vector2d>{{2.5, 0.0}});
  CHECK(cellAt(layer, map, 2.01, 0.01) == Cell::kFree);
  CHECK(cellAt(layer, map, 2.51, 0.01) == Cell::kObstacle);
  CHECK(layer.obstacleCount() == 1);
}

TEST_CASE("a table top seen in depth blocks the cells beneath it", "[navigation]") {
  const Costmap map = area();
  ObstacleLayer layer(map);
  // A camera 1 m up sees the table top (0.75 m) at x = 2 and the floor behind it at x = 3.
  const Eigen::Vector3d camera(0, 0, 1.0);
  std::vector<Eigen::Vector3d> points;
  for (double y = -0.3; y <= 0.3; y += 0.05) {
    for (double x = 1.8; x <= 2.2; x += 0.05) points.emplace_back(x, y, 0.75);
    points.emplace_back(3.0, y, 0.0);  // the floor: clears, never marks
    points.emplace_back(2.6, y, 2.5);  // the ceiling: above the band
  }
  layer.addPoints(camera, points);
  CHECK(cellAt(layer, map, 2.0, 0.0) == Cell::kObstacle);
  CHECK(cellAt(layer, map, 1.0, 0.0) == Cell::kFree);
  CHECK(cellAt(layer, map, 2.6, 0.0) == Cell::kFree);  // the ray to the floor crossed it
  CHECK(cellAt(layer, map, 3.0, 0.0) == Cell::kUnknown);

  // The planar laser at 0.2 m sees through under the table to a chair leg at x = 2.4: it must
  // not clear the table top.
  std::vector<Eigen::Vector2d> beam = {{2.4, 0.0}};
  layer.addScan(Eigen::Vector3d(0, 0, 0.2), beam);
  CHECK(cellAt(layer, map, 2.0, 0.0) == Cell::kObstacle);
  CHECK(cellAt(layer, map, 2.41, 0.01) == Cell::kObstacle);

  // The camera now sees the floor under and behind the table from a low angle only: the
  // rays cross the table's cells below the top's slice, which stays marked.
  layer.addPoints(Eigen::Vector3d(0, 0, 0.3), std::vector<Eigen::Vector3d>{{3.0, 0.0, 0.0}});
  CHECK(cellAt(layer, map, 2.0, 0.0) == Cell::kObstacle);

  Costmap costs = area();
  layer.applyTo(costs);
  CHECK(costs.at(costs.cellOf({2.0, 0.0})) == cost::kLethal);
  CHECK(costs.at(costs.cellOf({1.0, 0.0})) == cost::kFree);
  CHECK(costs.at(costs.cellOf({-0.5, 1.0})) == cost::kUnknown);
}

TEST_CASE("the obstacle layer skips bad points and refuses a costmap of another size",
          "[navigation]") {
  const Costmap map = area();
  ObstacleLayer layer(map);
  const double nan = std::nan("");
  layer.addScan(Eigen::Vector3d(nan, 0, 0.2), std::vector<Eigen::Vector2d>{{1, 0}});
  layer.addScan(Eigen::Vector3d(0, 0, 0.2), std::vector<Eigen::Vector2d>{{nan, 0}, {50, 50}});
  layer.addPoints(Eigen::Vector3d(0, 0, 1), std::vector<Eigen::Vector3d>{{nan, 0, 0.5}});
  CHECK(layer.obstacleCount() == 0);
  Costmap other(10, 10, 0.05);
  CHECK_THROWS_WITH(layer.applyTo(other), Catch::Contains("10 x 10"));
  ObstacleLayerOptions o;
  o.max_height = 0.0;
  CHECK_THROWS_WITH(ObstacleLayer(map, o), Catch::Contains("max_height"));
}
