// Tests for the saved laser SLAM state (slam_state.hpp): exact round trips and an error naming
// the file and field for every kind of bad input.
#include <tessera/laser_slam/slam_state.hpp>

#include <Eigen/LU>
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

#include "../../shared_data.hpp"

using namespace tessera;
using Catch::Contains;
using laser_slam::SavedCamera;
using laser_slam::SavedConstraint;
using laser_slam::SavedSubmap;
using laser_slam::SlamState;
using laser_slam::SlamStateError;

namespace {

namespace fs = std::filesystem;

/// A submap with a random mix of unknown, free, occupied and in-between cells.
SavedSubmap randomSubmap(int id, const Pose2& origin, int width, int height, unsigned seed) {
  SavedSubmap s;
  s.id = id;
  s.origin = origin;
  s.grid.resolution = 0.05;
  s.grid.width = width;
  s.grid.height = height;
  s.grid.origin = Pose2(-0.1 * width / 2 + 0.013, -0.1 * height / 3, 0.0);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(-1, 100);
  s.grid.cells.resize(static_cast<std::size_t>(width) * height);
  for (auto& c : s.grid.cells) c = static_cast<std::int8_t>(value(rng));
  s.finished = true;
  return s;
}

SlamState sampleState() {
  SlamState state;
  state.frame_id = "map";
  // Coordinates that do not print exactly in a few digits (0.1 + 0.2, π/3, 1/3).
  state.submaps.push_back(randomSubmap(0, Pose2(1.5, -2.25, 0.5), 40, 30, 1));
  state.submaps.push_back(
      randomSubmap(1, Pose2(0.1 + 0.2, 1.0 / 3.0, std::numbers::pi / 3), 25, 35, 2));
  state.submaps.push_back(randomSubmap(3, Pose2(-7.125e-3, 12.75, -3.0), 10, 12, 3));
  state.submaps.back().finished = false;
  SavedConstraint hand;
  hand.from = 0;
  hand.to = 1;
  hand.relative = Pose2(1.0 / 7.0, -0.2, 0.1);
  Eigen::Matrix3d cov;
  cov << 0.01, 0.002, 0.0001, 0.002, 0.03, 0.0003, 0.0001, 0.0003, 0.004;
  const Eigen::Matrix3d inv = cov.inverse();
  hand.information = 0.5 * (inv + inv.transpose());
  SavedConstraint loop;
  loop.from = 3;
  loop.to = 0;
  loop.relative = Pose2(-4.0, 2.5, std::numbers::pi);
  loop.information = Eigen::Vector3d(400.0, 250.0, 1e4 / 3.0).asDiagonal();
  loop.revisit = true;
  state.constraints = {hand, loop};
  // Two cameras, out of id order: a tilted one calibrated in submap 3, one looking down in 1.
  SavedCamera tilted;
  tilted.camera = 5;
  tilted.submap = 3;
  tilted.stamp_ns = 1'234'567'890'123;
  tilted.floor_to_pixel << 106.0 + 1.0 / 3.0, -3.25, 320.5, 2.0 / 7.0, 107.3, 240.125, 1e-3 / 3.0,
      -2e-3, 1.0;
  tilted.rms_px = 0.1 + 0.2;
  tilted.coverage = std::numbers::pi / 10;
  tilted.condition = 3.3e3 / 7;
  tilted.pairs = 402;
  tilted.inliers = 398;
  SavedCamera down;
  down.camera = 2;
  down.submap = 1;
  down.stamp_ns = 77;
  down.floor_to_pixel << -50.0, 0.5, 640.0, 0.25, 49.75, 12.0, 0.0, 0.0, 1.0;
  down.rms_px = 1.5;
  down.coverage = 0.75;
  down.condition = 12.0;
  down.pairs = 30;
  down.inliers = 29;
  state.cameras = {tilted, down};
  return state;
}

void checkSameCamera(const SavedCamera& a, const SavedCamera& b) {
  CHECK(b.camera == a.camera);
  CHECK(b.submap == a.submap);
  CHECK(b.stamp_ns == a.stamp_ns);
  CHECK(b.floor_to_pixel == a.floor_to_pixel);
  CHECK(b.rms_px == a.rms_px);
  CHECK(b.coverage == a.coverage);
  CHECK(b.condition == a.condition);
  CHECK(b.pairs == a.pairs);
  CHECK(b.inliers == a.inliers);
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

/// A fresh directory holding sampleState().
fs::path savedSample(const std::string& name) {
  const fs::path dir = test::scratchDir("slam_state_" + name) / "state";
  laser_slam::saveSlamState(sampleState(), dir);
  return dir;
}

}  // namespace

TEST_CASE("slam state round trip keeps submaps, poses and constraints bit for bit",
          "[slam_state]") {
  const SlamState saved = sampleState();
  const fs::path dir = savedSample("round_trip");
  CHECK(fs::exists(dir / "state.yaml"));
  CHECK(fs::exists(dir / "submap_0003.cells"));
  CHECK_FALSE(fs::exists(dir / "state.yaml.tmp"));
  const SlamState loaded = laser_slam::loadSlamState(dir);
  CHECK(loaded.format_version == 2);
  CHECK(loaded.frame_id == saved.frame_id);
  REQUIRE(loaded.submaps.size() == saved.submaps.size());
  for (std::size_t k = 0; k < saved.submaps.size(); ++k) {
    const SavedSubmap& a = saved.submaps[k];
    const SavedSubmap& b = loaded.submaps[k];
    CHECK(b.id == a.id);
    CHECK(b.origin.x == a.origin.x);
    CHECK(b.origin.y == a.origin.y);
    CHECK(b.origin.theta == a.origin.theta);
    CHECK(b.finished == a.finished);
    CHECK(b.grid.resolution == a.grid.resolution);
    CHECK(b.grid.width == a.grid.width);
    CHECK(b.grid.height == a.grid.height);
    CHECK(b.grid.origin.x == a.grid.origin.x);
    CHECK(b.grid.origin.y == a.grid.origin.y);
    CHECK(b.grid.origin.theta == a.grid.origin.theta);
    CHECK(b.grid.cells == a.grid.cells);
  }
  REQUIRE(loaded.constraints.size() == 2);
  for (std::size_t k = 0; k < 2; ++k) {
    const SavedConstraint& a = saved.constraints[k];
    const SavedConstraint& b = loaded.constraints[k];
    CHECK(b.from == a.from);
    CHECK(b.to == a.to);
    CHECK(b.revisit == a.revisit);
    CHECK(b.relative.x == a.relative.x);
    CHECK(b.relative.y == a.relative.y);
    CHECK(b.relative.theta == a.relative.theta);
    CHECK(b.information == a.information);
  }
  // Cameras come back by increasing id.
  REQUIRE(loaded.cameras.size() == 2);
  checkSameCamera(saved.cameras[1], loaded.cameras[0]);
  checkSameCamera(saved.cameras[0], loaded.cameras[1]);
  // The assembled maps agree too, and a second save of the loaded state is the same text.
  const auto map_a = laser_slam::assembleSlamState(saved);
  const auto map_b = laser_slam::assembleSlamState(loaded);
  REQUIRE_FALSE(map_a.empty());
  CHECK(map_b.width == map_a.width);
  CHECK(map_b.height == map_a.height);
  CHECK(map_b.cells == map_a.cells);
  const fs::path again = dir.parent_path() / "again";
  laser_slam::saveSlamState(loaded, again);
  CHECK(readText(again / "state.yaml") == readText(dir / "state.yaml"));
}

TEST_CASE("slam state saves submaps by id whatever their order and an empty graph",
          "[slam_state]") {
  SlamState state = sampleState();
  std::swap(state.submaps.front(), state.submaps.back());
  state.constraints.clear();
  const fs::path dir = test::scratchDir("slam_state_order") / "s";
  laser_slam::saveSlamState(state, dir);
  const SlamState loaded = laser_slam::loadSlamState(dir);
  REQUIRE(loaded.submaps.size() == 3);
  CHECK(loaded.submaps[0].id == 0);
  CHECK(loaded.submaps[1].id == 1);
  CHECK(loaded.submaps[2].id == 3);
  CHECK(loaded.constraints.empty());
}

TEST_CASE("slam state version 3 is rejected naming the versions read", "[slam_state]") {
  const fs::path dir = savedSample("version");
  replaceInFile(dir / "state.yaml", "version: 2", "version: 3");
  CHECK_THROWS_AS(laser_slam::loadSlamState(dir), SlamStateError);
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("state.yaml:3") &&
                                                        Contains("version: 3 is not supported") &&
                                                        Contains("reads versions 1 to 2"));
  SlamState state = sampleState();
  state.format_version = 3;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, dir.parent_path() / "v3"),
                    Contains("version: this build writes version 2"));
}

