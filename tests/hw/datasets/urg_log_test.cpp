#include <tessera/datasets/urg_log.hpp>

#include <cmath>
#include <numbers>
#include <random>

#include "../../shared_data.hpp"
#include "mutate.hpp"

namespace fs = std::filesystem;
using namespace tessera::datasets;
using namespace tessera::io;
using Catch::Matchers::Contains;

namespace {

// A line in the exp2.dat layout: timestamp, telemetry, encoders, 20 telemetry fields, ranges, 0.
std::string urgLine(std::int64_t t_us, std::int64_t left, std::int64_t right,
                    const std::vector<std::string>& ranges, std::size_t beams = 682) {
  std::string s =
      std::to_string(t_us) + " 14554 " + std::to_string(left) + " " + std::to_string(right);
  for (int i = 0; i < 20; ++i) s += i == 3 ? " 167.2" : " 0";
  for (std::size_t k = 0; k < beams; ++k) s += " " + (k < ranges.size() ? ranges[k] : "1000");
  return s + " 0\n";
}

void requireError(const std::string& text, std::size_t line, const std::string& what) {
  try {
    parseUrgLog("exp.dat", text);
    FAIL("no error");
  } catch (const DatasetError& e) {
    INFO(e.what());
    CHECK(e.line() == line);
    CHECK_THAT(e.what(), Contains(what));
    CHECK_THAT(e.what(), Contains("exp.dat:" + std::to_string(line) + ":"));
  }
}

}  // namespace

TEST_CASE("URG reader reads MinesParisTech exp2: 641 scans of 682 beams", "[datasets][urg]") {
  TESSERA_SHARED_DATA(path, "mines-paristech-urg04lx-odometry/exp2.dat.gz");
  const UrgLog log = readUrgLog(path);
  REQUIRE(log.scans.size() == 641);
  CHECK(log.report.skipped == 0);
  CHECK(log.report.lines == 641);
  const UrgScan& first = log.scans.front();
  CHECK(first.timestamp_us == 361431443);
  CHECK(first.left_ticks == 234835);
  CHECK(first.right_ticks == 231727);
  CHECK(first.angle_min == Approx(-120 * std::numbers::pi / 180));
  CHECK(first.angle_min + 681 * first.angle_increment == Approx(120 * std::numbers::pi / 180));
  CHECK(log.scans.back().timestamp - first.timestamp == Approx(63.162132));
  std::size_t no_return = 0, invalid = 0, valid = 0;
  float max_range = 0;
  for (const auto& s : log.scans) {
    REQUIRE(s.ranges.size() == 682);
    for (float r : s.ranges) {
      if (std::isnan(r)) {
        ++invalid;
      } else if (std::isinf(r)) {
        ++no_return;
      } else {
        ++valid;
        max_range = std::max(max_range, r);
      }
    }
  }
  CHECK(no_return == 241623);  // readings of 0
  CHECK(invalid == 10789);     // error codes 1..19
  CHECK(valid == 641 * 682 - 241623 - 10789);
  CHECK(max_range == Approx(5.580f));
  for (std::size_t i = 1; i < log.scans.size(); ++i)
    REQUIRE(log.scans[i].timestamp_us > log.scans[i - 1].timestamp_us);
}

TEST_CASE("URG wheel odometry of exp2 follows the differential-drive model", "[datasets][urg]") {
  TESSERA_SHARED_DATA(path, "mines-paristech-urg04lx-odometry/exp2.dat.gz");
  const UrgLog log = readUrgLog(path);
  const auto poses = urgOdometry(log.scans);
  REQUIRE(poses.size() == 641);
  double length = 0, turned = 0;
  for (std::size_t i = 1; i < poses.size(); ++i) {
    length += std::hypot(poses[i].x - poses[i - 1].x, poses[i].y - poses[i - 1].y);
    turned += std::abs(std::remainder(poses[i].theta - poses[i - 1].theta, 2 * std::numbers::pi));
  }
  // Figures from an independent re-computation of the same model (Python, midpoint heading).
  CHECK(length == Approx(44.50).margin(0.02));
  CHECK(turned * 180 / std::numbers::pi == Approx(1202.0).margin(0.5));
  CHECK(poses.back().x == Approx(-7.608).margin(0.002));
  CHECK(poses.back().y == Approx(1.712).margin(0.002));
  CHECK(poses.back().theta * 180 / std::numbers::pi == Approx(79.21).margin(0.01));
}

