// `tessera bench ipc --json`: runs end to end (RouDi, forked leader and follower, every transport)
// and reports one JSON object of the documented shape. Timing targets are reported, not asserted.
#include "../../apps/cli_run.hpp"

#include <nlohmann/json.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <filesystem>
#include <set>

using tessera::test::runCli;

TEST_CASE("bench ipc prints one JSON object with rows for every transport and size", "[shm]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_bench_ipc_test";
  std::filesystem::create_directories(dir);
  const auto run = runCli("bench ipc --samples 50 --rounds 2 --stream-seconds 0.2 --json", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);  // throws unless stdout is exactly JSON
  CHECK(j["machine"].is_string());
  CHECK(j["samples"] == 50);
  CHECK(j["rounds"] == 2);
  CHECK(j["fill"] == "first-use");  // iceperf's method unless --fill every

  std::set<std::pair<std::string, std::size_t>> seen;
  for (const auto& row : j["results"]) {
    const std::string transport = row["transport"];
    const std::size_t bytes = row["payload_bytes"];
    seen.insert({transport, bytes});
    INFO(transport << " " << bytes);
    const double ping = row["ping_p50_us"], pong = row["pong_p50_us"];
    CHECK(ping > 0);
    CHECK(pong > 0);
    CHECK(row["p50_us"].get<double>() == Approx(0.5 * (ping + pong)));
    CHECK(row["p99_us"].get<double>() >= std::min(ping, pong));
    CHECK(row["round_trip_p50_us"].get<double>() > 0);
    if (bytes == 64) {
      CHECK(row["msgs_per_s"].get<double>() > 0);
    } else {
      CHECK(row["msgs_per_s"].is_null());
    }
    if (transport == "iceoryx") {
      CHECK(row["payload_copies"] == 0);  // every message built in its loaned chunk
    }
  }
  for (const char* transport : {"iceoryx", "iceoryx_raw", "uds", "inproc"}) {
    for (std::size_t bytes : {64u, 4096u, 1u << 20, 4u << 20}) {
      CHECK(seen.count({transport, bytes}) == 1);
    }
  }

  for (const char* target : {"iceoryx_over_raw_p50_worst", "iceoryx_p50_4MiB_over_64B",
                             "uds_over_iceoryx_p50_1MiB", "uds_over_iceoryx_p50_4MiB",
                             "iceoryx_over_raw_rtt_p50_worst", "uds_over_iceoryx_rtt_p50_1MiB",
                             "uds_over_iceoryx_rtt_p50_4MiB", "iceoryx_msgs_per_s_64B"}) {
    INFO(target);
    REQUIRE(j["targets"].contains(target));
    CHECK(j["targets"][target]["value"].get<double>() > 0);
    CHECK(j["targets"][target]["met"].is_boolean());
  }
  // Nothing left behind: RouDi's shared memory and the children's runtime locks are gone.
  CHECK_FALSE(std::filesystem::exists("/dev/shm/iceoryx_mgmt"));
  for (const auto& entry : std::filesystem::directory_iterator("/tmp")) {
    const std::string name = entry.path().filename().string();
    INFO(name);
    CHECK_FALSE((name.rfind("tessera_bench_ipc_", 0) == 0 && entry.path().extension() == ".lock"));
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("bench ipc rejects rounds and fill modes it cannot run before starting anything",
          "[shm]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_bench_ipc_rounds_test";
  std::filesystem::create_directories(dir);
  const auto none = runCli("bench ipc --rounds 0", dir);
  CHECK(none.exit_code != 0);
  CHECK(none.err.find("--rounds must be at least 1") != std::string::npos);
  const auto too_long = runCli("bench ipc --samples 100000 --rounds 1", dir);
  CHECK(too_long.exit_code != 0);
  CHECK(too_long.err.find("samples per round; raise --rounds") != std::string::npos);
  const auto fill = runCli("bench ipc --fill sometimes", dir);
  CHECK(fill.exit_code != 0);
  CHECK(fill.err.find("--fill: sometimes not in {first-use,every}") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists("/dev/shm/iceoryx_mgmt"));
  std::filesystem::remove_all(dir);
}
