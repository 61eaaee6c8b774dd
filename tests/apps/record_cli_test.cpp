// tessera record / tessera replay end to end: record the simulated mapping run's scans and
// ground-truth poses, replay them into the same profile (the simulator is replaced by the
// recording) and get the identical map; damaged files replay their intact part and say so.
#include "cli_run.hpp"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>

using namespace tessera;
using tessera::test::fileText;
using tessera::test::runCli;
namespace fs = std::filesystem;

TEST_CASE("tessera record then replay reproduces the sim_mapping map byte for byte",
          "[recording][e2e]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_record_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path rec = dir / "sim.trec";

  const auto record = runCli("record sim_mapping --topics scan,ground_truth --block-kib 64 --out " +
                                 rec.string() + " --dir " + (dir / "live").string() +
                                 " --set max_duration_s=40 --quiet --threads 2",
                             dir);
  INFO(record.err);
  REQUIRE(record.exit_code == 0);
  CHECK_THAT(record.err, Catch::Contains("recorded ") && Catch::Contains("MB/s"));
  REQUIRE(fs::exists(rec));

  const auto info = runCli("replay " + rec.string() + " --info", dir);
  INFO(info.out);
  CHECK(info.exit_code == 0);
  CHECK_THAT(info.out, Catch::Contains("scan") && Catch::Contains("LaserScan") &&
                           Catch::Contains("ground_truth") && Catch::Contains("indexed") &&
                           Catch::Contains("no damage found"));

  const auto replay = runCli("replay " + rec.string() + " --profile sim_mapping --out " +
                                 (dir / "replay").string() + " --quiet --threads 2",
                             dir);
  INFO(replay.err);
  REQUIRE(replay.exit_code == 0);
  CHECK_THAT(replay.err, Catch::Contains("not running 'sim'") &&
                             Catch::Contains("not running 'odometry_writer'"));
  const std::string live_map = fileText(dir / "live" / "map.pgm");
  REQUIRE(live_map.size() > 1000);
  CHECK(fileText(dir / "replay" / "map.pgm") == live_map);
  CHECK(fileText(dir / "replay" / "ground_truth.tum") ==
        fileText(dir / "live" / "ground_truth.tum"));

  {  // a truncated recording replays its intact prefix and reports the loss
    const auto bytes = fileText(rec);
    const fs::path cut = dir / "cut.trec";
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
    const auto cut_info = runCli("replay " + cut.string() + " --info", dir);
    INFO(cut_info.out);
    CHECK(cut_info.exit_code == 3);
    CHECK_THAT(cut_info.out, Catch::Contains("no index") && Catch::Contains("DAMAGED") &&
                                 Catch::Contains("truncated"));
    const auto cut_replay = runCli("replay " + cut.string() + " --profile sim_mapping --out " +
                                       (dir / "cut").string() + " --quiet --threads 2",
                                   dir);
    INFO(cut_replay.err);
    CHECK(cut_replay.exit_code == 3);
    CHECK_THAT(cut_replay.err,
               Catch::Contains("DAMAGED recording") && Catch::Contains("messages lost"));
    CHECK(fs::exists(dir / "cut" / "map.pgm"));
  }
  {  // a file that is not a recording is a clear error
    const auto bad = runCli("replay " + (dir / "live" / "map.yaml").string() + " --info", dir);
    CHECK(bad.exit_code == 1);
    CHECK_THAT(bad.err, Catch::Contains("map.yaml") && Catch::Contains("not a Tessera recording"));
  }
}
