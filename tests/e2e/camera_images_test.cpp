// End to end: apps/profiles/sim_camera_images.yaml on the first 60 s of the seed-000 route (the
// robot's first visit under camera 0, 0-45.3 s): the simulator renders the cameras' images, seven
// marker_camera actors find the robot's ArUco marker in them, and camera 0 is calibrated from
// those real detections alone. The full comparison with sim_camera_slam's geometric detections is
// in docs/benchmarks.md.
#include <tessera/camera_network/camera_calibration_file.hpp>
#include <tessera/runtime/profile.hpp>

#include <filesystem>
#include <string>

#include "../shared_data.hpp"
#include "run_profile.hpp"

namespace camera_images_e2e_test {

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_camera_images calibrates camera 0 from markers detected in rendered images",
          "[e2e][camera_network][camera_images]") {
  const fs::path out = test::scratchDir("e2e_sim_camera_images");
  const RunReport report = test::runProfile("sim_camera_images", out, {"max_duration_s=60"});
  CHECK(report.stop_reason == "reached max_duration_s");

  // The simulator rendered images and published no geometric sightings of its own.
  CHECK(test::summaryInt(report, "cameras", "images") > 400);
  CHECK(test::summaryInt(report, "cameras", "detections") == 0);
  CHECK(test::summaryInt(report, "cameras", "events") == 0);

  // Camera 0 saw the whole visit: in, the marker in almost every frame, out again.
  const auto detections = test::summaryInt(report, "camera0", "detections");
  const auto misses = test::summaryInt(report, "camera0", "misses");
  INFO("camera 0: " << detections << " detections, " << misses << " misses");
  CHECK(test::summaryInt(report, "camera0", "events") == 2);
  CHECK(detections > 400);
  CHECK(misses < detections / 20);
  CHECK(test::summaryInt(report, "camera0", "other_markers") == 0);
  CHECK(test::summaryInt(report, "camera0", "read_failures") == 0);
  CHECK(test::summaryInt(report, "camera0", "late_frames") == 0);
  for (int id = 1; id < 7; ++id)  // not visited yet
    CHECK(test::summaryInt(report, "camera" + std::to_string(id), "events") == 0);

  // The SLAM took every one of them and calibrated camera 0.
  CHECK(test::summaryInt(report, "camera_slam", "sightings") == detections);
  CHECK(test::summaryInt(report, "camera_slam", "calibrations") == 1);
  const double rms =
      std::get<double>(test::summaryOf(report, "camera_slam").at("calibration_rms_px"));
  INFO("calibration RMS " << rms << " px");
  CHECK(rms < 4.0);
  const auto records =
      tessera::camera_network::readCameraCalibrations(out / "camera_calibrations.yaml");
  REQUIRE(records.size() == 1);
  CHECK(records[0].camera == 0);
  // From the whole visit, which ends when the marker leaves the image at 45.3 s. (Within the run
  // the calibration would come when camera 1's view starts the next submap, at 142 s; here the
  // run's end finishes the submap.)
  CHECK(records[0].stamp_ns > 44'000'000'000);
  CHECK(records[0].stamp_ns < 47'000'000'000);
  fs::remove_all(out);
}

}  // namespace camera_images_e2e_test
