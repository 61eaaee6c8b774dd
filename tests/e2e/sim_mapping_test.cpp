// End to end: run apps/profiles/sim_mapping.yaml (simulator -> grid mapper -> writers) for two
// simulated minutes, read back the files it wrote, and compare the map with the world.
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/world.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_mapping builds a map that matches the simulated office", "[e2e]") {
  const fs::path out = fs::temp_directory_path() / "tessera_e2e_sim_mapping";
  fs::remove_all(out);
  fs::create_directories(out);

  auto profile = loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_mapping.yaml",
                             {"max_duration_s=120"});
  RuntimeOptions options;
  options.show_progress = false;
  options.output_dir = out.string();
  auto runtime = buildRuntime(profile, options);
  const RunReport report = runtime->run();
  CHECK(report.stop_reason == "reached max_duration_s");
  CHECK(report.sim_duration_s == Approx(120.0));
  for (const auto& a : report.actors) CHECK(a.drops == 0);  // simulated time waits for consumers

  for (const char* f :
       {"map.pgm", "map.yaml", "map.png", "trajectory.tum", "odometry.tum", "ground_truth.tum"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  const auto map = tessera::mapping::loadMap(out / "map.yaml");
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  REQUIRE(truth.size() > 1000);
  CHECK(tessera::mapping::readTum(out / "odometry.tum").size() > 1000);

  const sim::World world = sim::World::builtinOffice();
  const sim::RayCaster caster(world);
  const double res = world.resolution();
  auto mapValueAt = [&](const Eigen::Vector2d& p) -> int {
    const Eigen::Vector2i c = map.cellOf(p);
    return map.contains(c.x(), c.y()) ? map.at(c.x(), c.y()) : -1;
  };
  auto occupiedNear = [&](const Eigen::Vector2d& p) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        if (mapValueAt(p + Eigen::Vector2d(dx * res, dy * res)) >= 65) return true;
    return false;
  };

  // Wall cells the robot saw: the cells its (noise-free) laser beams end in.
  std::set<std::pair<int, int>> seen_walls;
  for (std::size_t i = 0; i < truth.size(); i += 5) {
    const auto pose = truth[i].planar();
    const Eigen::Vector2d origin(pose.x, pose.y);
    for (int b = 0; b < 181; ++b) {
      const double angle = pose.theta - M_PI / 2 + b * M_PI / 180.0;
      const double r = caster.cast(origin, angle, 30.0);
      if (!std::isfinite(r)) continue;
      const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
      const Eigen::Vector2i cell = world.cellOf(origin + (r + 0.5 * res) * dir);
      if (world.wall(cell.x(), cell.y())) seen_walls.insert({cell.x(), cell.y()});
    }
  }
  REQUIRE(seen_walls.size() > 2000);
  std::size_t walls_occupied = 0;
  for (const auto& [cx, cy] : seen_walls) {
    if (occupiedNear(Eigen::Vector2d((cx + 0.5) * res, (cy + 0.5) * res))) ++walls_occupied;
  }
  const double wall_fraction = static_cast<double>(walls_occupied) / seen_walls.size();

  // Free cells the map knows (one cell away from any wall, to ignore discretisation at edges).
  std::size_t free_known = 0, free_marked_occupied = 0;
  for (int row = 0; row < map.height; ++row) {
    for (int col = 0; col < map.width; ++col) {
      const int v = map.at(col, row);
      if (v < 0) continue;
      const Eigen::Vector2i w = world.cellOf(map.cellCenter(col, row));
      if (!world.inside(w.x(), w.y())) continue;
      bool near_wall = false;
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          near_wall = near_wall || world.wall(w.x() + dx, w.y() + dy);
      if (near_wall) continue;
      ++free_known;
      if (v >= 65) ++free_marked_occupied;
    }
  }
  REQUIRE(free_known > 20000);
  const double false_fraction = static_cast<double>(free_marked_occupied) / free_known;
  INFO("seen wall cells " << seen_walls.size() << ", occupied " << wall_fraction << "; known free "
                          << free_known << ", marked occupied " << false_fraction);
  CHECK(wall_fraction >= 0.95);
  CHECK(false_fraction < 0.02);
}
