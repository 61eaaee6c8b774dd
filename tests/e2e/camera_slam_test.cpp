// End to end: apps/profiles/sim_camera_slam.yaml on the first 1200 s of the seed-000 route (the
// cameras' first visits and the first revisits of cameras 0 and 1): the cameras calibrate from the
// robot's motion, localise it within a few centimetres, and their revisit constraints are all
// true. The full route and the four-way comparison are `tessera bench camera_network`.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <yaml-cpp/yaml.h>

#include <filesystem>

#include "../shared_data.hpp"
#include "run_profile.hpp"

namespace camera_slam_e2e_test {

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_camera_slam calibrates the cameras and sends only true revisit constraints",
          "[e2e][camera_network]") {
  const fs::path out = test::scratchDir("e2e_sim_camera_slam");
  const RunReport report = test::runProfile("sim_camera_slam", out, {"max_duration_s=1200"});
  CHECK(report.stop_reason == "reached max_duration_s");
  const auto& cams = test::summaryOf(report, "camera_slam");
  const auto calibrations = std::get<std::int64_t>(cams.at("calibrations"));
  const auto revisits = std::get<std::int64_t>(cams.at("revisits"));
  const double loc = std::get<double>(cams.at("camera_localisation_rms_m"));
  INFO("calibrations " << calibrations << ", revisits " << revisits << ", localisation RMS " << loc
                       << " m");
  CHECK(calibrations >= 4);
  CHECK(revisits >= 1);
  CHECK(std::get<std::int64_t>(cams.at("revisits_false")) == 0);
  CHECK(loc < 0.08);
  CHECK(test::summaryInt(report, "optimizer", "constraints_unresolved") == 0);
  // The calibrations file names each camera's submap and homography.
  const YAML::Node file = YAML::LoadFile((out / "camera_calibrations.yaml").string());
  REQUIRE(file["cameras"].size() == static_cast<std::size_t>(calibrations));
  for (const auto& c : file["cameras"]) {
    CHECK(c["homography"].size() == 9);
    CHECK(c["rms_px"].as<double>() < 4.0);
  }
  const auto final_ate =
      tessera::evaluation::computeAte(tessera::mapping::readTum(out / "trajectory_final.tum"),
                                      tessera::mapping::readTum(out / "ground_truth.tum"));
  INFO("final ATE " << final_ate.translation.rmse << " m");
  CHECK(final_ate.translation.rmse < 0.3);
  fs::remove_all(out);
}

}  // namespace camera_slam_e2e_test