TEST_CASE("slam state of version 1 (no cameras) still loads and is saved again as version 2",
          "[slam_state]") {
  const fs::path dir = savedSample("version1");
  const fs::path yaml = dir / "state.yaml";
  // What a version-1 build wrote: the same file without the cameras section.
  std::string text = readText(yaml);
  const auto cameras = text.find("cameras:\n");
  REQUIRE(cameras != std::string::npos);
  text.erase(cameras);
  const auto version = text.find("version: 2\n");
  REQUIRE(version != std::string::npos);
  text.replace(version, 10, "version: 1");
  std::ofstream(yaml, std::ios::trunc) << text;
  const SlamState loaded = laser_slam::loadSlamState(dir);
  CHECK(loaded.format_version == 1);
  CHECK(loaded.submaps.size() == 3);
  CHECK(loaded.constraints.size() == 2);
  CHECK(loaded.cameras.empty());
  CHECK(loaded.submaps[1].grid.cells == sampleState().submaps[1].grid.cells);
  // Saved again, it is a version 2 state with an empty cameras list.
  const fs::path again = dir.parent_path() / "again";
  laser_slam::saveSlamState(loaded, again);
  const std::string saved = readText(again / "state.yaml");
  CHECK_THAT(saved, Contains("version: 2\n") && Contains("cameras: []\n"));
  CHECK(laser_slam::loadSlamState(again).format_version == 2);
  // A version 1 file has no cameras section: one there is an error, as is a version 2 without.
  std::ofstream(yaml, std::ios::trunc) << text << "cameras: []\n";
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("state.yaml:") && Contains("cameras: not part of version 1"));
  std::ofstream(yaml, std::ios::trunc) << saved.substr(0, saved.find("cameras:"));
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("state.yaml:2: cameras: missing (version 2 lists"));
}

