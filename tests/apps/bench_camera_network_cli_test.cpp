// `tessera bench camera_network` end to end on the first 200 s of the seed-000 route: the JSON
// has exactly the shape, every configuration scores, bad options are named.
#include <nlohmann/json.hpp>

#include <filesystem>
#include <set>
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
}

TEST_CASE("bench camera_network names a bad option", "[bench_camera_network]") {
  const auto dir = tessera::test::scratchDir("bench_camera_network_bad");
  const auto config = runCli("bench camera_network --configurations vasco", dir);
  CHECK(config.exit_code != 0);
  CHECK(config.err.find("vasco") != std::string::npos);
  const auto cams = runCli("bench camera_network --cameras maybe", dir);
  CHECK(cams.exit_code != 0);
  CHECK(cams.err.find("--cameras") != std::string::npos);
}
