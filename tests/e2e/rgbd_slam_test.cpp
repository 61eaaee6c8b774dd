// End to end: apps/profiles/rgbd_slam.yaml on the 9 TUM fr1/desk frames (player -> front end ->
// loop detector and keyframe graph -> writers, keyframes -> mapper): the outputs exist, the ATE
// against the dataset is below 2 cm, and the mapper's cloud and OctoMap files load.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/mapping3d/cloud_map.hpp>
#include <tessera/mapping3d/octomap_builder.hpp>
#include <tessera/runtime/profile.hpp>

#include <nlohmann/json.hpp>

#include <fstream>

#include "../apps/cli_run.hpp"
#include "../shared_data.hpp"

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("rgbd_slam tracks the TUM fr1/desk frames to under 2 cm ATE",
          "[e2e][rgbd][visual_slam]") {
  TESSERA_SHARED_DATA(dir, "tum-rgbd-fr1-desk-9frames");
  const fs::path out = tessera::test::scratchDir("e2e_rgbd_slam");
  fs::create_directories(out);
  const std::string profile_path =
      std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/rgbd_slam.yaml";

  CHECK_THROWS_WITH(buildRuntime(loadProfile(profile_path), {}),
                    Catch::Contains("path") && Catch::Contains("required"));

  // Through the CLI, which also writes summary.json.
  const test::CliRun run = test::runCli(
      "run " + profile_path + " --set player.path=" + dir.string() + " --out " + out.string(), out);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);

  const auto trajectory = mapping::readTum(out / "trajectory.tum");
  const auto truth = mapping::readTum(out / "ground_truth.tum");
  const auto keyframes = mapping::readTum(out / "keyframes.tum");
  CHECK(trajectory.size() == 9);
  CHECK(truth.size() == 9);
  CHECK(keyframes.size() >= 1);
  CHECK(fs::exists(out / "keyframe_graph.g2o"));
  const double ate = evaluation::computeAte(trajectory, truth).translation.rmse;
  CHECK(ate < 0.02);

  std::ifstream in(out / "summary.json");
  REQUIRE(in);
  const auto summary = nlohmann::json::parse(in);
  INFO(summary.dump(2));
  const auto& fe = summary.at("actors").at("front_end");
  CHECK(fe.at("frames") == 9);
  CHECK(fe.at("lost") == 0);
  CHECK(fe.at("ate_rmse_m").get<double>() < 0.02);
  CHECK(std::abs(fe.at("ate_rmse_m").get<double>() - ate) < 1e-6);
  CHECK(summary.at("actors").at("graph").at("graph_keyframes") == fe.at("keyframes"));
  // The loop detector sees every keyframe; 5 keyframes are fewer than its vocabulary bootstrap
  // needs, so no query runs and no loop is published.
  const auto& loops = summary.at("actors").at("loops");
  CHECK(loops.at("keyframes_received") == fe.at("keyframes"));
  CHECK(loops.at("keyframes_bad") == 0);
  CHECK(loops.at("published") == 0);

  const auto& mapper = summary.at("actors").at("mapper");
  CHECK(mapper.at("keyframes_mapped") == fe.at("keyframes"));
  CHECK(mapper.at("keyframes_bad") == 0);
  const auto cloud = mapping3d::readPcd(out / "cloud.pcd");
  CHECK(cloud.size() > 1000);
  CHECK(mapping3d::readPly(out / "cloud.ply").size() == cloud.size());
  mapping3d::OctoMapBuilder octomap;
  REQUIRE_NOTHROW(octomap.readBinary(out / "map.bt"));
  CHECK(octomap.stats().occupied_leaves > 100);
}