TEST_CASE("Differential drive: straight runs, turns in place and arcs", "[datasets][urg]") {
  DifferentialDriveModel m;
  m.wheel_radius = 0.1;
  m.half_axle = 0.25;
  m.ticks_per_revolution = 1000;
  const double rev = 2 * std::numbers::pi * 0.1;  // m per wheel revolution

  const auto straight = wheelIncrement(1000, 1000, m);
  CHECK(straight.distance == Approx(rev));
  CHECK(straight.rotation == 0);
  const auto spin = wheelIncrement(-500, 500, m);  // right forward: counter-clockwise
  CHECK(spin.distance == Approx(0).margin(1e-12));
  CHECK(spin.rotation == Approx(0.5 * rev / 0.25));

  tessera::Pose2 p{1, 2, std::numbers::pi / 2};
  p = advancePose(p, straight);
  CHECK(p.x == Approx(1).margin(1e-12));
  CHECK(p.y == Approx(2 + rev));
  // Quarter circle: the step goes along the chord's direction (midpoint heading, 45 deg).
  const double arc = std::numbers::pi / 2;
  const tessera::Pose2 q = advancePose(tessera::Pose2{}, DriveIncrement{arc, std::numbers::pi / 2});
  CHECK(q.theta == Approx(std::numbers::pi / 2));
  CHECK(std::hypot(q.x, q.y) == Approx(arc));
  CHECK(q.y / q.x == Approx(1.0));

  std::vector<UrgScan> scans(3);
  scans[1].left_ticks = scans[1].right_ticks = 1000;
  scans[2].left_ticks = 1000 - 500;
  scans[2].right_ticks = 1000 + 500;
  const auto poses = urgOdometry(scans, m, tessera::Pose2{5, 0, 0});
  REQUIRE(poses.size() == 3);
  CHECK(poses[0].x == 5);
  CHECK(poses[1].x == Approx(5 + rev));
  CHECK(poses[2].x == Approx(5 + rev));
  CHECK(poses[2].theta == Approx(std::remainder(rev * 2, 2 * std::numbers::pi)));
}

TEST_CASE("URG readings: 0 is no return, small values are error codes, mm become m",
          "[datasets][urg]") {
  const auto log = parseUrgLog("exp.dat", urgLine(1000000, 5, 7, {"0", "1", "19", "20", "1544"}));
  REQUIRE(log.scans.size() == 1);
  const auto& s = log.scans[0];
  CHECK(s.timestamp == 1.0);
  CHECK(s.left_ticks == 5);
  CHECK(s.right_ticks == 7);
  CHECK(std::isinf(s.ranges[0]));
  CHECK(s.ranges[0] > 0);
  CHECK(std::isnan(s.ranges[1]));
  CHECK(std::isnan(s.ranges[2]));
  CHECK(s.ranges[3] == 0.02f);
  CHECK(s.ranges[4] == 1.544f);
  CHECK(s.ranges[681] == 1.0f);

  UrgOptions strict_zero;
  strict_zero.zero_is_no_return = false;
  CHECK(
      std::isnan(parseUrgLog("exp.dat", urgLine(0, 0, 0, {"0"}), strict_zero).scans[0].ranges[0]));
  // Without the trailing ignored field the line is accepted as well.
  std::string no_tail = urgLine(0, 0, 0, {});
  no_tail.resize(no_tail.size() - 3);
  CHECK(parseUrgLog("exp.dat", no_tail + "\n").scans.size() == 1);
}

