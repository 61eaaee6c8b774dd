// End to end: apps/profiles/sim_multi_robot.yaml, two simulated robots with their own laser SLAM
// joined by the map merger, against the same first robot alone (sim_slam_global, same seed and
// settings): every inter-robot closure true, each robot's ATE in the merged frame (one alignment
// for both) within 5 cm of its ATE alone, and a merged map with no more doubled walls than one
// robot's.
#include <tessera/evaluation/map_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "../shared_data.hpp"
#include "run_profile.hpp"

using namespace tessera;
namespace fs = std::filesystem;

namespace {

/// The walls of `dir`/walls.txt (world frame) scored against `map`, moved into the map's frame
/// by `alignment` (estimate -> world).
evaluation::MapWallScore wallScore(const fs::path& map, const fs::path& walls_file,
                                   const evaluation::Alignment& alignment) {
  auto walls = evaluation::readWalls(walls_file.string());
  for (auto& w : walls)
    for (Eigen::Vector2d* p : {&w.a, &w.b}) *p = alignment.unapply({p->x(), p->y(), 0}).head<2>();
  return evaluation::scoreMapAgainstWalls(mapping::loadMap(map), walls);
}

double fraction(const evaluation::MapWallScore& s) {
  return static_cast<double>(s.doubled_wall_cells) / static_cast<double>(s.occupied_cells);
}

}  // namespace

TEST_CASE(
    "two robots join one map: closures true, merged ATE within 5 cm of alone, no doubled walls",
    "[e2e][multi_robot]") {
  const fs::path out = test::scratchDir("multi_robot");
  const RunReport report = test::runProfile("sim_multi_robot", out);
  CHECK(report.stop_reason == "all inputs finished");
  const auto& merger = test::summaryOf(report, "merger");
  const auto count = [&](const char* key) { return std::get<std::int64_t>(merger.at(key)); };
  CHECK(count("robots_joined") == 2);
  CHECK(count("inter_robot_closures") >= 10);
  CHECK(count("inter_robot_closures_true") == count("inter_robot_closures"));
  CHECK(count("inter_robot_closures_false") == 0);
  CHECK(count("merger_conflicting") >= 1);  // the office's mirrored corridors were seen and refused
  CHECK(count("map_poses_published") > 1000);

  std::ifstream frames(out / "robot_frames.json");
  std::stringstream text;
  text << frames.rdbuf();
  CHECK(text.str().find("\"name\": \"r2\", \"joined\": true") != std::string::npos);

  std::vector<std::pair<std::vector<mapping::TumPose>, std::vector<mapping::TumPose>>> pairs;
  for (const char* r : {"r1", "r2"})
    pairs.emplace_back(mapping::readTum(out / (std::string(r) + "_trajectory_merged.tum")),
                       mapping::readTum(out / (std::string(r) + "_ground_truth.tum")));
  const auto joint = evaluation::computeJointAte(pairs);
  for (std::size_t k = 0; k < 2; ++k) {
    INFO("r" << k + 1 << ": merged " << joint.joint[k].rmse << " m, alone "
             << joint.alone[k].translation.rmse << " m");
    CHECK(joint.alone[k].pairs > 3000);
    CHECK(joint.joint[k].rmse <= joint.alone[k].translation.rmse + 0.05);
    CHECK(joint.alone[k].translation.rmse < 0.15);
  }

  // r1 alone: the same robot, seed and SLAM settings in sim_slam_global.
  const fs::path alone = test::scratchDir("multi_robot_alone");
  test::runProfile("sim_slam_global", alone);
  const auto r1_alone = evaluation::computeAte(mapping::readTum(alone / "trajectory_final.tum"),
                                               mapping::readTum(alone / "ground_truth.tum"));
  CHECK(r1_alone.translation.rmse == Approx(joint.alone[0].translation.rmse).margin(1e-3));
  const auto merged = wallScore(out / "map.yaml", out / "walls.txt", joint.alignment);
  const auto single = wallScore(alone / "map.yaml", out / "walls.txt", r1_alone.alignment);
  INFO("doubled wall cells: merged " << merged.doubled_wall_cells << " of " << merged.occupied_cells
                                     << ", r1 alone " << single.doubled_wall_cells << " of "
                                     << single.occupied_cells);
  CHECK(merged.occupied_cells > single.occupied_cells);  // r2 mapped rooms r1 never entered
  CHECK(merged.wall_cells_found > 0.98);
  CHECK(fraction(merged) <= 1.1 * fraction(single));
}
