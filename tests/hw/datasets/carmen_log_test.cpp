#include <tessera/datasets/carmen_log.hpp>

#include <zlib.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "../../shared_data.hpp"
#include "mutate.hpp"

namespace fs = std::filesystem;
using namespace tessera::datasets;
using namespace tessera::io;
using Catch::Matchers::Contains;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// "FLASER n r... x y theta ox oy otheta ts host logger_ts" with the given readings.
std::string flaser(const std::vector<std::string>& ranges,
                   const std::string& tail = "1 2 0.5 1.5 2.5 0.25 100.5 host 0.5") {
  std::string s = "FLASER " + std::to_string(ranges.size());
  for (const auto& r : ranges) s += " " + r;
  return s + " " + tail + "\n";
}

std::string flaserOfSize(int n, const std::string& value = "1.0") {
  return flaser(std::vector<std::string>(static_cast<std::size_t>(n), value));
}

const CarmenLaser& laserAt(const CarmenLog& log, std::size_t i) {
  return std::get<CarmenLaser>(log.records.at(i));
}

std::size_t countLasers(const CarmenLog& log, const std::string& message) {
  std::size_t n = 0;
  for (const auto& r : log.records)
    if (const auto* l = std::get_if<CarmenLaser>(&r); l && l->message == message) ++n;
  return n;
}

std::size_t countOdom(const CarmenLog& log) {
  std::size_t n = 0;
  for (const auto& r : log.records) n += std::holds_alternative<CarmenOdometry>(r) ? 1 : 0;
  return n;
}

std::size_t countNoReturn(const CarmenLog& log) {
  std::size_t n = 0;
  for (const auto& r : log.records)
    if (const auto* l = std::get_if<CarmenLaser>(&r))
      for (float v : l->ranges) n += std::isinf(v) && v > 0 ? 1 : 0;
  return n;
}

// Expects parseCarmenLog(text) to throw a DatasetError at `line` whose message contains `what`.
void requireError(const std::string& text, std::size_t line, const std::string& what,
                  const CarmenOptions& options = {}) {
  try {
    parseCarmenLog("test.log", text, options);
    FAIL("no error for:\n" << text.substr(0, 300));
  } catch (const DatasetError& e) {
    INFO(e.what());
    CHECK(e.line() == line);
    CHECK_THAT(e.what(), Contains(what));
    CHECK_THAT(e.what(), Contains("test.log:" + std::to_string(line) + ":"));
  }
}

std::string firstLines(const fs::path& path, std::size_t n) {
  TextReader reader(path);
  std::string text, line;
  for (std::size_t i = 0; i < n && reader.next(line); ++i) text += line + "\n";
  return text;
}

}  // namespace

TEST_CASE("CARMEN reader reads intel.clf: 2726 FLASER with raw odometry", "[datasets][carmen]") {
  TESSERA_SHARED_DATA(path, "intel-lab-mrpt/intel.clf.gz");
  const CarmenLog log = readCarmenLog(path);
  CHECK(log.records.size() == 2726);
  CHECK(countLasers(log, "FLASER") == 2726);
  CHECK(countOdom(log) == 0);
  CHECK(log.report.records == 2726);
  CHECK(log.report.skipped == 0);
  CHECK(log.report.lines == 2726);
  // Every reading of 81.83 m (the log's no-return value) and only those became +inf.
  CHECK(countNoReturn(log) == 13586);

  const CarmenLaser& first = laserAt(log, 0);
  CHECK(first.ranges.size() == 180);
  CHECK(first.ranges[0] == Approx(1.07f));
  CHECK(first.angle_min == Approx(-90 * kDeg));
  CHECK(first.angle_increment == Approx(1 * kDeg));
  CHECK(first.timestamp == Approx(976052856.338882).epsilon(1e-15));
  CHECK(first.logger_timestamp == Approx(-1.001118));
  CHECK(first.has_pose);

  const CarmenLaser& last = laserAt(log, 2725);
  CHECK(last.robot_pose.x == Approx(-50.795746));
  CHECK(last.robot_pose.y == Approx(-35.949980));
  CHECK(last.robot_pose.theta == Approx(2.540560));
  CHECK(last.timestamp == Approx(976055550.147778).epsilon(1e-15));

  // The raw odometry the relations evaluation uses: one pose per scan, times non-decreasing (a few
  // rebuilt times repeat).
  const auto odom = carmenOdometry(log);
  REQUIRE(odom.size() == 2726);
  CHECK(odom.back().pose.x == Approx(-50.795746));
  CHECK(odom.back().timestamp == last.timestamp);
  for (std::size_t i = 1; i < odom.size(); ++i) REQUIRE(odom[i].timestamp >= odom[i - 1].timestamp);
}

