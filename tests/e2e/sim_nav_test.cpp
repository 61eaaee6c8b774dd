// End to end: run apps/profiles/sim_nav.yaml (simulator driven by cmd_vel, MCL on the published
// wall map, the navigator with laser and depth obstacles, the goal sequencer) with a few random
// goals: every goal is reached, the body never touches a wall or a piece of furniture, and the
// robot drives close to the shortest path. The 100-goal run is `tessera bench nav`.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include "run_profile.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_nav: random goals in the office are reached without a collision",
          "[e2e][nav][slow]") {
  const fs::path out = fs::temp_directory_path() / "tessera_e2e_sim_nav";
  fs::remove_all(out);
  fs::create_directories(out);
  const RunReport report = test::runProfile("sim_nav", out, {"goals.random=3", "goals.seed=7"});
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(test::summaryInt(report, "goals", "goals") == 3);
  CHECK(test::summaryInt(report, "goals", "reached") == 3);
  CHECK(test::summaryInt(report, "sim", "collisions") == 0);
  CHECK(test::summaryInt(report, "sim", "watchdog_stops") == 0);
  CHECK(test::summaryInt(report, "nav", "nonfinite_commands") == 0);
  CHECK(test::summaryInt(report, "nav", "depth_frames") > 0);
  // A* planned with landmark bounds all along: the laser's and the depth camera's obstacles
  // only ever add cost to the map they were built on.
  CHECK(test::summaryInt(report, "nav", "landmark_builds") == 1);
  CHECK(test::summaryInt(report, "nav", "plans") > 0);
  CHECK(test::summaryInt(report, "nav", "landmark_plans") ==
        test::summaryInt(report, "nav", "plans"));
  const double ratio = std::get<double>(test::summaryOf(report, "goals").at("path_length_ratio"));
  CHECK(ratio < 1.3);

  // goals.csv: a header and one row per goal.
  std::ifstream csv(out / "goals.csv");
  std::string line;
  int rows = 0;
  while (std::getline(csv, line)) ++rows;
  CHECK(rows == 4);

  const auto estimate = mapping::readTum(out / "trajectory.tum");
  const auto truth = mapping::readTum(out / "ground_truth.tum");
  // MCL's error in the map frame (no alignment: the map is the world).
  const auto pairs = evaluation::associateByTime(estimate, truth, {});
  REQUIRE(pairs.size() > 100);
  double sum = 0;
  for (const auto& [e, r] : pairs) sum += (estimate[e].position - truth[r].position).norm();
  const double mean = sum / static_cast<double>(pairs.size());
  std::cout << "sim_nav: 3 goals, path length ratio " << ratio << ", MCL error mean " << mean
            << " m\n";
  CHECK(mean < 0.15);
}

TEST_CASE("sim_nav: a robot kidnapped on its way relocalises and still reaches its goal",
          "[e2e][nav][slow]") {
  const fs::path out = fs::temp_directory_path() / "tessera_e2e_sim_nav_kidnap";
  fs::remove_all(out);
  fs::create_directories(out);
  // 20 s into the first goal (about 76 s away) the robot is carried 7 m into another area; its
  // odometry does not see it.
  const RunReport report = test::runProfile("sim_nav", out,
                                            {"goals.random=1", "goals.seed=7", "sim.kidnap_at_s=20",
                                             "sim.kidnap_pose=[14.0, 11.5, 0.5]"});
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(test::summaryInt(report, "sim", "kidnapped") == 1);
  CHECK(test::summaryInt(report, "mcl", "relocalisations") >= 1);
  CHECK(test::summaryInt(report, "goals", "reached") == 1);
  CHECK(test::summaryInt(report, "sim", "collisions") == 0);

  // Lost after the kidnapping, then found: the last 30 s of poses are all within 0.2 m.
  const auto estimate = mapping::readTum(out / "trajectory.tum");
  const auto truth = mapping::readTum(out / "ground_truth.tum");
  const auto pairs = evaluation::associateByTime(estimate, truth, {});
  REQUIRE(pairs.size() > 100);
  const double end = 1e-9 * static_cast<double>(estimate[pairs.back().first].stamp_ns);
  double worst_after_kidnap = 0, worst_at_end = 0;
  for (const auto& [e, r] : pairs) {
    const double err = (estimate[e].position - truth[r].position).norm();
    const double t = 1e-9 * static_cast<double>(estimate[e].stamp_ns);
    if (t > 20.5) worst_after_kidnap = std::max(worst_after_kidnap, err);
    if (t > end - 30) worst_at_end = std::max(worst_at_end, err);
  }
  std::cout << "sim_nav kidnapped: worst error after the kidnapping " << worst_after_kidnap
            << " m, over the last 30 s " << worst_at_end << " m\n";
  CHECK(worst_after_kidnap > 1.0);  // it was lost
  CHECK(worst_at_end < 0.2);
}

TEST_CASE("sim_nav_slam: a goal is reached while the laser SLAM maps", "[e2e][nav][slow]") {
  const fs::path out = fs::temp_directory_path() / "tessera_e2e_sim_nav_slam";
  fs::remove_all(out);
  fs::create_directories(out);
  const RunReport report = test::runProfile("sim_nav_slam", out, {"goals.random=1"});
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(test::summaryInt(report, "goals", "reached") == 1);
  CHECK(test::summaryInt(report, "sim", "collisions") == 0);
  // The robot drove before any submap was finished: the navigator's costmap existed without a map.
  CHECK(test::summaryInt(report, "nav", "control_ticks") > 100);
  CHECK(fs::exists(out / "trajectory.tum"));
}
