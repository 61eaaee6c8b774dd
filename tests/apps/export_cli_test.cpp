// `tessera replay FILE --export OUT.mcap` end to end: a recording of scans, maps, odometry and a
// status topic (plus a topic of a type this build does not know) exported, then read back by
// the ecosystem's own MCAP reader (@mcap/core, tests/js/mcap_check.mjs) and compared with what
// was recorded. Damaged recordings export their intact part and say so.
#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/recording.hpp>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "cli_run.hpp"

using namespace tessera;
using tessera::test::runCli;
namespace fs = std::filesystem;

namespace {

constexpr int kScans = 40;

fs::path writeRecording(const fs::path& dir) {
  const fs::path rec = dir / "run.trec";
  std::vector<RecordingTopic> topics{
      {"scan", messageTypeOf<msg::LaserScan>().id, "LaserScan"},
      {"map", messageTypeOf<msg::OccupancyGrid>().id, "OccupancyGrid"},
      {"odom", messageTypeOf<msg::Odometry>().id, "Odometry"},
      {"nav_status", messageTypeOf<msg::NavStatus>().id, "NavStatus"},
      {"mystery", 0x1234, "FromTheFuture"}};
  RecordingWriterOptions o;
  o.block_bytes = 4096;  // many blocks, so a cut file keeps most of them
  RecordingWriter w(rec.string(), topics, o);
  for (int i = 0; i < kScans; ++i) {
    const Nanos t = 1'000'000'000 + static_cast<Nanos>(i) * 100'000'000;
    Loan<msg::LaserScan> scan;
    setHeader(scan->initHeader(), t, "laser", static_cast<std::uint64_t>(i));
    scan->setAngleMin(-1.5f);
    scan->setAngleIncrement(0.01f);
    auto r = scan->initRanges(301);
    for (unsigned k = 0; k < 301; ++k) r.set(k, 1.0f + 0.01f * static_cast<float>(i));
    w.append(0, t, *std::move(scan).seal());
    Loan<msg::Odometry> odom;
    setHeader(odom->initHeader(), t, "odom", static_cast<std::uint64_t>(i));
    odom->initPose().setX(0.1 * i);
    w.append(2, t, *std::move(odom).seal());
    if (i % 10 == 0) {
      Loan<msg::OccupancyGrid> map;
      setHeader(map->initHeader(), t, "map", 0);
      map->setResolution(0.05f);
      map->setWidth(20);
      map->setHeight(10);
      map->initCells(200);
      w.append(1, t, *std::move(map).seal());
      Loan<msg::NavStatus> status;
      setHeader(status->initHeader(), t, "map", 0);
      status->setReason("step " + std::to_string(i));
      w.append(3, t, *std::move(status).seal());
      Loan<msg::Blob> future;  // any payload: its topic's type is what the exporter cannot know
      w.append(4, t, *std::move(future).seal());
    }
  }
  w.close();
  return rec;
}

/// @mcap/core's reading of `mcap` (tests/js/mcap_check.mjs), or nullopt with the reason when
/// Node.js or the npm packages are missing (scripts/test.sh installs them).
std::optional<nlohmann::json> readWithMcapCore(const fs::path& mcap, const fs::path& dir,
                                               std::string* why) {
  const fs::path js = fs::path(TESSERA_SOURCE_DIR) / "tests" / "js";
  if (!fs::exists(js / "node_modules" / "@mcap" / "core")) {
    *why = "no " + (js / "node_modules").string() + " (run: cd tests/js && npm ci)";
    return std::nullopt;
  }
  if (std::system("node --version > /dev/null 2>&1") != 0) {
    *why = "no node on PATH";
    return std::nullopt;
  }
  const fs::path out = dir / "mcap_check.json";
  const std::string cmd = "node " + (js / "mcap_check.mjs").string() + " " + mcap.string() + " > " +
                          out.string() + " 2> " + (dir / "mcap_check.err").string();
  const int rc = std::system(cmd.c_str());
  std::ifstream in(out), err(dir / "mcap_check.err");
  const std::string err_text{std::istreambuf_iterator<char>(err), {}};
  INFO(err_text);
  REQUIRE(rc == 0);
  return nlohmann::json::parse(in);
}

void skipOrFail(const std::string& why) {
  const char* ci = std::getenv("CI");
  if (ci && std::string(ci) == "true") FAIL("the MCAP check needs Node.js packages: " << why);
  WARN("SKIPPED: npm " << why);
}

}  // namespace