TEST_CASE("CARMEN reader reads the GMapping-corrected Intel log and counts skipped lines",
          "[datasets][carmen]") {
  TESSERA_SHARED_DATA(path, "intel-lab-carmen-gfs/intel-corrected.log.gz");
  const CarmenLog log = readCarmenLog(path);
  CHECK(countLasers(log, "FLASER") == 910);
  // 14541 ODOM lines, of which 863 are GMapping's time-0 echoes of the corrected laser pose.
  CHECK(countOdom(log) == 14541 - 863);
  CHECK(log.records.size() == 910 + 14541 - 863);
  CHECK(log.report.skipped == 912 + 863);
  CHECK(log.report.skipped_by_reason.at("NEFF") == 910);
  CHECK(log.report.skipped_by_reason.at("PARAM") == 2);
  CHECK(log.report.skipped_by_reason.at("ODOM stamped 0 (GFS pose echo)") == 863);
  CarmenOptions keep;
  keep.skip_zero_time_odom = false;
  CHECK(countOdom(readCarmenLog(path, keep)) == 14541);
  CHECK(log.report.lines == 910 + 14541 + 912 + 2);  // + 2 comment lines
  CHECK(countNoReturn(log) == 4172);
  for (const auto& r : log.records)
    if (const auto* l = std::get_if<CarmenLaser>(&r)) REQUIRE(l->ranges.size() == 180);

  // With ODOM lines present, the odometry comes from them, not from the corrected laser poses.
  const auto odom = carmenOdometry(log);
  CHECK(odom.size() == 14541 - 863);
  CHECK(odom.front().timestamp == Approx(0.000246));
  for (const auto& o : odom) REQUIRE(o.timestamp > 1e-4);
}

TEST_CASE("CARMEN streaming reader reports progress and matches the bulk reader",
          "[datasets][carmen]") {
  std::string text = "# comment\n\nPARAM a b\n";
  for (int i = 0; i < 50; ++i) text += flaserOfSize(4) + "ODOM 1 2 3 0.1 0.2 0 5.5 h 5.5\n";
  CarmenReader reader(TextReader::fromString("mem.log", text));
  CarmenRecord record;
  std::size_t n = 0;
  double last_progress = 0;
  while (reader.next(record)) {
    ++n;
    CHECK(reader.progress() >= last_progress);
    last_progress = reader.progress();
  }
  CHECK(n == 100);
  CHECK(last_progress == Approx(1.0));
  CHECK(reader.report().records == 100);
  CHECK(reader.report().skipped_by_reason.at("PARAM") == 1);
  CHECK(reader.report().lines == 103);
}

TEST_CASE("CARMEN FLASER beam angles: even counts split 180 deg, odd counts include both ends",
          "[datasets][carmen]") {
  const auto angles = [](int n) {
    const auto l = laserAt(parseCarmenLog("a.log", flaserOfSize(n)), 0);
    REQUIRE(l.ranges.size() == static_cast<std::size_t>(n));
    return std::pair<double, double>(l.angle_min, l.angle_increment);
  };
  CHECK(angles(180).first == Approx(-90 * kDeg));
  CHECK(angles(180).second == Approx(1 * kDeg));
  CHECK(angles(181).second == Approx(1 * kDeg));
  CHECK(angles(360).second == Approx(0.5 * kDeg));
  CHECK(angles(361).second == Approx(0.5 * kDeg));
  CHECK(angles(361).first + 360 * angles(361).second == Approx(90 * kDeg));
  CHECK(angles(1).second == 0);
}

