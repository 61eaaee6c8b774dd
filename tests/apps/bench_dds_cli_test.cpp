// `tessera bench dds` end to end, briefly: the JSON has the documented shape, every transport and
// size has latencies, the two-host bandwidth run sent compressed bytes, and bad options are named.
// Nothing here depends on the times measured.
#include <nlohmann/json.hpp>

#include <set>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

namespace bench_dds_cli_test {

TEST_CASE("bench dds reports ours and raw Cyclone DDS at three sizes and the laser bandwidth",
          "[bench_dds][dds]") {
  const auto dir = tessera::test::scratchDir("bench_dds");
  const auto run =
      runCli("bench dds --json --samples 5 --rounds 1 --bandwidth-seconds 20 --visual ''", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j.size() == 3);
  CHECK(!j["machine"].get<std::string>().empty());
  REQUIRE(j["results"].size() == 6);
  std::set<std::pair<std::string, std::size_t>> seen;
  for (const auto& r : j["results"]) {
    CHECK(r.size() == 4);
    seen.insert({r["transport"].get<std::string>(), r["payload_bytes"].get<std::size_t>()});
    CHECK(r["p50_us"].get<double>() > 0);
    CHECK(r["p99_us"].get<double>() >= r["p50_us"].get<double>());
  }
  for (const char* t : {"dds", "dds_raw"})
    for (std::size_t bytes : {std::size_t{64}, std::size_t{65536}, std::size_t{1048576}})
      CHECK(seen.count({t, bytes}) == 1);
  REQUIRE(j["bandwidth"].size() == 1);
  const auto& b = j["bandwidth"][0];
  CHECK(b["pipeline"] == "laser");
  CHECK(b["bytes_per_s_sent"].get<double>() > 0);
  CHECK(b["bytes_per_s_sent"].get<double>() < b["bytes_per_s_raw"].get<double>());
}

TEST_CASE("bench dds names a bad option", "[bench_dds][dds]") {
  const auto dir = tessera::test::scratchDir("bench_dds_bad");
  const auto run = runCli("bench dds --samples 0", dir);
  CHECK(run.exit_code == 2);
  CHECK(run.err.find("--samples") != std::string::npos);
  const auto visual =
      runCli("bench dds --samples 1 --bandwidth-seconds 0 --visual /nonexistent", dir);
  CHECK(visual.exit_code != 0);
  CHECK(visual.err.find("--visual /nonexistent: no such folder") != std::string::npos);
}

}  // namespace bench_dds_cli_test
