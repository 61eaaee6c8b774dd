// End to end: run apps/profiles/sim_odometry.yaml (simulator with wheel encoders and a gyro ->
// two wheel_gyro_odometry actors, with and without the gyro -> trajectory writers) over the
// office route and compare the heading drift of both with the ground truth (issue figure: the
// gyro's at least 5x smaller).
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <iostream>

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_odometry: the gyro cuts the heading drift of wheel odometry at least 5x",
          "[e2e][odometry]") {
  const fs::path out = fs::temp_directory_path() / "tessera_e2e_sim_odometry";
  fs::remove_all(out);
  fs::create_directories(out);
  auto profile =
      loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_odometry.yaml", {});
  RuntimeOptions options;
  options.show_progress = false;
  options.output_dir = out.string();
  auto runtime = buildRuntime(profile, options);
  const RunReport report = runtime->run();
  CHECK(report.stop_reason == "all inputs finished");
  for (const auto& a : report.actors) CHECK(a.drops == 0);

  const auto truth = mapping::readTum(out / "robot_ground_truth.tum");
  const auto gyro = mapping::readTum(out / "odometry_gyro.tum");
  const auto wheels = mapping::readTum(out / "odometry_wheels.tum");
  REQUIRE(truth.size() > 20000);  // ~450 s at 50 Hz
  // Every tick interval is one odometry pose (the first ticks are the baseline).
  CHECK(gyro.size() + 1 == truth.size());
  CHECK(wheels.size() + 1 == truth.size());

  const auto g = evaluation::computeHeadingDrift(gyro, truth);
  const auto w = evaluation::computeHeadingDrift(wheels, truth);
  std::cout << "sim_odometry heading drift [deg]: wheels final " << w.final_deg << " rms "
            << w.error_deg.rmse << "; gyro final " << g.final_deg << " rms " << g.error_deg.rmse
            << "\n";
  CHECK(w.final_deg > 5 * g.final_deg);
  CHECK(w.error_deg.rmse > 5 * g.error_deg.rmse);
  // Both start on the truth and follow it: the wheels' drift is the calibration errors', not a
  // broken filter.
  CHECK(w.final_deg < 180);
}