TEST_CASE("CARMEN max-range readings become +inf (no return)", "[datasets][carmen]") {
  const std::string text = flaser({"1.5", "81.83", "80.0", "79.99", "0"});
  const auto l = laserAt(parseCarmenLog("a.log", text), 0);
  CHECK(l.ranges[0] == 1.5f);
  CHECK(std::isinf(l.ranges[1]));
  CHECK(l.ranges[1] > 0);
  CHECK(std::isinf(l.ranges[2]));
  CHECK(l.ranges[3] == 79.99f);
  CHECK(l.ranges[4] == 0.0f);
  CHECK(l.max_range == 80.0f);

  CarmenOptions keep;
  keep.flaser_max_range = 0;
  const auto k = laserAt(parseCarmenLog("a.log", text, keep), 0);
  CHECK(k.ranges[1] == 81.83f);

  CarmenOptions close;
  close.flaser_max_range = 50;
  CHECK(std::isinf(laserAt(parseCarmenLog("a.log", text, close), 0).ranges[3]));

  // ROBOTLASER1 / RAWLASER use their own max_range field (8 m here).
  const std::string raw = "RAWLASER1 0 -2.0 4.0 0.5 8.0 0.01 0 3 7.99 8.0 9.5 0 12.5 h 12.6\n";
  const auto r = laserAt(parseCarmenLog("a.log", raw), 0);
  CHECK(r.ranges[0] == 7.99f);
  CHECK(std::isinf(r.ranges[1]));
  CHECK(std::isinf(r.ranges[2]));
  CHECK(r.max_range == 8.0f);
  CarmenOptions override;
  override.max_range_override = 20;
  CHECK(laserAt(parseCarmenLog("a.log", raw, override), 0).ranges[2] == 9.5f);
}

TEST_CASE("CARMEN ROBOTLASER1, RAWLASER, RLASER and ODOM fields land where they belong",
          "[datasets][carmen]") {
  const std::string text =
      "ROBOTLASER1 0 -1.5 3.0 0.75 30.0 0.01 1 5 1 2 3 4 5 2 0.5 0.6 "
      "10 11 0.1 9 8 0.2 0.3 0.4 0.5 0.6 0.7 1001.25 host 1001.5\n"
      "RAWLASER3 0 -1.0 2.0 1.0 30.0 0.01 0 3 1 2 3 0 1002 host 1002.5\n"
      "RLASER 2 4 5 1 2 3 4 5 6 1003 host 1003.5\n"
      "ODOM 1.5 -2.5 0.75 0.3 -0.1 0.05 1004.25 host 1004.5\n";
  const CarmenLog log = parseCarmenLog("a.log", text);
  REQUIRE(log.records.size() == 4);

  const auto& rl = laserAt(log, 0);
  CHECK(rl.message == "ROBOTLASER1");
  CHECK(rl.angle_min == -1.5f);
  CHECK(rl.angle_increment == 0.75f);
  CHECK(rl.max_range == 30.0f);
  CHECK(rl.ranges == std::vector<float>{1, 2, 3, 4, 5});
  CHECK(rl.remissions == std::vector<float>{0.5f, 0.6f});
  CHECK(rl.has_pose);
  CHECK(rl.laser_pose.x == 10);
  CHECK(rl.laser_pose.theta == 0.1);
  CHECK(rl.robot_pose.x == 9);
  CHECK(rl.robot_pose.theta == 0.2);
  CHECK(rl.timestamp == 1001.25);
  CHECK(rl.logger_timestamp == 1001.5);

  const auto& raw = laserAt(log, 1);
  CHECK(raw.message == "RAWLASER3");
  CHECK_FALSE(raw.has_pose);
  CHECK(raw.ranges.size() == 3);
  CHECK(raw.timestamp == 1002);

  const auto& rear = laserAt(log, 2);
  CHECK(rear.message == "RLASER");
  CHECK(rear.laser_pose.y == 2);
  CHECK(rear.robot_pose.theta == 6);
  CHECK(rear.angle_increment == Approx(90 * kDeg));

  const auto& odom = std::get<CarmenOdometry>(log.records.at(3));
  CHECK(odom.pose.x == 1.5);
  CHECK(odom.pose.y == -2.5);
  CHECK(odom.pose.theta == 0.75);
  CHECK(odom.tv == 0.3);
  CHECK(odom.rv == -0.1);
  CHECK(odom.accel == 0.05);
  CHECK(odom.timestamp == 1004.25);
}

TEST_CASE("CARMEN time-0 ODOM echoes of GFS logs are skipped, a log starting at 0 is not",
          "[datasets][carmen]") {
  const std::string text = "ODOM 0 0 0 0 0 0 0 h 0\nODOM 1 0 0 0 0 0 2.5 h 2.5\n" +
                           flaserOfSize(2) + "ODOM 1 2 0.5 0 0 0 0 pippo 0\n" +
                           "ODOM 1 2 0.5 0 0 0 1.08499e-42 pippo 1.08499e-42\n" +
                           "ODOM 1.1 0 0 0 0 0 101 h 101\n";
  const CarmenLog log = parseCarmenLog("a.log", text);
  CHECK(countOdom(log) == 3);
  CHECK(log.report.skipped_by_reason.at("ODOM stamped 0 (GFS pose echo)") == 2);
  CHECK(std::get<CarmenOdometry>(log.records.at(0)).timestamp == 0);
}