TEST_CASE("slam state of another format is rejected naming the format", "[slam_state]") {
  const fs::path dir = savedSample("format");
  replaceInFile(dir / "state.yaml", "format: tessera-slam-state", "format: g2o-graph");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("state.yaml:2") && Contains("format") && Contains("'g2o-graph'") &&
                        Contains("tessera-slam-state"));
  replaceInFile(dir / "state.yaml", "format: g2o-graph\n", "");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("format: missing"));
}

TEST_CASE("slam state with a truncated submap file names the file and sizes", "[slam_state]") {
  const fs::path dir = savedSample("truncated");
  const fs::path cells = dir / "submap_0001.cells";
  REQUIRE(fs::file_size(cells) == 25u * 35u);
  fs::resize_file(cells, 100);
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("submap_0001.cells") &&
                                                        Contains("submap 1") &&
                                                        Contains("holds 100 bytes, expected 875"));
  fs::remove(cells);
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("submap_0001.cells") && Contains("cell file missing"));
}

TEST_CASE("slam state with a changed or out-of-range cell names the file", "[slam_state]") {
  const fs::path dir = savedSample("corrupt");
  const fs::path cells = dir / "submap_0000.cells";
  {
    std::fstream f(cells, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(17);
    f.put(static_cast<char>(120));  // same size, other content, not a cell value
  }
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("submap_0000.cells") && Contains("checksum"));
  // With the checksum updated, the value itself is named.
  const SlamState good = sampleState();
  std::vector<std::int8_t> bad = good.submaps[0].grid.cells;
  bad[17] = 120;
  SlamState with_bad = good;
  with_bad.submaps[0].grid.cells = bad;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(with_bad, dir.parent_path() / "x"),
                    Contains("submap 0") && Contains("value 120 at index 17"));
}

