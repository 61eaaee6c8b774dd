// `tessera bench overload` end to end on one short profile, in one process (`tessera run`) and as
// a deployment (`--launch`: one process per group, losses between processes from the launch's
// delivery ledger). Runs a launch, so it is one of the shared-memory tests (one at a time).
#include <nlohmann/json.hpp>

#include <string>

#include "../runtime/shm/launch_fixtures.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("bench overload runs a profile at 10x in one process and as a launch",
          "[bench_overload]") {
  const auto dir = tessera::test::freshDir("bench_overload");
  for (const std::string mode : {"", "--launch "}) {
    INFO(mode);
    const auto run = runCli("bench overload --json --seconds 2 --profiles sim_mapping " + mode +
                                "--out " + (dir / "out").string(),
                            dir);
    INFO(run.err);
    REQUIRE(run.exit_code == 0);
    const auto j = nlohmann::json::parse(run.out);
    CHECK(j["factor"] == 10);
    CHECK(j["command"] == (mode.empty() ? "run" : "launch"));
    REQUIRE(j["profiles"].size() == 1);
    const auto& p = j["profiles"][0];
    CHECK(p["profile"] == "sim_mapping");
    CHECK(p["finished"] == true);
    CHECK(p["reliable_lost"] == 0);
    CHECK(p["reliable_drops"] == 0);
    // 2 s of wall time at 10x: about 20 s of data.
    CHECK(p["data_s"].get<double>() > 15.0);
    CHECK(p["data_s"].get<double>() < 25.0);
  }
  CHECK(tessera::test::shmClean());
}

TEST_CASE("bench overload names a bad option", "[bench_overload]") {
  const auto dir = tessera::test::freshDir("bench_overload_bad");
  const auto bad = runCli("bench overload --factor 0", dir);
  CHECK(bad.exit_code != 0);
  CHECK(bad.err.find("factor") != std::string::npos);
  const auto nan = runCli("bench overload --factor nan", dir);
  CHECK(nan.exit_code != 0);
  CHECK(nan.err.find("finite number") != std::string::npos);
}