TEST_CASE("CARMEN unknown messages, comments and blanks are skipped and counted by name",
          "[datasets][carmen]") {
  const std::string text =
      "# header\n\n   \nPARAM robot_x 1 host 0\nNEFF 15\nSYNC a b\nTRUEPOS 1 2 3 4 5 6 7 h 8\n"
      "GPSNMEA whatever\n" +
      flaserOfSize(3) + "NEFF 14\n";
  const CarmenLog log = parseCarmenLog("a.log", text);
  CHECK(log.records.size() == 1);
  CHECK(log.report.lines == 10);
  CHECK(log.report.skipped == 6);
  CHECK(log.report.skipped_by_reason.at("NEFF") == 2);
  CHECK(log.report.skipped_by_reason.at("TRUEPOS") == 1);
  CHECK(log.report.skipped_by_reason.at("GPSNMEA") == 1);
  REQUIRE_FALSE(log.report.first_skips.empty());
  CHECK(log.report.first_skips[0] == "a.log:4: PARAM");
}

TEST_CASE("CARMEN malformed lines give an error naming line, field and value",
          "[datasets][carmen]") {
  const std::string good = flaserOfSize(3);
  SECTION("too few fields") {
    requireError(good + "ODOM 1 2 3 4 5 6 7 h\n", 2,
                 "field 10 (logger_timestamp): missing, the line ends after 9 fields");
  }
  SECTION("count larger than the line") {
    requireError(good + "FLASER 5 1 2 1 2 0.5 1.5 2.5 0.25 100.5 host 0.5\n", 2,
                 "5 values announced but the line has only 11 fields");
  }
  SECTION("extra fields") {
    requireError(flaserOfSize(2) + good + "ODOM 1 2 3 4 5 6 7 h 8 9\n", 3, "1 extra fields");
  }
  SECTION("huge count is rejected before allocating") {
    requireError("FLASER 1000000000000 1 2 3\n", 1, "exceeds the limit of 100000");
    requireError("FLASER 99999999999999999999999 1 2\n", 1, "integer out of range");
    requireError("FLASER -3 1 2\n", 1, "expected a count >= 0");
  }
  SECTION("NaN and inf") {
    requireError(flaser({"1", "nan", "2"}), 1,
                 "field 4 (range): expected a finite number, got 'nan'");
    requireError(flaser({"1", "2"}, "1 2 inf 1 2 3 100 host 1"), 1, "field 7 (theta)");
    requireError("ODOM 1 2 3 4 5 6 -inf h 8\n", 1, "(ipc_timestamp): expected a finite number");
    requireError(flaser({"1e999"}), 1, "number out of range");
  }
  SECTION("negative range") {
    requireError(flaser({"1", "-0.5"}), 1, "field 4 (range): expected a range >= 0");
  }
  SECTION("not a number") {
    requireError(flaser({"1", "x2"}), 1, "expected a number, got 'x2'");
  }
  SECTION("garbage line") {
    requireError(good + "\x01\x02\xff garbage\n", 2, "not a CARMEN message");
    requireError(good + "3.5 4.5\n", 2, "not a CARMEN message");
  }
  SECTION("ROBOTLASER1 remission count beyond the line") {
    requireError(
        "ROBOTLASER1 0 -1.5 3.0 0.75 30.0 0.01 1 2 1 2 99 0.5 10 11 0.1 9 8 0.2 0.3 0.4 0.5 0.6 "
        "0.7 1001.25 host 1001.5\n",
        1, "field 12 (num_remissions): 99 values announced");
  }
  SECTION("negative max_range") {
    requireError("RAWLASER1 0 -2.0 4.0 0.5 -8.0 0.01 0 1 7 0 12.5 h 12.6\n", 1, "(max_range)");
  }
}

TEST_CASE("CARMEN skip_malformed turns bad lines into counted skips", "[datasets][carmen]") {
  CarmenOptions lenient;
  lenient.skip_malformed = true;
  const std::string text = flaserOfSize(3) + flaser({"nan"}) + "FLASER 99999999 1\n" +
                           "\x01garbage\n" + "ODOM 1 2 3\n" + flaserOfSize(2);
  const CarmenLog log = parseCarmenLog("a.log", text, lenient);
  CHECK(log.records.size() == 2);
  CHECK(log.report.skipped == 4);
  CHECK(log.report.skipped_by_reason.at("malformed FLASER") == 2);
  CHECK(log.report.skipped_by_reason.at("malformed ODOM") == 1);
  CHECK(log.report.skipped_by_reason.at("garbage") == 1);
  CHECK(log.report.first_skips.at(0) == "a.log:2: malformed FLASER");
}