TEST_CASE("slam state with a NaN origin names the submap and field", "[slam_state]") {
  const fs::path dir = savedSample("nan");
  replaceInFile(dir / "state.yaml", "origin: [1.5, -2.25, 0.5]", "origin: [.nan, -2.25, 0.5]");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("state.yaml:7") &&
                                                        Contains("submaps[0].origin") &&
                                                        Contains("finite") && Contains(".nan"));
  replaceInFile(dir / "state.yaml", "origin: [.nan, -2.25, 0.5]", "origin: [nan, -2.25, 0.5]");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("submaps[0].origin") && Contains("numbers"));
  replaceInFile(dir / "state.yaml", "origin: [nan, -2.25, 0.5]", "origin: [1, 2]");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("submaps[0].origin") && Contains("[x, y, theta]"));
  // Saving refuses a non-finite pose too, naming it.
  SlamState state = sampleState();
  state.submaps[1].origin.theta = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, dir.parent_path() / "nan_save"),
                    Contains("submap 1") && Contains("origin"));
  state = sampleState();
  state.constraints[1].relative.x = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, dir.parent_path() / "inf_save"),
                    Contains("constraints[1]") && Contains("relative"));
}

TEST_CASE("slam state in an empty or missing directory says state.yaml is missing",
          "[slam_state]") {
  const fs::path root = test::scratchDir("slam_state_empty");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(root), Contains("state.yaml") && Contains("missing"));
  CHECK_THROWS_WITH(laser_slam::loadSlamState(root / "nowhere"),
                    Contains("nowhere") && Contains("no such directory"));
  std::ofstream(root / "file.txt") << "x";
  CHECK_THROWS_WITH(laser_slam::loadSlamState(root / "file.txt"), Contains("not a directory"));
}

TEST_CASE("slam state with state.yaml removed but cell files left says state.yaml is missing",
          "[slam_state]") {
  const fs::path dir = savedSample("no_yaml");
  fs::remove(dir / "state.yaml");
  REQUIRE(fs::exists(dir / "submap_0000.cells"));
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains((dir / "state.yaml").string()) && Contains("missing"));
}

