#include <tessera/datasets/landmark_logs.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <random>

#include "../../shared_data.hpp"
#include "mutate.hpp"

namespace fs = std::filesystem;
using namespace tessera::datasets;
using namespace tessera::io;

namespace {

const std::string kBarcodes = "# header\n  1 \t 5\n  2 \t 14\n  6 \t 72\n  7 \t 27\n";
const std::string kLandmarks =
    "# header\n 6 \t 1.5 \t 2.5 \t 0.001 \t 0.002\n 7 \t -1 \t 0 \t 0 \t 0\n";

std::map<int, int> barcodes(const std::string& text = kBarcodes) {
  TextReader r = TextReader::fromString("Barcodes.dat", text);
  return readMrclamBarcodes(r);
}

std::vector<MrclamLandmark> landmarks() {
  TextReader r = TextReader::fromString("Landmark_Groundtruth.dat", kLandmarks);
  return readMrclamLandmarks(r, barcodes());
}

std::vector<MrclamMeasurement> measurements(const std::string& text, ParseReport& report) {
  TextReader r = TextReader::fromString("Robot1_Measurement.dat", text);
  return readMrclamMeasurements(r, barcodes(), landmarks(), report);
}

template <typename F>
std::string errorOf(F&& f) {
  try {
    f();
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "";
}

VictoriaParkLog victoria(const std::string& text) {
  TextReader r = TextReader::fromString("victoria.txt", text);
  return readVictoriaPark(r);
}

const std::string kOdo = " 0.0001 0 0 4e-06 0 4e-06\n";

}  // namespace

TEST_CASE("MRCLAM: every robot of dataset 1 reads with exact counts", "[datasets][landmarks]") {
  TESSERA_SHARED_DATA(folder, "utias-mrclam-dataset1");
  struct Expected {
    std::size_t odometry, landmark_obs, robot_obs, unknown_barcodes;
  };
  // Counted with awk on the gunzipped files; barcode 43 is not in Barcodes.dat.
  const Expected expected[5] = {{97890, 4771, 952, 0},
                                {94826, 5543, 1156, 0},
                                {97351, 6771, 1969, 2},
                                {100012, 3269, 722, 0},
                                {100726, 7137, 1654, 1}};
  for (int robot = 1; robot <= 5; ++robot) {
    const auto start = std::chrono::steady_clock::now();
    const MrclamRobotLog log = readMrclam(folder, robot);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const Expected& x = expected[robot - 1];
    INFO("robot " << robot << ": " << log.report.describe() << " in " << ms << " ms");
    CHECK(log.barcode_to_subject.size() == 20);
    REQUIRE(log.landmarks.size() == 15);
    CHECK(log.landmarks.front().subject == 6);
    CHECK(log.landmarks.front().barcode == 72);
    CHECK(log.landmarks.front().x == 5.70928255);
    CHECK(log.landmarks.back().subject == 20);
    CHECK(log.odometry.size() == x.odometry);
    std::size_t lm = 0, rob = 0;
    for (const auto& m : log.measurements) {
      if (m.is_robot) {
        ++rob;
        CHECK(m.landmark_index == -1);
        CHECK(m.subject != robot);  // a robot never sees itself
      } else {
        ++lm;
        CHECK(log.landmarks.at(static_cast<std::size_t>(m.landmark_index)).subject == m.subject);
      }
    }
    CHECK(lm == x.landmark_obs);
    CHECK(rob == x.robot_obs);
    CHECK(log.report.skipped == x.unknown_barcodes);
    CHECK(log.ground_truth.empty());  // RobotN_Groundtruth.dat is not in the shared copy
    UNSCOPED_INFO("MRCLAM robot " << robot << " read in " << ms << " ms");
  }
  // Robot 1's first measurement: "1248272276.038  90  2.148  0.025", barcode 90 = subject 16.
  const MrclamRobotLog r1 = readMrclam(folder, 1);
  CHECK(r1.measurements.front().time == 1248272276.038);
  CHECK(r1.measurements.front().subject == 16);
  CHECK(r1.measurements.front().landmark_index == 10);
  CHECK(r1.measurements.front().range == 2.148);
  CHECK(r1.odometry.front().v == 0.074);
}

TEST_CASE("MRCLAM: robots are marked, unknown barcodes skipped, times checked",
          "[datasets][landmarks]") {
  ParseReport report;
  const auto m = measurements(
      "# t barcode range bearing\n1.0 72 2.0 0.1\n1.0 14 3.0 -0.2\n1.5 43 1.0 0\n2.0 27 1 3\n",
      report);
  REQUIRE(m.size() == 3);
  CHECK(m[0].subject == 6);
  CHECK(m[0].landmark_index == 0);
  CHECK_FALSE(m[0].is_robot);
  CHECK(m[1].subject == 2);
  CHECK(m[1].is_robot);
  CHECK(m[1].landmark_index == -1);
  CHECK(m[2].landmark_index == 1);
  CHECK(report.skipped_by_reason.at("unknown barcode") == 1);
  CHECK(report.records == 3);

  ParseReport r2;
  CHECK_THAT(errorOf([&] { measurements("2.0 72 1 0\n1.0 72 1 0\n", r2); }),
             Catch::Contains("Robot1_Measurement.dat:2") && Catch::Contains("backwards"));
  CHECK_THAT(errorOf([&] { measurements("1.0 72 -1 0\n", r2); }), Catch::Contains(">= 0"));
  CHECK_THAT(errorOf([&] { measurements("1.0 72 1 nan\n", r2); }), Catch::Contains("finite"));
  CHECK_THAT(errorOf([&] { measurements("1.0 72 1\n", r2); }), Catch::Contains("expected 4"));
  CHECK_THAT(errorOf([&] { measurements("1e300 72 1 0\n", r2); }), Catch::Contains("time"));
  CHECK_THAT(errorOf([&] { measurements("1 99999999999 1 0\n", r2); }), Catch::Contains("barcode"));
}

TEST_CASE("MRCLAM: malformed barcode, landmark and odometry files", "[datasets][landmarks]") {
  CHECK_THAT(errorOf([] { barcodes("1 5\n2 5\n"); }), Catch::Contains("barcode 5 is listed twice"));
  CHECK_THAT(errorOf([] { barcodes("1 5\n1 6\n"); }), Catch::Contains("subject 1 is listed twice"));
  CHECK_THAT(errorOf([] { barcodes("# only a header\n"); }), Catch::Contains("no barcodes"));
  auto lm = [](const std::string& text) {
    TextReader r = TextReader::fromString("Landmark_Groundtruth.dat", text);
    return readMrclamLandmarks(r, barcodes());
  };
  CHECK_THAT(errorOf([&] { lm("2 0 0 0 0\n"); }), Catch::Contains("is a robot"));
  CHECK_THAT(errorOf([&] { lm("9 0 0 0 0\n"); }), Catch::Contains("no barcode"));
  CHECK_THAT(errorOf([&] { lm("6 0 0 -1 0\n"); }), Catch::Contains(">= 0"));
  CHECK_THAT(errorOf([&] { lm("6 0 inf 0 0\n"); }), Catch::Contains("finite"));
  CHECK_THAT(errorOf([&] { lm("6 0 0 0 0\n6 1 1 0 0\n"); }), Catch::Contains("listed twice"));
  auto odo = [](const std::string& text) {
    ParseReport report;
    TextReader r = TextReader::fromString("Robot1_Odometry.dat", text);
    return readMrclamOdometry(r, report);
  };
  CHECK(odo("1 0.1 0.2\n1 0.1 0.2\n2 0 0\n").size() == 3);  // repeated stamps are kept
  CHECK_THAT(errorOf([&] { odo("1 0.1\n"); }), Catch::Contains("Robot1_Odometry.dat:1"));
  CHECK_THAT(errorOf([&] { odo("1 0.1 0.2 7\n"); }), Catch::Contains("expected 3"));
  CHECK_THAT(errorOf([&] { odo("1 nan 0.2\n"); }), Catch::Contains("finite"));
  CHECK_THAT(errorOf([&] { odo("-5 0 0\n"); }), Catch::Contains("time"));
  CHECK_THAT(errorOf([&] { odo("\x7f\x45LF\x01\x02\n"); }), Catch::Contains("expected"));
  CHECK_THAT(errorOf([] { readMrclam("/nonexistent/folder", 1); }), Catch::Contains("missing"));
  CHECK_THAT(errorOf([] { readMrclam("/nonexistent/folder", 6); }), Catch::Contains("1..5"));
}

TEST_CASE("MRCLAM: an optional ground-truth file is read when present", "[datasets][landmarks]") {
  const auto dir = tessera::test::scratchDir("mrclam_gt");
  std::ofstream(dir / "Barcodes.dat") << kBarcodes;
  std::ofstream(dir / "Landmark_Groundtruth.dat") << kLandmarks;
  std::ofstream(dir / "Robot2_Odometry.dat") << "10 0.1 0\n";
  std::ofstream(dir / "Robot2_Measurement.dat") << "10.5 72 1 0\n";
  std::ofstream(dir / "Robot2_Groundtruth.dat") << "# t x y th\n10 1 2 0.5\n10.01 1.1 2 0.5\n";
  const MrclamRobotLog log = readMrclam(dir, 2);
  REQUIRE(log.ground_truth.size() == 2);
  CHECK(log.ground_truth[1].x == 1.1);
  CHECK(log.ground_truth[0].theta == 0.5);
  CHECK(log.report.records == 4);
}

TEST_CASE("Victoria Park: the GTSAM file reads with exact counts and dense indices",
          "[datasets][landmarks]") {
  TESSERA_SHARED_DATA(path, "victoria-park-gtsam/victoria_park.txt");
  const auto start = std::chrono::steady_clock::now();
  const VictoriaParkLog log = readVictoriaPark(path);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  INFO(log.report.describe() << " in " << ms << " ms");
  UNSCOPED_INFO("victoria_park.txt read in " << ms << " ms");
  CHECK(log.odometry.size() == 6968);
  CHECK(log.observations.size() == 3640);
  CHECK(log.pose_ids.size() == 6969);
  CHECK(log.landmark_ids.size() == 151);
  CHECK(log.report.skipped == 0);
  // One shared id space: the ids together are exactly 0..7119.
  std::vector<std::int64_t> all = log.pose_ids;
  all.insert(all.end(), log.landmark_ids.begin(), log.landmark_ids.end());
  std::sort(all.begin(), all.end());
  REQUIRE(all.size() == 7120);
  for (std::size_t i = 0; i < all.size(); ++i) REQUIRE(all[i] == static_cast<std::int64_t>(i));
  std::size_t skips = 0;
  for (std::size_t k = 0; k < log.odometry.size(); ++k) {
    REQUIRE(log.odometry[k].from_index == k);
    if (log.odometry[k].to_id != log.odometry[k].from_id + 1) ++skips;
  }
  CHECK(skips == 151);  // e.g. ODOMETRY 4 6: id 5 is a landmark
  CHECK(log.odometry[4].from_id == 4);
  CHECK(log.odometry[4].to_id == 6);
  CHECK(log.odometry[0].covariance(0, 0) == 0.0001);
  CHECK(log.odometry[0].covariance(2, 2) == 4e-06);
  // First sighting: "LANDMARK 4 5 11.5387 -3.2007 0.4 0 0.4".
  const auto& o = log.observations.front();
  CHECK(o.pose_id == 4);
  CHECK(o.pose_index == 4);
  CHECK(o.landmark_id == 5);
  CHECK(o.landmark_index == 0);
  CHECK(o.range == Approx(std::hypot(11.5387, -3.2007)));
  CHECK(o.bearing == Approx(std::atan2(-3.2007, 11.5387)));
  CHECK(o.range_std == Approx(std::sqrt(0.4)));
  CHECK(o.bearing_std == Approx(0.2));
  // Pose 6 is the fifth pose (index 5) because id 5 is a landmark.
  CHECK(log.pose_ids[5] == 6);
}

TEST_CASE("Victoria Park: malformed files", "[datasets][landmarks]") {
  const auto ok =
      victoria("ODOMETRY 0 1 1 0 0" + kOdo + "LANDMARK 1 2 3 4 0.4 0 0.4\n" + "ODOMETRY 1 3 1 0 0" +
               kOdo + "LANDMARK 3 2 0 0 0.4 0 0.4\n" + "GPS 1 2\n");
  CHECK(ok.odometry.size() == 2);
  CHECK(ok.observations.size() == 1);
  CHECK(ok.observations[0].range == 5);
  CHECK(ok.report.skipped_by_reason.at("landmark at zero range") == 1);
  CHECK(ok.report.skipped_by_reason.at("unknown tag") == 1);
  CHECK(ok.pose_ids == std::vector<std::int64_t>{0, 1, 3});

  auto err = [](const std::string& text) { return errorOf([&] { victoria(text); }); };
  CHECK_THAT(err("ODOMETRY 0 1 1 0 0" + kOdo + "LANDMARK 1 0 3 4 0.4 0 0.4\n"),
             Catch::Contains("victoria.txt:2") && Catch::Contains("both as a pose and a landmark"));
  CHECK_THAT(err("ODOMETRY 0 1 1 0 0" + kOdo + "ODOMETRY 0 2 1 0 0" + kOdo),
             Catch::Contains("victoria.txt:2") && Catch::Contains("not a chain"));
  CHECK_THAT(err("ODOMETRY 0 1 1 0 0" + kOdo + "LANDMARK 9 5 1 1 0.4 0 0.4\n"),
             Catch::Contains("not on the odometry chain"));
  CHECK_THAT(err("ODOMETRY 0 1 1 0 0 -1 0 0 1 0 1\n"), Catch::Contains("semidefinite"));
  CHECK_THAT(err("LANDMARK 0 1 1 1 0.4 5 0.4\n"), Catch::Contains("semidefinite"));
  CHECK_THAT(err("ODOMETRY 0 1 1 0 nan" + kOdo), Catch::Contains("finite"));
  CHECK_THAT(err("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0\n"), Catch::Contains("expected 12"));
  CHECK_THAT(err("LANDMARK 0 1 1e999 1 0.4 0 0.4\n"), Catch::Contains("out of range"));
  CHECK_THAT(err("ODOMETRY 0 99999999999 1 0 0" + kOdo), Catch::Contains("0..2147483647"));
  CHECK_THAT(err(""), Catch::Contains("no ODOMETRY or LANDMARK"));
  CHECK_THAT(err("\x89PNG\r\n\x1a\n"), Catch::Contains("no ODOMETRY or LANDMARK"));
  CHECK_THAT(err("LANDMARK 0 1 1.5e308 1.5e308 0.4 0 0.4\n"), Catch::Contains("too far"));
}

TEST_CASE("Landmark logs: thousands of random mutations parse or throw DatasetError",
          "[datasets][landmarks][fuzz]") {
  TESSERA_SHARED_DATA(victoria_path, "victoria-park-gtsam/victoria_park.txt");
  TESSERA_SHARED_DATA(mrclam, "utias-mrclam-dataset1");
  auto head = [](const fs::path& p, std::size_t n) {
    std::string s;
    TextReader r(p);
    std::string line;
    for (std::size_t i = 0; i < n && r.next(line); ++i) s += line + "\n";
    return s;
  };
  const std::string samples[3] = {head(victoria_path, 200),
                                  head(mrclam / "Robot3_Measurement.dat.gz", 200),
                                  head(mrclam / "Robot3_Odometry.dat.gz", 200)};
  const auto codes = barcodes(head(mrclam / "Barcodes.dat", 100));
  TextReader lr(mrclam / "Landmark_Groundtruth.dat");
  const auto lms = readMrclamLandmarks(lr, codes);
  auto parse = [&](int which, const std::string& text) {
    ParseReport report;
    TextReader r = TextReader::fromString("sample.dat", text);
    if (which == 0) readVictoriaPark(r);
    if (which == 1) readMrclamMeasurements(r, codes, lms, report);
    if (which == 2) readMrclamOdometry(r, report);
  };
  tessera::test::Mutator mutator(7);
  for (int which = 0; which < 3; ++which) {
    REQUIRE_NOTHROW(parse(which, samples[which]));
    std::size_t ok = 0, rejected = 0;
    for (int i = 0; i < 2500; ++i) {
      const std::string text = mutator.mutate(samples[which]);
      try {
        parse(which, text);
        ++ok;
      } catch (const DatasetError&) {
        ++rejected;
      } catch (const std::exception& e) {
        FAIL("sample " << which << ", mutation " << i << ": non-DatasetError " << e.what());
      }
    }
    INFO("sample " << which << ": " << ok << " parsed, " << rejected << " rejected");
    CHECK(ok > 0);
    CHECK(rejected > 0);
  }
}