TEST_CASE("CARMEN reader reports a truncated gzip log", "[datasets][carmen]") {
  const auto dir = tessera::test::scratchDir("carmen_trunc");
  std::string text;
  for (int i = 0; i < 3000; ++i) text += flaserOfSize(180, std::to_string(1 + i % 7));
  {
    gzFile f = gzopen((dir / "full.log.gz").c_str(), "wb");
    REQUIRE(f != nullptr);
    gzwrite(f, text.data(), static_cast<unsigned>(text.size()));
    gzclose(f);
  }
  std::ifstream in(dir / "full.log.gz", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  std::ofstream(dir / "cut.log.gz", std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
  CHECK(readCarmenLog(dir / "full.log.gz").records.size() == 3000);
  try {
    readCarmenLog(dir / "cut.log.gz");
    FAIL("truncated gzip read without error");
  } catch (const DatasetError& e) {
    CHECK_THAT(e.what(), Contains("cut.log.gz"));
    CHECK(e.line() > 0);
  }
  CHECK_THROWS_AS(readCarmenLog(dir / "absent.log"), DatasetError);
}

TEST_CASE("CARMEN parser survives random mutations of the real logs", "[datasets][carmen][fuzz]") {
  std::vector<std::string> sources;
  for (const char* rel :
       {"intel-lab-mrpt/intel.clf.gz", "intel-lab-carmen-gfs/intel-corrected.log.gz"}) {
    const fs::path path = tessera::test::sharedDataDir() / rel;
    if (fs::exists(path)) {
      sources.push_back(firstLines(path, 200));
    } else if (tessera::test::underCi()) {
      FAIL("dataset " << path.string() << " is absent and CI=true");
    }
  }
  // Without the datasets, still fuzz a synthetic log with every message type.
  sources.push_back("# c\nPARAM a 1 h 0\n" + flaserOfSize(10) +
                    "ROBOTLASER1 0 -1.5 3.0 0.75 30.0 0.01 1 5 1 2 3 4 5 2 0.5 0.6 "
                    "10 11 0.1 9 8 0.2 0.3 0.4 0.5 0.6 0.7 1001.25 host 1001.5\n"
                    "RAWLASER3 0 -1.0 2.0 1.0 30.0 0.01 0 3 1 2 3 0 1002 host 1002.5\n"
                    "ODOM 1.5 -2.5 0.75 0.3 -0.1 0.05 1004.25 host 1004.5\nNEFF 3\n");
  tessera::test::Mutator mutator(20240611);
  std::size_t parsed = 0, rejected = 0;
  for (const auto& source : sources) {
    // Mutate windows of up to 20 lines of the source so that each case stays cheap.
    std::vector<std::size_t> starts{0};
    for (std::size_t i = 0; i < source.size(); ++i)
      if (source[i] == '\n' && i + 1 < source.size()) starts.push_back(i + 1);
    std::mt19937 pick(7);
    for (int iter = 0; iter < 2500; ++iter) {
      const std::size_t first = pick() % starts.size();
      const std::size_t last = std::min(starts.size(), first + 1 + pick() % 20);
      const std::size_t end = last < starts.size() ? starts[last] : source.size();
      const std::string window = source.substr(starts[first], end - starts[first]);
      const std::string text = mutator.mutate(window);
      for (bool lenient : {false, true}) {
        CarmenOptions options;
        options.skip_malformed = lenient;
        try {
          const CarmenLog log = parseCarmenLog("fuzz.log", text, options);
          ++parsed;
          for (const auto& r : log.records)
            if (const auto* l = std::get_if<CarmenLaser>(&r)) {
              REQUIRE(std::isfinite(l->timestamp));
              for (float v : l->ranges) REQUIRE((std::isfinite(v) || v > 0));
            }
        } catch (const DatasetError&) {
          ++rejected;
          REQUIRE_FALSE(lenient);  // lenient mode skips every malformed line of plain text
        }
      }
    }
  }
  INFO("parsed " << parsed << ", rejected " << rejected);
  CHECK(parsed > 0);
  CHECK(rejected > 0);
}