TEST_CASE("slam state with malformed or inconsistent fields names them", "[slam_state]") {
  const fs::path dir = savedSample("malformed");
  const fs::path yaml = dir / "state.yaml";
  const std::string original = readText(yaml);
  const auto expectError = [&](const std::string& from, const std::string& to,
                               const std::string& named) {
    std::ofstream(yaml, std::ios::trunc) << original;
    replaceInFile(yaml, from, to);
    INFO(from << " -> " << to);
    CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains(named));
  };
  expectError("width: 40", "width: forty", "submaps[0].width: must be an integer, got 'forty'");
  expectError("width: 40", "width: 0", "submaps[0].width: must be in 1..");
  // A size that disagrees with the cell file: 41 x 30 cells expected, 40 x 30 there.
  expectError("width: 40", "width: 41", "holds 1200 bytes, expected 1230");
  expectError("resolution: 0.05", "resolution: -0.05", "submaps[0].resolution: must be > 0");
  expectError("finished: true", "finished: maybe", "submaps[0].finished: must be true or false");
  expectError("file: submap_0000.cells", "file: ../submap_0000.cells",
              "submaps[0].file: must be a file name inside the state directory");
  expectError("  - id: 1\n", "  - id: 0\n", "submaps[1].id: submap 0 is listed twice");
  expectError("    to: 1\n", "    to: 2\n", "constraints[0].to: names submap 2, not saved");
  expectError("    to: 1\n", "    to: 0\n", "constraints[0].to: links submap 0 to itself");
  expectError("kind: hand_over", "kind: odometry",
              "constraints[0].kind: must be hand_over or revisit");
  expectError("information: [", "information: [1, ",
              "constraints[0].information: must be a list of 9 values");
  expectError("frame_id: map", "frame_id: ''", "frame_id: must be a non-empty text");
  expectError("submaps:\n", "submaps: 3\nsubmaps_old:\n", "submaps: must be a list");
  // Cameras: each in a saved submap, 9 finite homography values, invertible, once per id.
  expectError("    submap: 1\n", "    submap: 4\n", "cameras[0].submap: names submap 4, not saved");
  expectError("rms_px: 1.5", "rms_px: .nan", "cameras[0].rms_px: must be finite, got '.nan'");
  expectError("homography: [-50, ", "homography: [",
              "cameras[0].homography: must be a list of 9 values (3x3 floor -> pixel homography");
  expectError("homography: [-50, ", "homography: [.inf, ",
              "cameras[0].homography: must be a list of 9 values (3x3 floor -> pixel homography, "
              "row-major) of finite numbers");
  expectError("homography: [-50, 0.5, 640, 0.25, 49.75, 12, 0, 0, 1]",
              "homography: [1, 2, 3, 2, 4, 6, 0, 0, 1]", "cameras[0].homography: is singular");
  expectError("  - id: 5\n", "  - id: 2\n", "cameras[1].id: camera 2 is listed twice");
  expectError("  - id: 2\n", "  - id: -2\n", "cameras[0].id: must be in 0..");
  expectError("inliers: 29", "inliers: 31", "cameras[0].inliers: must be in 0..pairs (30), got 31");
  expectError("    coverage: 0.75\n", "", "cameras[0].coverage: missing");
  expectError("cameras:\n", "cameras: {}\nold:\n", "cameras: must be a list");
  // Not YAML at all, and a file cut in half.
  std::ofstream(yaml, std::ios::trunc) << "format: [unclosed\n";
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("state.yaml") && Contains("YAML"));
  std::ofstream(yaml, std::ios::trunc) << original.substr(0, original.size() / 2);
  CHECK_THROWS_AS(laser_slam::loadSlamState(dir), SlamStateError);
  std::ofstream(yaml, std::ios::trunc) << "";
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir), Contains("expected a YAML mapping"));
}

TEST_CASE("slam state with a bad camera names it on save, line and field on load", "[slam_state]") {
  const fs::path root = test::scratchDir("slam_state_cameras");
  SlamState state = sampleState();
  state.cameras[0].submap = 9;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, root / "a"),
                    Contains("state.yaml") && Contains("cameras[0] (camera 5)") &&
                        Contains("submap: names submap 9, not saved"));
  state = sampleState();
  state.cameras[1].floor_to_pixel(1, 2) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, root / "b"),
                    Contains("cameras[1] (camera 2): homography: must be 9 finite numbers"));
  state = sampleState();
  state.cameras[1].camera = 5;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, root / "c"),
                    Contains("cameras[1] (camera 5): id: twice"));
  CHECK_FALSE(fs::exists(root / "a" / "state.yaml"));
  // The line of the field at fault: the first camera (id 2, written first) starts at "  - id: 2".
  const fs::path dir = savedSample("camera_line");
  const std::string text = readText(dir / "state.yaml");
  const auto at = text.find("  - id: 2\n", text.find("cameras:"));
  REQUIRE(at != std::string::npos);
  const auto line =
      std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n') + 1;
  replaceInFile(dir / "state.yaml", "rms_px: 1.5", "rms_px: .nan");
  CHECK_THROWS_WITH(laser_slam::loadSlamState(dir),
                    Contains("state.yaml:" + std::to_string(line + 4) + ": cameras[0].rms_px"));
  CHECK(floorCameraCalibrationProblem(sampleState().cameras[0]).empty());
}

TEST_CASE("slam state asymmetric or indefinite information is refused on save", "[slam_state]") {
  const fs::path dir = test::scratchDir("slam_state_info") / "s";
  SlamState state = sampleState();
  state.constraints[0].information(0, 1) += 1.0;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, dir),
                    Contains("constraints[0]") && Contains("symmetric"));
  state = sampleState();
  state.constraints[1].information(2, 2) = -1.0;
  CHECK_THROWS_WITH(laser_slam::saveSlamState(state, dir),
                    Contains("constraints[1]") && Contains("positive semidefinite"));
  CHECK_FALSE(fs::exists(dir / "state.yaml"));
}

