// Tests for map files (PGM + YAML + PNG, ROS map_server format) and TUM trajectories.
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <catch2/catch.hpp>

#include "../../file_size_limit.hpp"

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <random>
#include <string>

namespace fs = std::filesystem;
using namespace tessera;
using namespace tessera::grid;
using namespace tessera::mapping;
using Catch::Matchers::Contains;

namespace {

/// A fresh, empty folder under the system temp dir, removed at scope exit.
struct TempDir {
  fs::path path;
  TempDir() {
    std::random_device rd;
    path = fs::temp_directory_path() / ("tessera_io_test_" + std::to_string(rd()));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

void writeText(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

const std::string kGoodYaml =
    "image: m.pgm\nresolution: 0.1\norigin: [1.0, -2.0, 0.0]\nnegate: 0\n"
    "occupied_thresh: 0.65\nfree_thresh: 0.196\n";

/// 3 wide, 2 high map with a distinct class per cell so a flip would show.
OccupancyMap smallMap() {
  OccupancyMap m;
  m.resolution = 0.05;
  m.width = 3;
  m.height = 2;
  m.origin = Pose2(-1.25, 2.5, 0.0);
  // row 0 (bottom): occupied, free, unknown; row 1 (top): free, unknown, occupied
  m.cells = {100, 0, -1, 10, 50, 97};
  return m;
}

}  // namespace

TEST_CASE("map save/load round trip keeps classes, orientation and origin", "[map_io]") {
  TempDir dir;
  const OccupancyMap map = smallMap();
  const SavedMap saved = saveMap(map, dir.path / "sub" / "map");
  CHECK(saved.yaml == dir.path / "sub" / "map.yaml");
  CHECK(fs::exists(saved.pgm));
  CHECK(fs::exists(saved.png));

  // Image row 0 is the top: map row 1.
  const GrayImage img = readPgm(saved.pgm);
  REQUIRE(img.width == 3);
  REQUIRE(img.height == 2);
  CHECK(img.pixels[0] == 254);  // (0, row 1) free
  CHECK(img.pixels[1] == 205);  // (1, row 1) 50% → unknown
  CHECK(img.pixels[2] == 0);    // (2, row 1) occupied
  CHECK(img.pixels[3] == 0);    // (0, row 0) occupied
  CHECK(img.pixels[4] == 254);
  CHECK(img.pixels[5] == 205);

  const OccupancyMap back = loadMap(saved.yaml);
  CHECK(back.width == 3);
  CHECK(back.height == 2);
  CHECK(back.resolution == 0.05);  // exact: no binary noise in the text
  CHECK(back.origin.x == -1.25);
  CHECK(back.origin.y == 2.5);
  CHECK(back.cells == std::vector<std::int8_t>{100, 0, -1, 0, -1, 100});
  // The same point maps to the same cell in both.
  const Eigen::Vector2d p = map.cellCenter(2, 1);
  CHECK(back.cellOf(p) == Eigen::Vector2i(2, 1));

  // The YAML is what map_server expects.
  std::ifstream y(saved.yaml);
  const std::string yaml((std::istreambuf_iterator<char>(y)), std::istreambuf_iterator<char>());
  CHECK_THAT(yaml, Contains("image: map.pgm"));
  CHECK_THAT(yaml, Contains("negate: 0"));
  CHECK_THAT(yaml, Contains("occupied_thresh: 0.65"));
  CHECK_THAT(yaml, Contains("free_thresh: 0.196"));
  CHECK_THAT(yaml, Contains("origin: [-1.25, 2.5, 0]"));

  SECTION("the PNG holds the same picture") {
    writeText(dir.path / "png.yaml",
              "image: sub/map.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
              "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n");
    const OccupancyMap from_png = loadMap(dir.path / "png.yaml");
    CHECK(from_png.cells == back.cells);
  }
}

TEST_CASE("PGM reader accepts comments, ASCII P2 and small maxval", "[map_io]") {
  TempDir dir;
  writeText(dir.path / "a.pgm", "P2\n# comment\n2 1 # trailing\n15\n0 15\n");
  const GrayImage a = readPgm(dir.path / "a.pgm");
  REQUIRE(a.pixels.size() == 2);
  CHECK(a.pixels[0] == 0);
  CHECK(a.pixels[1] == 255);
  writeText(dir.path / "b.pgm", std::string("P5 2 1 255\n") + char(7) + char(200));
  const GrayImage b = readPgm(dir.path / "b.pgm");
  CHECK(b.pixels == std::vector<std::uint8_t>{7, 200});
}

TEST_CASE("malformed map files give errors naming the file and the problem", "[map_io]") {
  TempDir dir;
  const fs::path yaml = dir.path / "m.yaml";
  const fs::path pgm = dir.path / "m.pgm";
  writeText(yaml, kGoodYaml);

  SECTION("bad magic") {
    writeText(pgm, "P6\n2 2\n255\nxxxx");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("m.pgm") && Contains("expected magic 'P5' or 'P2'"));
  }
  SECTION("bad width") {
    writeText(pgm, "P5\nabc 2\n255\nxxxx");
    CHECK_THROWS_WITH(readPgm(pgm), Contains("expected width") && Contains("'abc'"));
  }
  SECTION("header cut short") {
    writeText(pgm, "P5\n2 2\n");
    CHECK_THROWS_WITH(readPgm(pgm), Contains("expected maxval") && Contains("end of file"));
  }
  SECTION("16-bit") {
    writeText(pgm, "P5\n2 2\n65535\nxxxxxxxx");
    CHECK_THROWS_WITH(readPgm(pgm), Contains("16-bit"));
  }
  SECTION("truncated pixel data") {
    writeText(pgm, "P5\n4 3\n255\nabcde");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("m.pgm") && Contains("truncated pixel data") &&
                                         Contains("expected 12 bytes") && Contains("found 5"));
  }
  SECTION("missing image file") {
    CHECK_THROWS_WITH(loadMap(yaml), Contains("m.pgm") && Contains("cannot open"));
  }
  SECTION("missing yaml file") {
    CHECK_THROWS_AS(loadMap(dir.path / "nope.yaml"), MapIoError);
  }
  SECTION("missing yaml key") {
    writeText(yaml,
              "image: m.pgm\norigin: [0, 0, 0]\nnegate: 0\n"
              "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("m.yaml") && Contains("missing key 'resolution'"));
  }
  SECTION("NaN resolution") {
    writeText(yaml,
              "image: m.pgm\nresolution: .nan\norigin: [0, 0, 0]\nnegate: 0\n"
              "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
    CHECK_THROWS_WITH(loadMap(yaml),
                      Contains("m.yaml:2") && Contains("'resolution' must be finite"));
  }
  SECTION("origin not a triple") {
    writeText(yaml,
              "image: m.pgm\nresolution: 0.1\norigin: [0, 0]\nnegate: 0\n"
              "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("m.yaml:3") && Contains("[x, y, yaw]"));
  }
  SECTION("non-numeric origin") {
    writeText(yaml,
              "image: m.pgm\nresolution: 0.1\norigin: [0, abc, 0]\nnegate: 0\n"
              "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("'origin' must be a number"));
  }
  SECTION("not YAML") {
    writeText(yaml, "image: [unclosed\n");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("not valid YAML"));
  }
  SECTION("inverted thresholds") {
    writeText(yaml,
              "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
              "occupied_thresh: 0.1\nfree_thresh: 0.5\n");
    CHECK_THROWS_WITH(loadMap(yaml), Contains("free_thresh < occupied_thresh"));
  }
}

TEST_CASE("map_server modes: negate and scale", "[map_io]") {
  TempDir dir;
  writeText(dir.path / "m.pgm", std::string("P5 3 1 255\n") + char(0) + char(128) + char(255));
  writeText(dir.path / "n.yaml",
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
  CHECK(loadMap(dir.path / "n.yaml").cells == std::vector<std::int8_t>{0, -1, 100});
  writeText(dir.path / "s.yaml",
            "image: m.pgm\nmode: scale\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
  const auto s = loadMap(dir.path / "s.yaml").cells;
  CHECK(s[0] == 100);
  CHECK(s[1] > 0);
  CHECK(s[1] < 100);
  CHECK(s[2] == 0);
}

TEST_CASE("saving an empty map is an error", "[map_io]") {
  TempDir dir;
  CHECK_THROWS_AS(saveMap(OccupancyMap{}, dir.path / "map"), MapIoError);
}

namespace map_io_failed_write_test {

using tessera::test::whatWithFileSizeLimit;

std::string bytesOf(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace map_io_failed_write_test

TEST_CASE("a map save that fails leaves the previous complete map", "[map_io][atomic_file]") {
  using namespace map_io_failed_write_test;
  TempDir dir;
  const fs::path base = dir.path / "map";
  saveMap(smallMap(), base);
  const std::string old_pgm = bytesOf(dir.path / "map.pgm");
  const std::string old_yaml = bytesOf(dir.path / "map.yaml");
  const std::string old_png = bytesOf(dir.path / "map.png");

  OccupancyMap big = smallMap();  // 120 kB of pixels
  big.width = 400;
  big.height = 300;
  big.cells.assign(static_cast<std::size_t>(400) * 300, 0);
  const std::string what = whatWithFileSizeLimit(16 * 1024, [&] { saveMap(big, base); });
  CHECK_THAT(what, Contains((dir.path / "map.pgm").string() + ": cannot write: File too large"));

  CHECK(bytesOf(dir.path / "map.pgm") == old_pgm);
  CHECK(bytesOf(dir.path / "map.yaml") == old_yaml);
  CHECK(bytesOf(dir.path / "map.png") == old_png);
  const OccupancyMap back = loadMap(dir.path / "map.yaml");
  CHECK(back.width == 3);
  CHECK(back.height == 2);
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(dir.path))
    files.push_back(e.path().filename().string());
  std::sort(files.begin(), files.end());
  CHECK(files == std::vector<std::string>{"map.pgm", "map.png", "map.yaml"});
}

TEST_CASE("TUM round trip is exact in time and planar pose", "[trajectory_io]") {
  TempDir dir;
  const fs::path file = dir.path / "t.tum";
  std::vector<TumPose> poses;
  poses.push_back(TumPose::fromPlanar(0, Pose2(0, 0, 0)));
  poses.push_back(TumPose::fromPlanar(1'234'567'890'123'456'789, Pose2(1.5, -2.25, 3.0)));
  poses.push_back(TumPose::fromPlanar(1, Pose2(-1e-9, 1e6, -std::numbers::pi / 2)));
  poses.push_back(TumPose::fromPlanar(-1'500'000'000, Pose2(0.1, 0.2, std::numbers::pi)));
  writeTum(file, poses);
  const auto back = readTum(file);
  REQUIRE(back.size() == poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    INFO("pose " << i);
    CHECK(back[i].stamp_ns == poses[i].stamp_ns);
    const Pose2 a = poses[i].planar(), b = back[i].planar();
    CHECK(b.x == a.x);
    CHECK(b.y == a.y);
    CHECK(std::abs(angleDiff(b.theta, a.theta)) < 1e-12);
    CHECK(back[i].position.z() == 0.0);
  }
  CHECK(formatTumLine(poses[1]).rfind("1234567890.123456789 1.5 -2.25 0 0 0 ", 0) == 0);
  CHECK(formatTumLine(poses[3]).rfind("-1.500000000 ", 0) == 0);
}

TEST_CASE("TUM reader skips comments, accepts stamps written by other tools", "[trajectory_io]") {
  TempDir dir;
  const fs::path file = dir.path / "t.tum";
  writeText(file,
            "# ground truth\n\n1305031102.1753 1 2 0.5 0 0 0.7071068 0.7071068\r\n"
            "  # indented comment\n1.5e0 0 0 0 0 0 0 1\n");
  const auto poses = readTum(file);
  REQUIRE(poses.size() == 2);
  CHECK(poses[0].stamp_ns == 1'305'031'102'175'300'000);
  CHECK(poses[0].position.z() == 0.5);
  CHECK(poses[0].planar().theta == Approx(std::numbers::pi / 2));
  CHECK(poses[1].stamp_ns == 1'500'000'000);
}

TEST_CASE("TUM reader reports malformed lines with file:line", "[trajectory_io]") {
  TempDir dir;
  const fs::path file = dir.path / "bad.tum";
  SECTION("too few fields") {
    writeText(file, "# c\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:3") && Contains("expected 8 fields"));
  }
  SECTION("too many fields") {
    writeText(file, "1.0 0 0 0 0 0 0 1 9\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:1") && Contains("found more"));
  }
  SECTION("not a number") {
    writeText(file, "1.0 0 0 0 0 0 0 1\n2.0 0 y 0 0 0 0 1\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:2") && Contains("for y") && Contains("'y'"));
  }
  SECTION("bad stamp") {
    writeText(file, "abc 0 0 0 0 0 0 1\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:1") && Contains("time stamp"));
  }
  SECTION("NaN") {
    writeText(file, "1.0 nan 0 0 0 0 0 1\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:1") && Contains("finite"));
  }
  SECTION("zero quaternion") {
    writeText(file, "1.0 0 0 0 0 0 0 0\n");
    CHECK_THROWS_WITH(readTum(file), Contains("bad.tum:1") && Contains("norm"));
  }
  SECTION("missing file") {
    CHECK_THROWS_AS(readTum(dir.path / "none.tum"), TrajectoryError);
  }
}

TEST_CASE("TumWriter streams and counts", "[trajectory_io]") {
  TempDir dir;
  const auto file = dir.path / "deep" / "s.tum";
  TumWriter w(file);
  w.write(10, Pose2(1, 2, 0.5));
  w.flush();
  // Until close() the poses are in a temporary file next to it; the trajectory file appears
  // complete or not at all.
  CHECK_FALSE(std::filesystem::exists(file));
  w.close();
  const auto poses = readTum(file);
  REQUIRE(poses.size() == 1);
  CHECK(poses[0].stamp_ns == 10);
  CHECK(poses[0].planar().theta == Approx(0.5));
  CHECK(w.count() == 1);
  CHECK(std::distance(std::filesystem::directory_iterator(dir.path / "deep"),
                      std::filesystem::directory_iterator()) == 1);
}

TEST_CASE("TumWriter without close leaves the previous trajectory", "[trajectory_io]") {
  TempDir dir;
  const auto file = dir.path / "s.tum";
  writeTum(file, {TumPose::fromPlanar(1, Pose2(0, 0, 0))});
  {
    TumWriter w(file);
    w.write(2, Pose2(1, 1, 0));
    w.write(3, Pose2(2, 2, 0));
    w.flush();
  }  // abandoned (a run that failed before stop): no close
  const auto poses = readTum(file);
  REQUIRE(poses.size() == 1);
  CHECK(poses[0].stamp_ns == 1);
  CHECK(std::distance(std::filesystem::directory_iterator(dir.path),
                      std::filesystem::directory_iterator()) == 1);
}
