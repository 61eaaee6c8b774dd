// End to end: apps/profiles/rgbd_replay.yaml on the real TUM folder (player -> trajectory writer),
// and its refusal to run without a dataset folder.
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include "../shared_data.hpp"

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("rgbd_replay writes the ground truth of the TUM sequence", "[e2e][rgbd]") {
  TESSERA_SHARED_DATA(dir, "tum-rgbd-fr1-desk-9frames");
  const fs::path out = tessera::test::scratchDir("e2e_rgbd_replay");
  const std::string profile_path =
      std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/rgbd_replay.yaml";

  CHECK_THROWS_WITH(buildRuntime(loadProfile(profile_path), {}),
                    Catch::Contains("path") && Catch::Contains("required"));

  auto profile = loadProfile(profile_path, {"player.path=" + dir.string()});
  RuntimeOptions options;
  options.show_progress = false;
  options.output_dir = out.string();
  auto runtime = buildRuntime(profile, options);
  const RunReport report = runtime->run();
  CHECK(report.stop_reason == "all inputs finished");
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  REQUIRE(truth.size() == 9);
  CHECK(truth.front().stamp_ns == 0);
  CHECK(truth.back().stamp_ns == std::llround((1305031453.627706 - 1305031453.359684) * 1e9));
  // TUM fr1/desk starts about 1.3 m from the mocap origin, with the camera about 1.5 m up: the
  // file holds the full 3D pose, not a planar projection.
  CHECK(truth.front().position.head<2>().norm() > 0.5);
  CHECK(truth.front().position.z() > 1.0);
  CHECK(std::abs(truth.front().orientation.norm() - 1.0) < 1e-9);
  const Eigen::Vector3d up = truth.front().orientation * Eigen::Vector3d::UnitZ();
  CHECK(std::abs(up.z()) < 0.99);  // the camera looks down at the desk: not a yaw-only rotation
}