TEST_CASE("replay --export writes an MCAP file Foxglove's reader opens", "[export][e2e]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_export_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path rec = writeRecording(dir);
  const fs::path mcap = dir / "run.mcap";
  const bool compress = GENERATE(true, false);
  const auto run = runCli(
      "replay " + rec.string() + " --export " + mcap.string() + (compress ? "" : " --uncompressed"),
      dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.err, Catch::Contains("exported " + std::to_string(2 * kScans + 8) +
                                      " messages on 4 topics (and " + std::to_string(2 * kScans) +
                                      " frame transforms on 'tf')"));
  CHECK_THAT(run.err, Catch::Contains("'mystery'") && Catch::Contains("FromTheFuture") &&
                          Catch::Contains("4 messages of unknown types not exported"));

  std::string why;
  const auto j = readWithMcapCore(mcap, dir, &why);
  if (!j) return skipOrFail(why);
  INFO(j->dump(2).substr(0, 2000));
  CHECK((*j)["ok"] == true);
  CHECK((*j)["ordered"] == true);
  // The recorded messages, plus a frame transform per scan (base_link -> laser) and per
  // odometry message (odom -> base_link) on "tf".
  CHECK((*j)["message_count"] == 2 * kScans + 8 + 2 * kScans);
  CHECK((*j)["library"] == "tessera");
  const auto& t = (*j)["topics"];
  CHECK(t.size() == 5);
  CHECK(t["tf"]["schema"] == "foxglove.FrameTransform");
  CHECK(t["tf"]["indexed"] == 2 * kScans);
  CHECK(t["tf"]["first"]["parent_frame_id"] == "base_link");
  CHECK(t["tf"]["first"]["child_frame_id"] == "laser");
  CHECK(t["scan"]["schema"] == "foxglove.LaserScan");
  CHECK(t["scan"]["schema_encoding"] == "jsonschema");
  CHECK(t["scan"]["message_encoding"] == "json");
  CHECK(t["scan"]["indexed"] == kScans);
  CHECK(t["scan"]["streamed"] == kScans);
  CHECK(t["scan"]["first"]["ranges"].size() == 301);
  CHECK(t["scan"]["first"]["ranges"][0].get<double>() == Approx(1.0));
  CHECK(t["scan"]["first"]["timestamp"]["sec"] == 1);
  CHECK(t["scan"]["last_time_ns"] ==
        std::to_string(1'000'000'000LL + (kScans - 1) * 100'000'000LL));
  CHECK(t["map"]["schema"] == "foxglove.Grid");
  CHECK(t["map"]["indexed"] == 4);
  CHECK(t["map"]["first"]["column_count"] == 20);
  CHECK(t["odom"]["schema"] == "foxglove.PoseInFrame");
  CHECK(t["odom"]["metadata"]["tessera_type"] == "Odometry");
  CHECK(t["nav_status"]["schema"] == "");
  CHECK(t["nav_status"]["first"]["reason"] == "step 0");
}

TEST_CASE("replay --export of a cut recording exports the intact part and says so",
          "[export][e2e]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_export_cli_cut";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path rec = writeRecording(dir);
  fs::resize_file(rec, fs::file_size(rec) * 2 / 3);
  const fs::path mcap = dir / "cut.mcap";
  const auto run = runCli("replay " + rec.string() + " --export " + mcap.string(), dir);
  INFO(run.err);
  CHECK(run.exit_code == 3);
  CHECK_THAT(run.err, Catch::Contains("DAMAGED"));
  std::string why;
  const auto j = readWithMcapCore(mcap, dir, &why);
  if (!j) return skipOrFail(why);
  CHECK((*j)["ok"] == true);
  const auto scans = (*j)["topics"]["scan"]["indexed"].get<int>();
  CHECK(scans > kScans / 3);
  CHECK(scans < kScans);
}

TEST_CASE("replay --export names what it cannot do", "[export]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_export_cli_bad";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path rec = writeRecording(dir);
  const auto unwritable = runCli("replay " + rec.string() + " --export /nonexistent/x.mcap", dir);
  CHECK(unwritable.exit_code != 0);
  CHECK_THAT(unwritable.err, Catch::Contains("/nonexistent/x.mcap"));
  const auto missing = runCli(
      "replay " + (dir / "none.trec").string() + " --export " + (dir / "y.mcap").string(), dir);
  CHECK(missing.exit_code != 0);
  CHECK_THAT(missing.err, Catch::Contains("none.trec"));
  const auto lone = runCli("replay " + rec.string() + " --uncompressed", dir);
  CHECK(lone.exit_code != 0);
  CHECK_THAT(lone.err, Catch::Contains("--export"));
}

TEST_CASE("record --out F.mcap records a run straight into MCAP", "[export][e2e]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_record_mcap";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path mcap = dir / "run.mcap";
  const auto run = runCli("record sim_mapping --topics scan,map,ground_truth --out " +
                              mcap.string() + " --dir " + (dir / "out").string() +
                              " --set max_duration_s=20 --quiet --block-kib 64",
                          dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.err, Catch::Contains("chunks to " + mcap.string() + " (MCAP"));
  std::string why;
  const auto j = readWithMcapCore(mcap, dir, &why);
  if (!j) return skipOrFail(why);
  const auto& t = (*j)["topics"];
  CHECK((*j)["ok"] == true);
  CHECK((*j)["chunk_count"].get<int>() > 1);
  CHECK(t["scan"]["schema"] == "foxglove.LaserScan");
  CHECK(t["map"]["schema"] == "foxglove.Grid");
  CHECK(t["ground_truth"]["schema"] == "foxglove.PoseInFrame");
  CHECK(t["tf"]["indexed"] == 201);  // the laser's mount, with every scan
  // 20 s of the simulator: 10 Hz scans, 50 Hz ground truth (both from t = 0).
  CHECK(t["scan"]["indexed"] == 201);
  CHECK(t["ground_truth"]["indexed"] == 1001);
  CHECK(t["map"]["first"]["frame_id"] == "map");
}

TEST_CASE("mcap_recorder names a bad option", "[export]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_record_mcap_bad";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto none = runCli("record sim_mapping --topics scan --out " + (dir / "x.mcap").string() +
                               " --block-kib 0 --quiet",
                           dir);
  CHECK(none.exit_code != 0);
  CHECK_THAT(none.err, Catch::Contains("chunk_kib"));
  const auto unwritable =
      runCli("record sim_mapping --topics scan --out /nonexistent/x.mcap --quiet", dir);
  CHECK(unwritable.exit_code != 0);
  CHECK_THAT(unwritable.err, Catch::Contains("/nonexistent/x.mcap"));
}

TEST_CASE("replay --export refuses an empty or malformed recording, naming it", "[export]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_export_cli_malformed";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path empty = dir / "empty.trec", garbage = dir / "garbage.trec";
  std::ofstream(empty).close();
  std::ofstream(garbage) << "this is not a recording, just some text\n";
  for (const fs::path& bad : {empty, garbage}) {
    const fs::path out = dir / (bad.stem().string() + ".mcap");
    const auto run = runCli("replay " + bad.string() + " --export " + out.string(), dir);
    INFO(run.err);
    CHECK(run.exit_code != 0);
    CHECK_THAT(run.err, Catch::Contains(bad.string()));
    CHECK_FALSE(fs::exists(out));  // nothing half-written
  }
}
