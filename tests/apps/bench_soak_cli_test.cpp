// `tessera bench soak` end to end on a short soak (a quarter of a simulated hour, sampled every
// three minutes): the JSON's shape as the issue gives it, the files it writes, and that
// lifelong mapping keeps the graph smaller than the submaps made.
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("bench soak reports memory, CPU, accuracy and graph size per period", "[bench_soak]") {
  const auto dir = tessera::test::scratchDir("bench_soak");
  const auto run = runCli(
      "bench soak --json --hours 0.25 --period-hours 0.05 --out " + (dir / "soak").string(), dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  for (const char* key : {"machine", "hours", "series", "false_loops"}) CHECK(j.contains(key));
  CHECK(j["hours"].get<double>() == Approx(0.25));
  CHECK(j["false_loops"].get<std::int64_t>() >= 0);
  const auto& series = j["series"];
  REQUIRE(series.size() == 5);
  for (const auto& r : series) {
    for (const char* key : {"hour", "rss_mb", "cpu_ms_per_scan", "ate_m", "submaps", "graph_nodes"})
      CHECK(r.contains(key));
    CHECK(r["rss_mb"].get<double>() > 1.0);
    CHECK(r["cpu_ms_per_scan"].get<double>() > 0.0);
    CHECK(r["ate_m"].get<double>() >= 0.0);
    CHECK(r["ate_m"].get<double>() < 1.0);
  }
  CHECK(series[4]["hour"].get<double>() == Approx(0.25));
  // Two laps of the office: the second lap's submaps cover the first's, which are trimmed.
  CHECK(series[4]["submaps"].get<double>() > 20);
  CHECK(series[4]["graph_nodes"].get<double>() < 0.75 * series[4]["submaps"].get<double>());
  std::ifstream svg(dir / "soak" / "soak.svg");
  std::stringstream text;
  text << svg.rdbuf();
  CHECK(text.str().find("<svg") == 0);
  std::size_t polylines = 0;
  for (std::size_t at = 0; (at = text.str().find("<polyline", at)) != std::string::npos; ++at)
    ++polylines;
  CHECK(polylines == 4);
  CHECK(std::filesystem::exists(dir / "soak" / "soak.json"));
  CHECK(std::filesystem::exists(dir / "soak" / "run" / "resources.csv"));
}

TEST_CASE("bench soak names a bad option and a profile it cannot soak", "[bench_soak]") {
  const auto dir = tessera::test::scratchDir("bench_soak_bad");
  const auto zero = runCli("bench soak --hours 0", dir);
  CHECK(zero.exit_code != 0);
  CHECK(zero.err.find("hours") != std::string::npos);
  // CLI11's own range check lets NaN through: it compares neither below nor above.
  for (const std::string value : {"nan", "inf", "''", "1x"}) {
    INFO(value);
    const auto bad = runCli("bench soak --hours " + value, dir);
    CHECK(bad.exit_code != 0);
    CHECK(bad.err.find("--hours") != std::string::npos);
    CHECK(bad.err.find("finite number") != std::string::npos);
  }
  // sim_slam_global has no resource monitor: the run refuses the override, the bench says where
  // to look.
  const auto other = runCli(
      "bench soak --hours 0.01 --profile sim_slam_global --out " + (dir / "other").string(), dir);
  CHECK(other.exit_code != 0);
  CHECK(other.err.find("run.log") != std::string::npos);
}

TEST_CASE("bench soak of the RGB-D profile counts keyframes and judges its loops",
          "[bench_soak][lifelong]") {
  // Two and a half minutes of simulated time: the short loop once (~107 s), then back into it,
  // where loops tie the revisit to the first lap and its keyframes are trimmed.
  const auto dir = tessera::test::scratchDir("bench_soak_rgbd");
  const auto run = runCli(
      "bench soak --json --profile sim_rgbd_lifelong --hours 0.042 "
      "--period-hours 0.014 --out " +
          (dir / "soak").string(),
      dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["false_loops"].get<std::int64_t>() == 0);
  const auto& series = j["series"];
  REQUIRE(series.size() == 3);
  const auto& last = series[2];
  CHECK(last["ate_m"].get<double>() >= 0.0);
  CHECK(last["ate_m"].get<double>() < 0.5);
  // Keyframes made (submaps) against kept (graph_nodes): the first lap's covered ones are gone.
  CHECK(last["submaps"].get<double>() > 300);
  CHECK(last["graph_nodes"].get<double>() < last["submaps"].get<double>() - 20);
  CHECK(std::filesystem::exists(dir / "soak" / "run" / "trajectory_optimized.tum"));
  CHECK(std::filesystem::exists(dir / "soak" / "run" / "loops.csv"));
}
