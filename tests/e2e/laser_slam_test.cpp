// End to end: apps/profiles/carmen_rbpf.yaml on a prefix of the real Intel log and
// apps/profiles/sim_slam.yaml on a shortened simulated route (player/simulator -> RBPF submap
// builder -> map assembler + writers -> files), read back what they wrote. Full-log figures come
// from the benchmark (README), not from here.
#include <tessera/datasets/relations.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <filesystem>

#include "../shared_data.hpp"
#include "run_profile.hpp"

using namespace tessera;
namespace fs = std::filesystem;

namespace {

tessera::evaluation::RelationsResult relationsError(const fs::path& tum,
                                                    const fs::path& relations_path) {
  const auto file = datasets::readRelations(relations_path);
  std::vector<tessera::evaluation::PoseRelation> relations;
  for (const auto& r : file.relations)
    relations.push_back({r.t1_ns, r.t2_ns, tessera::Pose2(r.dx, r.dy, r.yaw)});
  return tessera::evaluation::computeRelationsError(tessera::mapping::readTum(tum), relations);
}

}  // namespace

TEST_CASE("carmen_rbpf maps the first 500 scans of intel.clf better than odometry",
          "[e2e][rbpf][data]") {
  TESSERA_SHARED_DATA(log, "intel-lab-mrpt/intel.clf.gz");
  TESSERA_SHARED_DATA(times, "intel-lab-mrpt/frame_times.txt");
  TESSERA_SHARED_DATA(relations, "intel-lab-mrpt/intel.relations");
  const fs::path out = test::scratchDir("carmen_rbpf");
  const RunReport report =
      test::runProfile("carmen_rbpf", out,
                       {"player.path=" + log.string(), "player.scan_times=" + times.string(),
                        "player.max_scans=500", "slam.rbpf.particles=5"});
  CHECK(report.stop_reason == "all inputs finished");
  for (const char* f : {"map.pgm", "map.yaml", "map.png", "trajectory.tum", "trajectory_final.tum",
                        "odometry.tum"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  CHECK(test::summaryInt(report, "slam", "scans_read") == 500);
  CHECK(test::summaryInt(report, "slam", "scans_unpaired") == 0);
  CHECK(test::summaryInt(report, "slam", "particles") == 5);
  const auto processed = test::summaryInt(report, "slam", "scans_processed");
  CHECK(processed > 100);
  CHECK(processed < 400);  // the 1 m / 0.5 rad gates skip most scans
  // The online estimate: one pose per input scan.
  CHECK(tessera::mapping::readTum(out / "trajectory.tum").size() == 500);
  const auto slam = relationsError(out / "trajectory.tum", relations);
  const auto odom = relationsError(out / "odometry.tum", relations);
  INFO("slam " << slam.matched << " relations: " << slam.translation.mean << " m, "
               << slam.rotation_deg.mean << " deg; odometry " << odom.translation.mean << " m, "
               << odom.rotation_deg.mean << " deg");
  REQUIRE(slam.matched > 300);
  CHECK(slam.translation.mean < 0.5 * odom.translation.mean);
  CHECK(slam.rotation_deg.mean < 0.5 * odom.rotation_deg.mean);
  CHECK(slam.translation.mean < 0.2);
  const auto map = tessera::mapping::loadMap(out / "map.yaml");
  CHECK(map.width > 200);
}

TEST_CASE("sim_slam keeps the simulated robot on its true path while odometry drifts",
          "[e2e][rbpf]") {
  const fs::path out = test::scratchDir("sim_slam");
  // A part of the office route keeps the test short; the full route is the benchmark.
  const RunReport report = test::runProfile("sim_slam", out, {"max_duration_s=120"});
  const auto estimate = tessera::mapping::readTum(out / "trajectory.tum");
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  const auto odometry = tessera::mapping::readTum(out / "odometry.tum");
  REQUIRE(estimate.size() > 500);
  const auto slam = tessera::evaluation::computeAte(estimate, truth);
  const auto odom = tessera::evaluation::computeAte(odometry, truth);
  INFO("ATE slam " << slam.translation.rmse << " m, odometry " << odom.translation.rmse << " m");
  CHECK(slam.translation.rmse < 0.1);
  CHECK(odom.translation.rmse > 2 * slam.translation.rmse);
  CHECK(test::summaryInt(report, "slam", "submaps") == 1);
  CHECK(fs::exists(out / "map.png"));
}

TEST_CASE("sim_slam_global closes loops without a false one and straightens the submap chain",
          "[e2e][rbpf][global]") {
  const fs::path out = test::scratchDir("sim_slam_global");
  const RunReport report = test::runProfile("sim_slam_global", out);
  CHECK(report.stop_reason == "all inputs finished");
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  const auto online =
      tessera::evaluation::computeAte(tessera::mapping::readTum(out / "trajectory.tum"), truth);
  const auto final_ate = tessera::evaluation::computeAte(
      tessera::mapping::readTum(out / "trajectory_final.tum"), truth);
  INFO("ATE online (chained submaps) " << online.translation.rmse << " m, after optimisation "
                                       << final_ate.translation.rmse << " m");
  const auto loops_true = test::summaryInt(report, "loops", "loops_true");
  const auto loops_false = test::summaryInt(report, "loops", "loops_false");
  INFO("loop closures: " << loops_true << " true, " << loops_false << " false");
  CHECK(test::summaryInt(report, "slam", "submaps") >= 10);
  CHECK(loops_true >= 10);
  CHECK(static_cast<double>(loops_true) / static_cast<double>(loops_true + loops_false) >= 0.98);
  CHECK(test::summaryInt(report, "optimizer", "optimizations") > 0);
  CHECK(test::summaryInt(report, "optimizer", "constraints_unresolved") == 0);
  CHECK(final_ate.translation.rmse < 0.2);
  CHECK(final_ate.translation.rmse < online.translation.rmse);
  CHECK(fs::exists(out / "map.png"));
}