TEST_CASE("URG malformed lines give an error naming line and field", "[datasets][urg]") {
  const std::string good = urgLine(1, 2, 3, {});
  SECTION("wrong field count") {
    requireError(good + urgLine(1, 2, 3, {}, 600), 2, "expected 706 or 707 fields");
    requireError(good + "12 13 14\n", 2, "got 3");
  }
  SECTION("NaN, inf and non-integers") {
    requireError(urgLine(1, 2, 3, {"1", "nan"}), 1,
                 "field 26 (range [mm]): expected an integer, got 'nan'");
    requireError(urgLine(1, 2, 3, {"inf"}), 1, "field 25 (range [mm])");
    requireError(urgLine(1, 2, 3, {"12.5"}), 1, "expected an integer");
  }
  SECTION("huge and negative values") {
    requireError(urgLine(1, 2, 3, {"99999999"}), 1, "expected 0..60000, got 99999999");
    requireError(urgLine(1, 2, 3, {"-5"}), 1, "got -5");
    requireError(good + urgLine(-1, 2, 3, {}), 2, "field 1 (timestamp [us])");
    const std::string line = urgLine(1, 2, 3, {});
    const std::string huge = "1 14554 99999999999999999999999" + line.substr(line.find(" 3 "));
    requireError(huge, 1, "field 3 (left encoder): integer out of range");
  }
  SECTION("garbage") {
    requireError(good + "\x01\x02 garbage\n", 2, "expected 706 or 707 fields");
  }
  SECTION("skip_malformed counts instead") {
    UrgOptions lenient;
    lenient.skip_malformed = true;
    const auto log =
        parseUrgLog("exp.dat", good + "junk\n" + urgLine(1, 2, 3, {"nan"}) + good, lenient);
    CHECK(log.scans.size() == 2);
    CHECK(log.report.skipped == 2);
    CHECK(log.report.first_skips.at(0) == "exp.dat:2: malformed scan line");
  }
}

TEST_CASE("URG parser survives random mutations of the real log", "[datasets][urg][fuzz]") {
  std::string source;
  const fs::path path =
      tessera::test::sharedDataDir() / "mines-paristech-urg04lx-odometry/exp2.dat.gz";
  if (fs::exists(path)) {
    TextReader reader(path);
    std::string line;
    for (int i = 0; i < 200 && reader.next(line); ++i) source += line + "\n";
  } else {
    if (tessera::test::underCi()) FAIL("dataset " << path.string() << " is absent and CI=true");
    for (int i = 0; i < 20; ++i) source += urgLine(i * 100000, i * 10, i * 12, {"0", "7", "1500"});
  }
  std::vector<std::size_t> starts{0};
  for (std::size_t i = 0; i + 1 < source.size(); ++i)
    if (source[i] == '\n') starts.push_back(i + 1);
  tessera::test::Mutator mutator(424242);
  std::mt19937 pick(3);
  std::size_t parsed = 0, rejected = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    const std::size_t first = pick() % starts.size();
    const std::size_t last = std::min(starts.size(), first + 1 + pick() % 4);
    const std::size_t end = last < starts.size() ? starts[last] : source.size();
    const std::string text = mutator.mutate(source.substr(starts[first], end - starts[first]));
    for (bool lenient : {false, true}) {
      UrgOptions options;
      options.skip_malformed = lenient;
      try {
        const UrgLog log = parseUrgLog("fuzz.dat", text, options);
        ++parsed;
        for (const auto& s : log.scans) REQUIRE(s.ranges.size() == 682);
        for (const auto& p : urgOdometry(log.scans)) (void)p;
      } catch (const DatasetError&) {
        ++rejected;
        REQUIRE_FALSE(lenient);
      }
    }
  }
  INFO("parsed " << parsed << ", rejected " << rejected);
  CHECK(parsed > 0);
  CHECK(rejected > 0);
}
