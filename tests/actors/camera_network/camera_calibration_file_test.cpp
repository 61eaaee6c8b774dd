// The camera calibrations file (camera_calibration_file.hpp): exact round trips, and an error
// naming the file, the camera entry and the field for every kind of bad input.
#include <tessera/camera_network/camera_calibration_file.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "../../shared_data.hpp"

namespace camera_calibration_file_test {

using namespace tessera;
using camera_network::CameraCalibrationFileError;
using camera_network::CameraCalibrationRecord;
using Catch::Contains;
namespace fs = std::filesystem;

/// Two cameras, given out of id order, with numbers that do not print exactly in a few digits.
std::vector<CameraCalibrationRecord> sampleRecords() {
  CameraCalibrationRecord a;
  a.camera = 4;
  a.submap = 7;
  a.stamp_ns = 1'234'567'890'123;
  a.floor_to_pixel << 106.0 + 1.0 / 3.0, -3.25, 320.5, 2.0 / 7.0, 107.3, 240.125, 1e-3 / 3.0, -2e-3,
      1.0;
  a.rms_px = 0.1 + 0.2;
  a.coverage = std::numbers::pi / 10;
  a.condition = 3.3e3 / 7;
  a.pairs = 402;
  a.inliers = 398;
  CameraCalibrationRecord b;
  b.camera = 1;
  b.submap = 0;
  b.stamp_ns = 5;
  b.floor_to_pixel << -50.0, 0.5, 640.0, 0.25, 49.75, 12.0, 0.0, 0.0, 1.0;
  b.rms_px = 1.5;
  b.coverage = 1.0;
  b.condition = 12.0;
  b.pairs = 30;
  b.inliers = 30;
  return {a, b};
}

std::string readText(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Replaces the first `from` in the file by `to` (the test fails when `from` is absent).
void replaceInFile(const fs::path& path, const std::string& from, const std::string& to) {
  std::string text = readText(path);
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  text.replace(at, from.size(), to);
  std::ofstream(path, std::ios::trunc) << text;
}

/// The reader's error for the file (the test fails when it reads it).
CameraCalibrationFileError readError(const fs::path& path) {
  try {
    camera_network::readCameraCalibrations(path);
  } catch (const CameraCalibrationFileError& e) {
    return e;
  }
  FAIL("read " << path << " without an error");
  return CameraCalibrationFileError(path, 0, "", "");
}

TEST_CASE("camera calibrations file round trip is exact, by increasing camera id",
          "[camera_network][calibration_file]") {
  const fs::path dir = test::scratchDir("calibration_file_round_trip");
  const fs::path file = dir / "camera_calibrations.yaml";
  const auto records = sampleRecords();
  camera_network::writeCameraCalibrations(file, records);
  const auto text = readText(file);
  CHECK_THAT(text, Contains("cameras:\n  - id: 1\n") && Contains("# floor (submap frame, m)"));
  const auto loaded = camera_network::readCameraCalibrations(file);
  REQUIRE(loaded.size() == 2);
  CHECK(loaded[0] == records[1]);  // camera 1 first
  CHECK(loaded[1] == records[0]);
  CHECK(loaded[1].floor_to_pixel(0, 0) == 106.0 + 1.0 / 3.0);
  CHECK(loaded[1].rms_px == 0.1 + 0.2);
  // A second write of what was read is the same text; no temporary file is left.
  camera_network::writeCameraCalibrations(dir / "again.yaml", loaded);
  CHECK(readText(dir / "again.yaml") == text);
  for (const auto& e : fs::directory_iterator(dir))
    CHECK(e.path().filename().string().find(".tmp") == std::string::npos);
  // No cameras: an empty list that reads back as none.
  camera_network::writeCameraCalibrations(dir / "none.yaml", {});
  CHECK_THAT(readText(dir / "none.yaml"), Contains("cameras: []"));
  CHECK(camera_network::readCameraCalibrations(dir / "none.yaml").empty());
}

TEST_CASE("camera calibrations from the builder keep homography and quality",
          "[camera_network][calibration_file]") {
  camera_network::CameraCalibration c;
  c.camera = 3;
  c.submap = 12;
  c.stamp_ns = 99;
  c.homography.h << 100, 1, 300, -2, 101, 200, 0.001, 0.002, 1;
  c.homography.quality.rms_px = 0.7;
  c.homography.quality.coverage = 0.2;
  c.homography.quality.condition = 1e3;
  c.homography.quality.pairs = 50;
  c.homography.quality.inliers = 48;
  const CameraCalibrationRecord r = camera_network::calibrationRecord(c);
  CHECK(r.camera == 3);
  CHECK(r.submap == 12);
  CHECK(r.stamp_ns == 99);
  CHECK(r.floor_to_pixel == c.homography.h);
  CHECK(r.rms_px == 0.7);
  CHECK(r.coverage == 0.2);
  CHECK(r.condition == 1e3);
  CHECK(r.pairs == 50);
  CHECK(r.inliers == 48);
  CHECK(floorCameraCalibrationProblem(r).empty());
}

TEST_CASE("camera calibrations file that is missing, empty or not YAML names the file",
          "[camera_network][calibration_file]") {
  const fs::path dir = test::scratchDir("calibration_file_missing");
  const fs::path file = dir / "camera_calibrations.yaml";
  auto e = readError(file);
  CHECK_THAT(e.what(), Contains(file.string()) && Contains("missing: no such file"));
  CHECK(e.file() == file);

  std::ofstream(file, std::ios::trunc) << "";
  CHECK_THAT(readError(file).what(), Contains(file.string()) && Contains("empty file"));
  std::ofstream(file, std::ios::trunc) << "\n  \n";
  CHECK_THAT(readError(file).what(), Contains("empty file"));
  std::ofstream(file, std::ios::trunc) << "# only a comment\n";
  CHECK_THAT(readError(file).what(), Contains("empty file"));

  // Malformed: not YAML at all, and YAML of the wrong shape.
  std::ofstream(file, std::ios::trunc) << "cameras: [unclosed\n";
  e = readError(file);
  CHECK_THAT(e.what(), Contains(file.string() + ":1") && Contains("not valid YAML") &&
                           Contains("the line reads 'cameras: [unclosed'"));
  CHECK(e.field() == "cameras");
  std::ofstream(file, std::ios::trunc) << "- 1\n- 2\n";
  CHECK_THAT(readError(file).what(), Contains("expected a YAML mapping with a 'cameras:' list"));
  std::ofstream(file, std::ios::trunc) << "cameras: 3\n";
  CHECK_THAT(readError(file).what(), Contains(file.string() + ":1: cameras: must be a list"));
  std::ofstream(file, std::ios::trunc) << "cameras:\n";
  CHECK_THAT(readError(file).what(), Contains("cameras: must be a list") && Contains("nothing"));
  std::ofstream(file, std::ios::trunc) << "camera: []\n";
  e = readError(file);
  CHECK_THAT(e.what(), Contains("camera: unknown key"));
  CHECK(e.field() == "camera");
  std::ofstream(file, std::ios::trunc) << "cameras: [7]\n";
  CHECK_THAT(readError(file).what(), Contains("cameras[0]: must be a mapping (id, submap"));
  CHECK_THROWS_AS(camera_network::readCameraCalibrations(dir), CameraCalibrationFileError);
}

TEST_CASE("camera calibrations file cut short names the entry and field it was cut in",
          "[camera_network][calibration_file]") {
  const fs::path dir = test::scratchDir("calibration_file_truncated");
  const fs::path file = dir / "camera_calibrations.yaml";
  camera_network::writeCameraCalibrations(file, sampleRecords());
  const std::string full = readText(file);
  // Cut inside the second camera's homography list: not YAML any more.
  const auto cut = full.find("homography: [", full.find("  - id: 4")) + 20;
  std::ofstream(file, std::ios::trunc) << full.substr(0, cut);
  auto e = readError(file);
  INFO(e.what());
  CHECK(e.field() == "cameras[1]: homography");
  CHECK(e.line() == 16);
  CHECK_THAT(e.what(), Contains(file.string() + ":16: cameras[1]: homography: not valid YAML") &&
                           Contains("the line reads 'homography: [106.333'"));
  // Cut after a whole line: valid YAML, the first field not there is named.
  const auto after_rms = full.find('\n', full.find("rms_px", full.find("  - id: 4"))) + 1;
  std::ofstream(file, std::ios::trunc) << full.substr(0, after_rms);
  e = readError(file);
  CHECK(e.field() == "cameras[1] (camera 4): coverage");
  CHECK_THAT(e.what(), Contains(file.string() + ":13: cameras[1] (camera 4): coverage: missing"));
}

TEST_CASE("camera calibrations file with a bad field names the file, camera and field",
          "[camera_network][calibration_file]") {
  const fs::path dir = test::scratchDir("calibration_file_fields");
  const fs::path file = dir / "camera_calibrations.yaml";
  camera_network::writeCameraCalibrations(file, sampleRecords());
  const std::string original = readText(file);
  const auto expectError = [&](const std::string& from, const std::string& to,
                               const std::string& named) {
    std::ofstream(file, std::ios::trunc) << original;
    replaceInFile(file, from, to);
    INFO(from << " -> " << to);
    CHECK_THAT(readError(file).what(), Contains(file.string() + ":") && Contains(named));
  };
  // NaN and infinity, anywhere.
  expectError("rms_px: 1.5", "rms_px: .nan",
              "cameras[0] (camera 1): rms_px: must be a finite number, got '.nan'");
  expectError("coverage: 1\n", "coverage: .inf\n",
              "cameras[0] (camera 1): coverage: must be a finite number, got '.inf'");
  expectError("homography: [-50,", "homography: [.nan,",
              "cameras[0] (camera 1): homography: must be finite numbers, element 0 is '.nan'");
  // Missing and unknown keys.
  expectError("    condition: 12\n", "",
              "cameras[0] (camera 1): condition: missing (each camera has id, submap, stamp_ns");
  expectError("  - id: 1\n", "  - ident: 1\n", "cameras[0]: id: missing");
  expectError("    pairs: 30\n", "    pairs: 30\n    colour: red\n",
              "cameras[0] (camera 1): colour: unknown key (expected id, submap,");
  // Wrong types and ranges.
  expectError("submap: 0", "submap: first",
              "cameras[0] (camera 1): submap: must be an integer, "
              "got 'first'");
  expectError("stamp_ns: 5", "stamp_ns: 5.5", "stamp_ns: must be an integer, got '5.5'");
  expectError("rms_px: 1.5", "rms_px: [1.5]", "rms_px: must be a number, got [1.5]");
  expectError("rms_px: 1.5", "rms_px: -1.5", "rms_px: must be >= 0, got '-1.5'");
  expectError("coverage: 1\n", "coverage: 1.5\n", "coverage: must be in 0..1, got '1.5'");
  expectError("inliers: 30", "inliers: 31", "cameras[0] (camera 1): inliers: must be in 0..30");
  expectError("  - id: 1\n", "  - id: -1\n", "cameras[0]: id: must be >= 0, got '-1'");
  expectError("submap: 0", "submap: -2", "cameras[0] (camera 1): submap: must be >= 0, got '-2'");
  // The homography: 9 numbers, invertible.
  expectError("homography: [-50, ", "homography: [",
              "cameras[0] (camera 1): homography: must be a list of 9 numbers (3x3 floor -> "
              "pixel homography, row-major), got [");
  expectError("homography: [-50, ", "homography: [", "of 8 values");
  expectError("homography: [-50, 0.5, 640, 0.25, 49.75, 12, 0, 0, 1]",
              "homography: [1, 2, 3, 2, 4, 6, 0, 0, 1]",
              "cameras[0] (camera 1): homography: is singular");
  expectError("homography: [-50, 0.5, 640, 0.25, 49.75, 12, 0, 0, 1]", "homography: 5",
              "homography: must be a list of 9 numbers");
  // A camera listed twice.
  expectError("  - id: 4\n", "  - id: 1\n",
              "cameras[1] (camera 1): id: camera 1 is listed twice (also cameras[0])");
  // The field is also given on its own, with the line.
  std::ofstream(file, std::ios::trunc) << original;
  replaceInFile(file, "rms_px: 1.5", "rms_px: .nan");
  const auto e = readError(file);
  CHECK(e.field() == "cameras[0] (camera 1): rms_px");
  CHECK(e.line() == 8);
}

TEST_CASE("camera calibrations writer refuses invalid records and leaves no file",
          "[camera_network][calibration_file]") {
  const fs::path dir = test::scratchDir("calibration_file_write");
  const fs::path file = dir / "camera_calibrations.yaml";
  auto records = sampleRecords();
  records[1].rms_px = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(
      camera_network::writeCameraCalibrations(file, records),
      Contains(file.string()) && Contains("records[1] (camera 1): rms_px") && Contains("finite"));
  records = sampleRecords();
  records[0].floor_to_pixel.setZero();
  CHECK_THROWS_WITH(camera_network::writeCameraCalibrations(file, records),
                    Contains("records[0] (camera 4): homography: is singular"));
  records = sampleRecords();
  records[1].camera = 4;
  CHECK_THROWS_WITH(camera_network::writeCameraCalibrations(file, records),
                    Contains("records[1] (camera 4): id: camera 4 is given twice"));
  records = sampleRecords();
  records[0].submap = -1;
  CHECK_THROWS_WITH(camera_network::writeCameraCalibrations(file, records),
                    Contains("submap: must be >= 0"));
  CHECK_FALSE(fs::exists(file));
  // A folder that does not exist: the write fails naming the file.
  CHECK_THROWS_WITH(camera_network::writeCameraCalibrations(dir / "no" / "c.yaml", sampleRecords()),
                    Contains((dir / "no" / "c.yaml").string()));
}

}  // namespace camera_calibration_file_test
