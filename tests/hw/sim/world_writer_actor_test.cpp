#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/world.hpp>
#include <tessera/sim/world_writer_actor.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cstdint>
#include <limits>
#include <string>

using namespace tessera;
using tessera::sim::World;
using tessera::sim::WorldWriterActor;
using tessera::sim::WorldWriterOptions;

namespace {

// The office: its first table stands over [18.6, 20.0] x [4.6, 5.6], 0.75 m high, with 0.05 m
// legs at the corners.
WorldWriterOptions officeMaps(double robot_height = 1.0) {
  WorldWriterOptions o;
  o.world = "builtin:office";
  o.walls_file.clear();
  o.publish_map = true;
  o.robot_height = robot_height;
  return o;
}

std::int8_t cellAt(const Message<msg::OccupancyGrid>& grid, double x, double y) {
  const double res = grid->getResolution();
  const auto col = static_cast<std::size_t>(x / res), row = static_cast<std::size_t>(y / res);
  const auto cells = grid->getCells();
  const std::size_t i = row * grid->getWidth() + col;
  REQUIRE(i < cells.size());
  return static_cast<std::int8_t>(cells[i]);
}

std::string configErrorOf(const WorldWriterOptions& o) {
  try {
    WorldWriterActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("WorldWriterActor: publish_map publishes the wall map and the obstacle map at start",
          "[sim][actor][world_writer]") {
  const World office = World::builtinOffice();
  ActorHarness h(std::make_unique<WorldWriterActor>(officeMaps()));
  h.advance(0);
  const auto maps = h.published<msg::OccupancyGrid>("map");
  const auto obstacles = h.published<msg::OccupancyGrid>("obstacle_map");
  REQUIRE(maps.size() == 1);
  REQUIRE(obstacles.size() == 1);
  for (const auto* grid : {&maps[0], &obstacles[0]}) {
    const auto& g = *grid;
    CHECK(g->getHeader().getStampNs() == 0);
    CHECK(std::string(g->getHeader().getFrameId().cStr()) == "map");
    CHECK(g->getResolution() == Approx(0.05f));
    CHECK(g->getWidth() == 800u);
    CHECK(g->getHeight() == 600u);
    CHECK(g->getCells().size() == 800u * 600u);
    const tessera::Pose2 origin = toPose2(g->getOrigin());
    CHECK(origin.x == 0.0);
    CHECK(origin.y == 0.0);
    CHECK(origin.theta == 0.0);
    CHECK(cellAt(g, 0.1, 0.1) == 100);  // the outer wall
    CHECK(cellAt(g, 3.0, 6.0) == 100);  // a room wall (y = 6 +- 0.1)
    CHECK(cellAt(g, 21.0, 3.0) == 0);   // a room's floor
    CHECK(cellAt(g, 7.5, 7.5) == 0);    // the corridor
  }
  // A table leg and the middle of the table's top: obstacles to a 1 m robot, not laser walls.
  REQUIRE_FALSE(office.blocked({18.62, 4.62}));
  CHECK(cellAt(maps[0], 18.62, 4.62) == 0);
  CHECK(cellAt(obstacles[0], 18.62, 4.62) == 100);
  CHECK(cellAt(maps[0], 19.3, 5.1) == 0);
  CHECK(cellAt(obstacles[0], 19.3, 5.1) == 100);
  // The wall map is the world's bitmap cell by cell; the obstacle map has every wall too.
  const auto map_cells = maps[0]->getCells(), obstacle_cells = obstacles[0]->getCells();
  std::size_t walls = 0, extra = 0, wrong = 0, walls_missing = 0;
  for (std::size_t i = 0; i < map_cells.size(); ++i) {
    const int row = static_cast<int>(i / 800), col = static_cast<int>(i % 800);
    if (static_cast<std::int8_t>(map_cells[i]) != (office.wall(col, row) ? 100 : 0)) ++wrong;
    if (map_cells[i] != 0) {
      ++walls;
      if (obstacle_cells[i] != map_cells[i]) ++walls_missing;
    } else if (obstacle_cells[i] != 0) {
      ++extra;
    }
  }
  CHECK(wrong == 0);
  CHECK(walls_missing == 0);
  CHECK(walls > 10000);
  CHECK(extra > 100);  // the furniture

  // A robot lower than the table top (0.71 m) meets only the legs there.
  ActorHarness low(std::make_unique<WorldWriterActor>(officeMaps(0.5)));
  low.advance(0);
  const auto low_obstacles = low.published<msg::OccupancyGrid>("obstacle_map");
  REQUIRE(low_obstacles.size() == 1);
  CHECK(cellAt(low_obstacles[0], 18.62, 4.62) == 100);
  CHECK(cellAt(low_obstacles[0], 19.3, 5.1) == 0);
}

TEST_CASE("WorldWriterActor: the maps are republished every map_period_s",
          "[sim][actor][world_writer]") {
  WorldWriterOptions o = officeMaps();
  o.map_period_s = 2.0;
  ActorHarness h(std::make_unique<WorldWriterActor>(o));
  h.advance(secondsToNanos(5.0));
  const auto maps = h.published<msg::OccupancyGrid>("map");
  REQUIRE(maps.size() == 3);  // at 0, 2 and 4 s
  REQUIRE(h.publishedCount("obstacle_map") == 3);
  for (std::size_t i = 0; i < maps.size(); ++i) {
    CHECK(maps[i]->getHeader().getStampNs() == static_cast<std::int64_t>(i) * 2'000'000'000);
    CHECK(maps[i]->getHeader().getSeq() == i);
  }
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("maps_published")) == 3);
}

TEST_CASE("WorldWriterActor: without publish_map nothing is advertised",
          "[sim][actor][world_writer]") {
  WorldWriterOptions o = officeMaps();
  o.publish_map = false;
  ActorHarness h(std::make_unique<WorldWriterActor>(o));
  h.advance(secondsToNanos(5.0));
  CHECK(h.runtime().publicationsOf("actor_under_test").empty());
  CHECK(h.publishedCount("map") == 0);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("maps_published")) == 0);
}

TEST_CASE("WorldWriterActor: map options from YAML; bad values are ConfigErrors naming them",
          "[sim][actor][world_writer][options]") {
  const auto o = loadOptions<WorldWriterOptions>(
      Params(YAML::Load("{publish_map: true, robot_height: 0.4, map_period_s: 0.5}"), "test"));
  CHECK(o.publish_map);
  CHECK(o.robot_height == 0.4);
  CHECK(o.map_period_s == 0.5);
  const WorldWriterOptions d;
  CHECK_FALSE(d.publish_map);
  CHECK(d.robot_height == 1.0);
  CHECK(d.map_period_s == 2.0);

  auto with = [](auto change) {
    WorldWriterOptions c = officeMaps();
    change(c);
    return configErrorOf(c);
  };
  CHECK(with([](auto&) {}).empty());
  CHECK_THAT(with([](auto& c) { c.map_period_s = 0; }),
             Catch::Contains("world_writer: option 'map_period_s'"));
  CHECK_THAT(with([](auto& c) { c.map_period_s = std::numeric_limits<double>::quiet_NaN(); }),
             Catch::Contains("map_period_s"));
  CHECK_THAT(with([](auto& c) { c.robot_height = -1; }),
             Catch::Contains("world_writer: option 'robot_height'"));
  CHECK_THAT(with([](auto& c) { c.robot_height = std::numeric_limits<double>::infinity(); }),
             Catch::Contains("robot_height"));
}
