// `tessera bench chaos` end to end on a short run (12 s, 6 kills, 3 stalls of 2-3 s, one kill
// of the launcher): the report's fields, every kill recovered, nothing reliable lost between live
// processes, and outputs that are complete. Runs launches, so it is one of the shared-memory
// tests (one at a time).
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>

#include "../runtime/shm/launch_fixtures.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("bench chaos kills and stalls workers and the launcher, and reports what it cost",
          "[bench_chaos]") {
  const auto dir = tessera::test::freshDir("bench_chaos");
  const auto run = runCli(
      "bench chaos --json --duration 12 --kills 6 --stalls 3 --min-stall 2 --max-stall 3 "
      "--launcher-kills 1 --out " +
          (dir / "chaos").string(),
      dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  for (const char* key : {"machine", "profile", "duration_s", "run", "launcher_kills"})
    CHECK(j.contains(key));
  const auto& r = j["run"];
  CHECK(r["exit_code"] == 0);
  CHECK(r["kills"] == 6);
  CHECK(r["stalls"] == 3);
  // Each stall outlasts RouDi's 1.5 s heartbeat timeout: the stopped process keeps its queues.
  CHECK(r["stall_s"]["over_1_5s"] == 3);
  CHECK(r["not_back"] == 0);
  int restarts = 0;
  for (const auto& [process, n] : r["restarts"].items()) restarts += n.get<int>();
  CHECK(restarts == 6);  // one restart per kill
  CHECK(r["recovery_s"]["max"].get<double>() > 0.0);
  CHECK(r["recovery_s"]["max"].get<double>() < 10.0);
  CHECK(r["reliable"]["sent"].get<std::uint64_t>() > 0);
  CHECK(r["reliable"]["lost_live"] == 0);
  CHECK(r["outputs"]["files"].get<int>() > 3);
  CHECK(r["outputs"]["incomplete"].empty());
  const auto& l = j["launcher_kills"];
  CHECK(l["kills"] == 1);
  CHECK(l["orphans_killed"] == 0);
  CHECK(l["relaunch_s"]["max"].get<double>() > 0.0);
  CHECK(l["outputs"]["incomplete"].empty());
  CHECK(std::filesystem::exists(dir / "chaos" / "chaos.json"));
  CHECK(tessera::test::shmClean());
}

TEST_CASE("bench chaos refuses a simulated-time profile and one with nothing to restart",
          "[bench_chaos]") {
  const auto dir = tessera::test::freshDir("bench_chaos_bad");
  const auto sim = runCli("bench chaos --profile sim_mapping --out " + (dir / "a").string(), dir);
  CHECK(sim.exit_code != 0);
  CHECK(sim.err.find("clock: wall") != std::string::npos);
  std::ofstream(dir / "wall.yaml") << tessera::test::wallMappingProfile("");
  const auto none = runCli(
      "bench chaos --profile " + (dir / "wall.yaml").string() + " --out " + (dir / "b").string(),
      dir);
  CHECK(none.exit_code != 0);
  CHECK(none.err.find("lists none") != std::string::npos);
  const auto bad = runCli("bench chaos --kills -1", dir);
  CHECK(bad.exit_code != 0);
  CHECK(bad.err.find("kills") != std::string::npos);
  const auto stalls = runCli("bench chaos --min-stall 4 --max-stall 3", dir);
  CHECK(stalls.exit_code != 0);
  CHECK(stalls.err.find("--min-stall 4") != std::string::npos);
  for (const std::string option : {"--min-stall", "--max-stall", "--duration"}) {
    for (const std::string value : {"nan", "''", "3s"}) {
      INFO(option << " " << value);
      const auto bad = runCli("bench chaos " + option + " " + value, dir);
      CHECK(bad.exit_code != 0);
      CHECK(bad.err.find(option) != std::string::npos);
      CHECK(bad.err.find("finite number") != std::string::npos);
    }
  }
}