TEST_CASE("slam state writer fed one submap at a time writes what saveSlamState writes",
          "[slam_state]") {
  const fs::path root = test::scratchDir("slam_state_writer");
  const SlamState state = sampleState();
  laser_slam::saveSlamState(state, root / "whole");
  {
    laser_slam::SlamStateWriter writer(root / "streamed", state.frame_id);
    // Out of id order, each grid a temporary the writer does not keep.
    for (const int k : {2, 0, 1}) writer.addSubmap(SavedSubmap(state.submaps[k]));
    CHECK(writer.submaps() == 3);
    CHECK_FALSE(fs::exists(root / "streamed" / "state.yaml"));  // only once finished
    for (const SavedConstraint& c : state.constraints) writer.addConstraint(c);
    for (const SavedCamera& c : state.cameras) writer.addCamera(c);
    writer.finish();
    CHECK_THROWS_WITH(writer.finish(), Contains("already written"));
  }
  CHECK(readText(root / "streamed" / "state.yaml") == readText(root / "whole" / "state.yaml"));
  for (const char* f : {"submap_0000.cells", "submap_0001.cells", "submap_0003.cells"})
    CHECK(readText(root / "streamed" / f) == readText(root / "whole" / f));
  const SlamState loaded = laser_slam::loadSlamState(root / "streamed");
  REQUIRE(loaded.submaps.size() == 3);
  CHECK(loaded.submaps[2].grid.cells == state.submaps[2].grid.cells);
}

TEST_CASE(
    "slam state writer refuses parts that name submaps not yet added and writes no "
    "state.yaml",
    "[slam_state]") {
  const fs::path root = test::scratchDir("slam_state_writer_bad");
  const SlamState state = sampleState();
  CHECK_THROWS_WITH(laser_slam::SlamStateWriter(root / "a", ""), Contains("frame_id"));
  CHECK_THROWS_WITH(laser_slam::SlamStateWriter(root / "a", "map", 3),
                    Contains("state.yaml") && Contains("the state says 3"));
  CHECK_FALSE(fs::exists(root / "a"));  // nothing created for a refused writer

  laser_slam::SlamStateWriter writer(root / "b", "map");
  writer.addSubmap(state.submaps[0]);
  CHECK_THROWS_WITH(writer.addSubmap(state.submaps[0]), Contains("submap 0: id: twice"));
  // Constraint 0 -> 1 before submap 1 was added.
  CHECK_THROWS_WITH(writer.addConstraint(state.constraints[0]),
                    Contains("constraints[0]") && Contains("to: names submap 1, not saved"));
  CHECK_THROWS_WITH(writer.addCamera(state.cameras[1]),
                    Contains("cameras[0] (camera 2)") && Contains("names submap 1, not saved"));
  SavedSubmap bad = state.submaps[1];
  bad.grid.cells[7] = 101;
  CHECK_THROWS_WITH(writer.addSubmap(bad), Contains("submap 1: cells: value 101 at index 7"));
  bad.grid.cells.pop_back();
  CHECK_THROWS_WITH(writer.addSubmap(bad), Contains("submap 1: cells:"));
  bad = state.submaps[1];
  bad.origin.x = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(writer.addSubmap(bad), Contains("submap 1: origin: must be finite"));
  CHECK_FALSE(fs::exists(root / "b" / "submap_0001.cells"));
  CHECK_FALSE(fs::exists(root / "b" / "state.yaml"));
  // The refused parts left the writer usable.
  writer.addSubmap(state.submaps[1]);
  writer.addConstraint(state.constraints[0]);
  writer.finish();
  const SlamState loaded = laser_slam::loadSlamState(root / "b");
  CHECK(loaded.submaps.size() == 2);
  CHECK(loaded.constraints.size() == 1);
}
