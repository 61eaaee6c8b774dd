// `tessera map export` end to end: a SLAM state saved here, exported by the CLI, read back with
// mapping::loadMap; and a profile that serves a saved state without SLAM (map_assembler's
// load_state + map_writer).
#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/mapping/map_io.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using namespace tessera;
using Catch::Contains;
using tessera::test::runCli;

namespace {

namespace fs = std::filesystem;

/// Two overlapping rooms: walls occupied, insides free, the second turned by 90 degrees.
laser_slam::SlamState twoRooms() {
  laser_slam::SlamState state;
  for (int id = 0; id < 2; ++id) {
    laser_slam::SavedSubmap s;
    s.id = id;
    s.origin = id == 0 ? Pose2{} : Pose2(3.0, 0.5, 1.5707963267948966);
    s.grid.resolution = 0.05;
    s.grid.width = 80;
    s.grid.height = 60;
    s.grid.origin = Pose2(-1.0, -1.0, 0.0);
    s.grid.cells.assign(80 * 60, grid::OccupancyMap::kUnknown);
    for (int r = 5; r < 55; ++r)
      for (int c = 5; c < 75; ++c)
        s.grid.at(c, r) = (r == 5 || r == 54 || c == 5 || c == 74) ? 96 : 2;
    state.submaps.push_back(std::move(s));
  }
  laser_slam::SavedConstraint c;
  c.from = 0;
  c.to = 1;
  c.relative = Pose2(3.0, 0.5, 1.5707963267948966);
  state.constraints.push_back(c);
  return state;
}

/// The class map_server reads back from a trinary file (thresholds of MapSaveOptions).
std::int8_t trinary(std::int8_t v) {
  if (v < 0) return grid::OccupancyMap::kUnknown;
  const double p = v / 100.0;
  return p > 0.65 ? 100 : p < 0.196 ? 0 : grid::OccupancyMap::kUnknown;
}

}  // namespace

TEST_CASE("map export writes a saved state as a PGM + YAML map that loadMap reads", "[map_cli]") {
  const fs::path dir = test::scratchDir("map_cli_export");
  const auto state = twoRooms();
  laser_slam::saveSlamState(state, dir / "state");
  const auto run = runCli(
      "map export " + (dir / "state").string() + " --out " + (dir / "maps/office").string(), dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto expected = laser_slam::assembleSlamState(state);
  CHECK_THAT(run.out, Contains("exported 2 submaps") && Contains("0 calibrated cameras") &&
                          Contains(std::to_string(expected.width) + " x " +
                                   std::to_string(expected.height) + " cells") &&
                          Contains((dir / "maps/office.yaml").string()));
  CHECK(fs::exists(dir / "maps/office.pgm"));
  CHECK(fs::exists(dir / "maps/office.png"));
  const auto map = mapping::loadMap(dir / "maps/office.yaml");
  REQUIRE(map.width == expected.width);
  REQUIRE(map.height == expected.height);
  CHECK(map.resolution == Approx(0.05));
  CHECK(map.origin.x == Approx(expected.origin.x).margin(1e-9));
  CHECK(map.origin.y == Approx(expected.origin.y).margin(1e-9));
  std::size_t differ = 0, occupied = 0;
  for (std::size_t k = 0; k < map.cells.size(); ++k) {
    differ += map.cells[k] != trinary(expected.cells[k]);
    occupied += map.cells[k] == 100;
  }
  CHECK(differ == 0);
  CHECK(occupied > 300);  // one room has 236 wall cells: both rooms are drawn
  // The first room's left wall (column 5: x = -1 + 5.5 * 0.05 m), which the turned room does
  // not reach, is occupied.
  const auto cell = map.cellOf({-0.725, 1.0});
  REQUIRE(map.contains(cell.x(), cell.y()));
  CHECK(map.at(cell.x(), cell.y()) == 100);

  const auto coarse = runCli("map export " + (dir / "state").string() + " --resolution 0.1 " +
                                 "--no-png --out " + (dir / "coarse").string(),
                             dir);
  REQUIRE(coarse.exit_code == 0);
  CHECK_FALSE(fs::exists(dir / "coarse.png"));
  CHECK(mapping::loadMap(dir / "coarse.yaml").resolution == Approx(0.1));
}

TEST_CASE("map export of a bad state fails with the file and field", "[map_cli]") {
  const fs::path dir = test::scratchDir("map_cli_bad");
  const auto absent =
      runCli("map export " + (dir / "absent").string() + " --out " + (dir / "m").string(), dir);
  CHECK(absent.exit_code != 0);
  CHECK_THAT(absent.err, Contains("absent") && Contains("no such directory"));
  laser_slam::saveSlamState(twoRooms(), dir / "state");
  {
    std::ifstream in(dir / "state/state.yaml");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.replace(text.find("version: 2"), 10, "version: 3");
    std::ofstream(dir / "state/state.yaml", std::ios::trunc) << text;
  }
  const auto v3 =
      runCli("map export " + (dir / "state").string() + " --out " + (dir / "m").string(), dir);
  CHECK(v3.exit_code != 0);
  CHECK_THAT(v3.err, Contains("state.yaml") && Contains("version: 3 is not supported"));
  CHECK_FALSE(fs::exists(dir / "m.yaml"));
  const auto no_out = runCli("map export " + (dir / "state").string(), dir);
  CHECK(no_out.exit_code == 2);
  CHECK_THAT(no_out.err, Contains("--out"));
  const auto help = runCli("map export --help", dir);
  CHECK(help.exit_code == 0);
  CHECK_THAT(help.out, Contains("SLAM state directory") && Contains("--resolution"));
}

TEST_CASE("a profile with map_assembler load_state and map_writer serves a saved map",
          "[map_cli]") {
  const fs::path dir = test::scratchDir("map_cli_profile");
  const auto state = twoRooms();
  laser_slam::saveSlamState(state, dir / "state");
  std::ofstream(dir / "serve.yaml") << "name: serve_saved_map\n"
                                       "description: a saved SLAM state, no SLAM\n"
                                       "clock: sim\n"
                                       "actors:\n"
                                       "  assembler:\n"
                                       "    type: map_assembler\n"
                                       "    params: {load_state: "
                                    << (dir / "state").string()
                                    << "}\n"
                                       "  map_writer:\n"
                                       "    type: map_writer\n";
  const auto run = runCli(
      "run " + (dir / "serve.yaml").string() + " --quiet --out " + (dir / "out").string(), dir);
  INFO(run.out << run.err);
  REQUIRE(run.exit_code == 0);
  const auto map = mapping::loadMap(dir / "out/map.yaml");
  const auto expected = laser_slam::assembleSlamState(state);
  REQUIRE(map.width == expected.width);
  REQUIRE(map.height == expected.height);
  std::size_t differ = 0;
  for (std::size_t k = 0; k < map.cells.size(); ++k)
    differ += map.cells[k] != trinary(expected.cells[k]);
  CHECK(differ == 0);
  // The served state is saved again with the run's outputs.
  CHECK(fs::exists(dir / "out/slam_state/state.yaml"));
}
