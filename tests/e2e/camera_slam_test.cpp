// End to end: apps/profiles/sim_camera_slam.yaml on the first 1200 s of the seed-000 route (the
// cameras' first visits and the first revisits of cameras 0 and 1): the cameras calibrate from the
// robot's motion, localise it within a few centimetres, and their revisit constraints are all
// true; and a kidnapping on the same floor, found lost by the filter and placed again by the next
// camera. The full route and the four-way comparison are `tessera bench camera_network`.
#include <tessera/camera_network/camera_calibration_file.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
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
  // Each visit's path is the odometry's placed on the SLAM (odometry_shape): the calibrations'
  // reprojection RMS is then near the pixel noise's √2 px (2.5-3 px from the SLAM's path).
  CHECK(test::summaryInt(report, "camera_slam", "visits_odometry_shaped") >= calibrations);
  const double rms_px = std::get<double>(cams.at("calibration_rms_px"));
  INFO("calibration RMS " << rms_px << " px");
  CHECK(rms_px < 1.8);
  CHECK(test::summaryInt(report, "optimizer", "constraints_unresolved") == 0);
  // The calibrations file names each camera's submap and homography.
  const YAML::Node file = YAML::LoadFile((out / "camera_calibrations.yaml").string());
  REQUIRE(file["cameras"].size() == static_cast<std::size_t>(calibrations));
  for (const auto& c : file["cameras"]) {
    CHECK(c["homography"].size() == 9);
    CHECK(c["rms_px"].as<double>() < 4.0);
  }
  // The same calibrations, read back by the file's reader and saved with the map (the map
  // assembler got them over camera_calibrations).
  const auto records =
      tessera::camera_network::readCameraCalibrations(out / "camera_calibrations.yaml");
  const auto state = tessera::laser_slam::loadSlamState(out / "slam_state");
  REQUIRE(state.cameras.size() == records.size());
  // One record type: the saved map holds exactly what the calibrations file holds.
  for (std::size_t k = 0; k < records.size(); ++k) CHECK(state.cameras[k] == records[k]);
  const auto final_ate =
      tessera::evaluation::computeAte(tessera::mapping::readTum(out / "trajectory_final.tum"),
                                      tessera::mapping::readTum(out / "ground_truth.tum"));
  INFO("final ATE " << final_ate.translation.rmse << " m");
  // The run repeats exactly (0.123 m here), but it is one draw of a particle filter: runs that
  // differed only in the order of one instant's messages gave 0.07-0.20 m, and the settings
  // before stop 61 0.23 m. So the bound only catches a broken map; the accuracy is measured over
  // seeds by `tessera bench camera_network --seeds` (docs/benchmarks.md).
  CHECK(final_ate.translation.rmse < 0.3);
  fs::remove_all(out);
}

TEST_CASE("a robot kidnapped on the camera floor is found lost and relocalised by a camera",
          "[e2e][camera_network]") {
  // At 600 s, between cameras 3 and 4, the robot is carried 95 m along its route to the west
  // corridor and put down facing a wall (turned 90 degrees off the route); the next camera it
  // passes is camera 0, calibrated in submap 1 at the start.
  const fs::path out = test::scratchDir("e2e_sim_camera_slam_kidnapped");
  const RunReport report = test::runProfile("sim_camera_slam", out,
                                            {"max_duration_s=950", "sim.kidnap_at_s=600",
                                             "sim.kidnap_route_m=260", "sim.kidnap_turn=1.57"});
  CHECK(test::summaryInt(report, "sim", "kidnapped") == 1);
  // The filter notices at once: two updates without the map under the scan, neither inserted.
  CHECK(test::summaryInt(report, "slam", "lost") == 1);
  CHECK(test::summaryInt(report, "slam", "suspect_updates") == 2);
  CHECK(test::summaryInt(report, "camera_slam", "revisits") >= 1);
  CHECK(test::summaryInt(report, "camera_slam", "revisits_false") == 0);

  // The smoothed trajectory after the jump lies in the frame of the one before it: the camera's
  // revisit placed the unanchored submaps. (The poses of the two suspect updates right after the
  // jump stay on the old submap, where the filter thought the robot was.)
  auto final_poses = tessera::mapping::readTum(out / "trajectory_final.tum");
  std::erase_if(final_poses, [](const auto& p) {
    return p.stamp_ns >= 600'000'000'000 && p.stamp_ns < 605'000'000'000;  // kidnap + 5 s
  });
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  const auto ate = tessera::evaluation::computeAte(final_poses, truth);
  INFO("final ATE " << ate.translation.rmse << " m, max " << ate.translation.max << " m");
  CHECK(ate.translation.rmse < 0.3);
  CHECK(ate.translation.max < 1.0);
  // The live pose is back in the map as soon as the robot leaves camera 0's view (at 686 s;
  // the relocalisation uses the online poses instead of waiting for smoothed ones): at 700 s
  // it agrees with the smoothed trajectory.
  CHECK(test::summaryInt(report, "camera_slam", "unanchored_handovers") == 1);
  CHECK(test::summaryInt(report, "camera_slam", "relocalisations") == 1);
  // ... and refined once its submap's smoothed trajectory came.
  CHECK(test::summaryInt(report, "camera_slam", "relocalisations_refined") == 1);
  const auto live = tessera::mapping::readTum(out / "trajectory.tum");
  const auto live_at = std::find_if(live.begin(), live.end(),
                                    [](const auto& p) { return p.stamp_ns >= 700'000'000'000; });
  REQUIRE(live_at != live.end());
  const auto final_at = std::find_if(final_poses.begin(), final_poses.end(), [&](const auto& p) {
    return p.stamp_ns == live_at->stamp_ns;
  });
  REQUIRE(final_at != final_poses.end());
  const double live_gap = (final_at->position - live_at->position).norm();
  INFO("live pose off the smoothed one by " << live_gap << " m at 700 s");
  CHECK(live_gap < 1.0);
  fs::remove_all(out);
}

}  // namespace camera_slam_e2e_test
