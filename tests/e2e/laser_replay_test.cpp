// End to end: apps/profiles/carmen_replay.yaml and urg_replay.yaml on the real logs in
// ../shared/data (player -> grid mapper + trajectory writer -> files), read back what they wrote.
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <filesystem>

#include "../shared_data.hpp"
#include "run_profile.hpp"

using namespace tessera;
namespace fs = std::filesystem;
using Catch::Matchers::Contains;
using test::summaryOf;

TEST_CASE("carmen_replay maps intel.clf with its raw odometry", "[e2e][players]") {
  TESSERA_SHARED_DATA(log, "intel-lab-mrpt/intel.clf.gz");
  const fs::path out = tessera::test::scratchDir("carmen_replay");
  const RunReport report = test::runProfile("carmen_replay", out, {"player.path=" + log.string()});
  CHECK(report.stop_reason == "all inputs finished");
  for (const char* f : {"map.pgm", "map.yaml", "map.png", "odometry.tum"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  const auto odom = tessera::mapping::readTum(out / "odometry.tum");
  REQUIRE(odom.size() == 2726);
  CHECK(odom.front().stamp_ns == 976052856'338882000);  // the log's absolute time
  CHECK(odom.back().stamp_ns == 976055550'147778000);
  CHECK(odom.back().planar().x == Approx(-50.795746));
  const Summary& player = summaryOf(report, "player");
  CHECK(std::get<std::int64_t>(player.at("scans_published")) == 2726);
  CHECK(std::get<std::int64_t>(player.at("lines_skipped")) == 0);
  const Summary& mapper = summaryOf(report, "mapper");
  CHECK(std::get<std::int64_t>(mapper.at("scans_inserted")) == 2726);
  const auto map = tessera::mapping::loadMap(out / "map.yaml");
  CHECK(map.width > 500);
}

TEST_CASE("urg_replay maps MinesParisTech exp2 with wheel odometry", "[e2e][players]") {
  TESSERA_SHARED_DATA(log, "mines-paristech-urg04lx-odometry/exp2.dat.gz");
  const fs::path out = tessera::test::scratchDir("urg_replay");
  const RunReport report = test::runProfile("urg_replay", out, {"player.path=" + log.string()});
  CHECK(report.stop_reason == "all inputs finished");
  for (const char* f : {"map.pgm", "map.yaml", "map.png", "odometry.tum"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  const auto odom = tessera::mapping::readTum(out / "odometry.tum");
  REQUIRE(odom.size() == 641);
  CHECK(odom.front().stamp_ns == 361'431'443'000);
  const Summary& player = summaryOf(report, "player");
  CHECK(std::get<std::int64_t>(player.at("scans_published")) == 641);
  CHECK(std::get<std::int64_t>(summaryOf(report, "mapper").at("scans_inserted")) == 641);
}

TEST_CASE("replay profiles refuse to start without a log path", "[e2e][players]") {
  for (const char* name : {"carmen_replay", "urg_replay"}) {
    INFO(name);
    try {
      test::runProfile(name, tessera::test::scratchDir("replay_nopath"));
      FAIL("ran without a path");
    } catch (const ConfigError& e) {
      CHECK_THAT(e.what(), Contains("option 'path': is required"));
    }
  }
}
