// End to end: apps/profiles/sim_lines.yaml (seed 001 room, drifting odometry) and
// apps/profiles/carmen_lines.yaml on a prefix of the real Intel log (simulator/player -> line_slam
// -> line map and trajectory writers), read back what they wrote.
#include <tessera/datasets/relations.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/line_slam/line_map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <filesystem>

#include "../shared_data.hpp"
#include "run_profile.hpp"

using namespace tessera;
namespace fs = std::filesystem;

namespace {

double summaryDouble(const RunReport& r, const std::string& actor, const std::string& key) {
  return std::get<double>(test::summaryOf(r, actor).at(key));
}

}  // namespace

TEST_CASE("sim_lines ends within 7 cm and half a degree while odometry drifts metres",
          "[e2e][lines]") {
  const fs::path out = test::scratchDir("sim_lines");
  const RunReport report = test::runProfile("sim_lines", out);
  CHECK(report.stop_reason == "all inputs finished");
  for (const char* f : {"trajectory.tum", "ground_truth.tum", "odometry.tum", "walls.txt",
                        "lines.csv", "lines.svg"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  const double err = summaryDouble(report, "slam", "final_position_error_m");
  const double heading = summaryDouble(report, "slam", "final_heading_error_deg");
  const double drift = summaryDouble(report, "sim", "odom_drift_m");
  const auto lines = test::summaryInt(report, "slam", "lines");
  const auto walls = test::summaryInt(report, "line_map_writer", "walls");
  const auto matched = test::summaryInt(report, "line_map_writer", "walls_matched");
  const auto on_walls = test::summaryInt(report, "line_map_writer", "lines_on_walls");
  INFO("final error " << err << " m, " << heading << " deg; odometry drift " << drift
                      << " m; lines " << lines << " (on walls " << on_walls << "), walls " << walls
                      << " (matched " << matched << ")");
  CHECK(drift > 1.0);
  CHECK(err < 0.07);
  CHECK(heading < 0.5);
  CHECK(test::summaryInt(report, "slam", "scans_unpaired") == 0);
  CHECK(test::summaryInt(report, "slam", "tentative_promoted") > 0);
  // The map: most true faces found, few spurious lines.
  CHECK(walls == test::summaryInt(report, "world_writer", "wall_segments"));
  CHECK(matched >= walls * 3 / 4);
  CHECK(on_walls >= lines * 3 / 4);
  CHECK(lines <= walls + 10);
  // The whole estimated trajectory, not only its end.
  const auto ate =
      tessera::evaluation::computeAte(tessera::mapping::readTum(out / "trajectory.tum"),
                                      tessera::mapping::readTum(out / "ground_truth.tum"));
  CHECK(ate.translation.rmse < 0.07);
}

TEST_CASE("carmen_lines tracks the first 500 scans of intel.clf better than odometry",
          "[e2e][lines][data]") {
  TESSERA_SHARED_DATA(log, "intel-lab-mrpt/intel.clf.gz");
  TESSERA_SHARED_DATA(times, "intel-lab-mrpt/frame_times.txt");
  TESSERA_SHARED_DATA(relations_path, "intel-lab-mrpt/intel.relations");
  const fs::path out = test::scratchDir("carmen_lines");
  const RunReport report =
      test::runProfile("carmen_lines", out,
                       {"player.path=" + log.string(), "player.scan_times=" + times.string(),
                        "player.max_scans=500"});
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(fs::exists(out / "lines.svg"));
  CHECK(test::summaryInt(report, "slam", "scans_read") == 500);
  CHECK(tessera::mapping::readTum(out / "trajectory.tum").size() == 500);
  const auto file = datasets::readRelations(relations_path);
  std::vector<tessera::evaluation::PoseRelation> relations;
  for (const auto& r : file.relations)
    relations.push_back({r.t1_ns, r.t2_ns, tessera::Pose2(r.dx, r.dy, r.yaw)});
  const auto slam = tessera::evaluation::computeRelationsError(
      tessera::mapping::readTum(out / "trajectory.tum"), relations);
  const auto odom = tessera::evaluation::computeRelationsError(
      tessera::mapping::readTum(out / "odometry.tum"), relations);
  INFO("slam " << slam.matched << " relations: " << slam.translation.mean << " m, "
               << slam.rotation_deg.mean << " deg; odometry " << odom.translation.mean << " m, "
               << odom.rotation_deg.mean << " deg");
  REQUIRE(slam.matched > 300);
  CHECK(slam.rotation_deg.mean < odom.rotation_deg.mean);
}
