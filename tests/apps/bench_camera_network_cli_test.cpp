// `tessera bench camera_network` end to end on the first 200 s of the seed-000 route: the JSON
// has exactly the shape, every configuration scores, bad options are named.
#include <nlohmann/json.hpp>

#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <set>
#include <sstream>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("bench camera_network reports configurations with and without cameras",
          "[bench_camera_network]") {
  const auto dir = tessera::test::scratchDir("bench_camera_network");
  const auto run = runCli(
      "bench camera_network --json --max-duration 200 --configurations "
      "two_level_ceres,scan_matching --out " +
          (dir / "out").string(),
      dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  std::set<std::string> top;
  for (const auto& [k, v] : j.items()) top.insert(k);
  CHECK(top == std::set<std::string>{"machine", "configurations", "calibration_rms_px",
                                     "camera_localisation_error_m", "false_revisit_constraints"});
  REQUIRE(j["configurations"].size() == 4);
  const std::set<std::string> keys{
      "name",        "cameras", "ate_rmse_m", "max_error_m", "wall_cells_found", "false_wall_cells",
      "peak_rss_mb", "cpu_s",   "submaps",    "constraints"};
  for (const auto& c : j["configurations"]) {
    std::set<std::string> got;
    for (const auto& [k, v] : c.items()) got.insert(k);
    CHECK(got == keys);
    CHECK(c["ate_rmse_m"].get<double>() < 0.5);
    CHECK(c["wall_cells_found"].get<double>() > 0.8);
    CHECK(c["peak_rss_mb"].get<double>() > 0);
    // With cameras every configuration cuts submaps at the cameras.
    if (c["cameras"].get<bool>()) CHECK(c["submaps"].get<int>() >= 2);
  }
  CHECK(j["configurations"][0]["name"] == "two_level_ceres");
  CHECK(j["configurations"][3]["name"] == "scan_matching");
  CHECK(j["configurations"][2]["submaps"] == 1);  // scan matching without cameras: one map
  CHECK(j["false_revisit_constraints"] == 0);
  CHECK(std::filesystem::file_size(dir / "out" / "maps.png") > 1000);  // the maps side by side
  // two_level_ceres draws its map from the scans and keeps the submap mosaic beside it; the
  // others, without the scan-level graph, have the mosaic as their map.
  namespace fs = std::filesystem;
  for (const char* run_dir : {"two_level_ceres", "two_level_ceres_cameras"}) {
    CHECK(fs::exists(dir / "out" / run_dir / "map.yaml"));
    CHECK(fs::exists(dir / "out" / run_dir / "map_submaps.yaml"));
  }
  CHECK(fs::exists(dir / "out" / "scan_matching" / "map.yaml"));
  CHECK_FALSE(fs::exists(dir / "out" / "scan_matching" / "map_submaps.yaml"));
}

TEST_CASE("bench camera_network names a bad option", "[bench_camera_network]") {
  const auto dir = tessera::test::scratchDir("bench_camera_network_bad");
  const auto config = runCli("bench camera_network --configurations vasco", dir);
  CHECK(config.exit_code != 0);
  CHECK(config.err.find("vasco") != std::string::npos);
  const auto cams = runCli("bench camera_network --cameras maybe", dir);
  CHECK(cams.exit_code != 0);
  CHECK(cams.err.find("--cameras") != std::string::npos);
  for (const char* seeds : {"abc", "''", "1.5", "nan", "-1"}) {
    const auto bad = runCli(std::string("bench camera_network --seeds ") + seeds, dir);
    INFO("--seeds " << seeds);
    CHECK(bad.exit_code != 0);
    CHECK(bad.err.find("--seeds") != std::string::npos);
  }
}

TEST_CASE("bench camera_network runs each seed, and a seed repeats exactly",
          "[bench_camera_network]") {
  const auto dir = tessera::test::scratchDir("bench_camera_network_seeds");
  const auto run = runCli(
      "bench camera_network --max-duration 200 --configurations two_level_ceres --cameras on "
      "--seeds 1,2,1 --montage '' --out " +
          (dir / "out").string(),
      dir);
  INFO(run.out << run.err);
  REQUIRE(run.exit_code == 0);
  // Each seed's profile seeds the simulator, the cameras and the filter.
  const auto profile =
      YAML::LoadFile((dir / "out/two_level_ceres_cameras/seed_2/profile.yaml").string());
  CHECK(profile["actors"]["sim"]["params"]["seed"].as<int>() == 2);
  CHECK(profile["actors"]["cameras"]["params"]["seed"].as<int>() == 2);
  CHECK(profile["actors"]["slam"]["params"]["rbpf"]["seed"].as<int>() == 2);
  // The per-seed line: seed 1 run twice gives the same ATE; seed 2, other noise, another
  // trajectory.
  const auto at = run.out.find("ATE per seed:");
  REQUIRE(at != std::string::npos);
  std::istringstream line(run.out.substr(at + 13));
  std::string name, cameras;
  double a = 0, b = 0, c = 0;
  line >> name >> cameras >> a >> b >> c;
  CHECK(name == "two_level_ceres");
  CHECK(a == c);
  CHECK(a < 0.5);
  CHECK(b < 0.5);
  const auto runs = dir / "out/two_level_ceres_cameras";
  CHECK(tessera::test::fileText(runs / "seed_1/trajectory_final.tum") !=
        tessera::test::fileText(runs / "seed_2/trajectory_final.tum"));
}
