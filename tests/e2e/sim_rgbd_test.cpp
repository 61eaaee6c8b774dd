// End to end: apps/profiles/sim_rgbd.yaml for its first 5 simulated seconds (75 frames at 15 Hz,
// the bottom corridor into the south room): simulator -> rendered RGB-D camera -> front end ->
// keyframe graph -> writers. The front end tracks every frame and its ATE against the camera's
// true pose stays under 2 cm.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <catch2/catch.hpp>

#include "../shared_data.hpp"
#include "run_profile.hpp"

#include <filesystem>

using namespace tessera;
using test::runProfile;
using test::summaryInt;
namespace fs = std::filesystem;

TEST_CASE("sim_rgbd tracks the rendered office camera to under 2 cm ATE, 0 lost",
          "[e2e][rgbd][sim]") {
  const fs::path out = test::scratchDir("e2e_sim_rgbd");
  const RunReport report = runProfile("sim_rgbd", out, {"max_duration_s=5"});
  CHECK(report.stop_reason == "reached max_duration_s");

  const auto truth = mapping::readTum(out / "ground_truth.tum");
  REQUIRE(truth.size() >= 70);  // 15 Hz over 5 s
  CHECK(truth.size() <= 77);
  for (const auto& p : truth) CHECK(p.position.z() == Approx(1.0));  // the camera mount height
  CHECK(mapping::readTum(out / "robot_ground_truth.tum").size() > truth.size());

  // Every rendered frame reaches the front end (the simulated clock waits for it) and is tracked.
  const std::int64_t frames = summaryInt(report, "camera", "frames_published");
  CHECK(summaryInt(report, "front_end", "frames") == frames);
  CHECK(summaryInt(report, "front_end", "lost") == 0);
  CHECK(summaryInt(report, "front_end", "skipped") == 0);
  const auto trajectory = mapping::readTum(out / "trajectory.tum");
  CHECK(static_cast<std::int64_t>(trajectory.size()) == frames);
  const std::int64_t keyframes = summaryInt(report, "front_end", "keyframes");
  CHECK(keyframes >= 2);
  CHECK(summaryInt(report, "graph", "graph_keyframes") == keyframes);
  CHECK(mapping::readTum(out / "keyframes.tum").size() == static_cast<std::size_t>(keyframes));

  // The written trajectory against the written truth, and the front end's own figure.
  const double ate = evaluation::computeAte(trajectory, truth).translation.rmse;
  INFO("ATE " << ate << " m over " << trajectory.size() << " frames, " << keyframes
              << " keyframes");
  CHECK(ate < 0.02);
  const auto& fe = test::summaryOf(report, "front_end");
  CHECK(std::get<double>(fe.at("ate_rmse_m")) == Approx(ate).margin(1e-6));
  fs::remove_all(out);
}
