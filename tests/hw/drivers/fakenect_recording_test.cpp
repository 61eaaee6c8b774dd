// fakenect recordings: written, checked, and refused (with the file and the reason) when
// fakenect would end the process on them: missing, truncated, malformed, NaN, empty.
#include <tessera/drivers/fakenect_recording.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <vector>

namespace fakenect_recording_test {

using namespace tessera::drivers;
namespace fs = std::filesystem;

struct TempFolder {
  explicit TempFolder(const std::string& name)
      : path(fs::temp_directory_path() / ("tessera_fakenect_" + name)) {
    fs::remove_all(path);
  }
  ~TempFolder() { fs::remove_all(path); }
  fs::path path;
};

void writeTwoFrames(const fs::path& folder) {
  FakenectRecordingWriter w(folder);
  const std::vector<std::uint16_t> depth(640 * 480, 1000);
  const std::vector<std::uint8_t> color(640 * 480 * 3, 7);
  w.addDepth(0.0, 1, depth);
  w.addColor(0.001, 2, color);
  w.addDepth(0.033, 3, depth);
  w.addColor(0.034, 4, color);
  CHECK(w.entries() == 4);
}

std::vector<std::string> indexLines(const fs::path& folder) {
  std::ifstream in(folder / "INDEX.txt");
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

void writeIndex(const fs::path& folder, const std::vector<std::string>& lines) {
  std::ofstream out(folder / "INDEX.txt", std::ios::trunc);
  for (const auto& l : lines) out << l << '\n';
}

TEST_CASE("a written fakenect recording checks out with its frame counts and duration",
          "[drivers][kinect]") {
  TempFolder t("ok");
  writeTwoFrames(t.path);
  const auto info = checkFakenectRecording(t.path);
  CHECK(info.depth_frames == 2);
  CHECK(info.color_frames == 2);
  CHECK(info.duration_s == Approx(0.034));
  const auto lines = indexLines(t.path);
  REQUIRE(lines.size() == 4);
  CHECK(lines[0].rfind("d-0.000000-1", 0) == 0);
  CHECK(fs::file_size(t.path / lines[0]) == 17 + 640 * 480 * 2);  // "P5 640 480 65535\n"
  // The second depth frame equals the first: a hard link, no second copy.
  CHECK(fs::hard_link_count(t.path / lines[0]) == 2);
  CHECK(fs::equivalent(t.path / lines[0], t.path / lines[2]));
}

TEST_CASE("the recording writer refuses wrong sizes, 12-bit values and time going back",
          "[drivers][kinect]") {
  TempFolder t("writer");
  FakenectRecordingWriter w(t.path);
  CHECK_THROWS_AS(w.addDepth(0, 0, std::vector<std::uint16_t>(100)), std::invalid_argument);
  CHECK_THROWS_AS(w.addDepth(0, 0, std::vector<std::uint16_t>(640 * 480, 4000)),
                  std::invalid_argument);
  CHECK_THROWS_AS(w.addColor(0, 0, std::vector<std::uint8_t>(640 * 480)), std::invalid_argument);
  w.addColor(1.0, 0, std::vector<std::uint8_t>(640 * 480 * 3));
  CHECK_THROWS_AS(w.addColor(0.5, 0, std::vector<std::uint8_t>(640 * 480 * 3)),
                  std::invalid_argument);
  CHECK_THROWS_AS(w.addColor(std::nan(""), 0, std::vector<std::uint8_t>(640 * 480 * 3)),
                  std::invalid_argument);
  CHECK_THROWS_AS(FakenectRecordingWriter(t.path), FakenectRecordingError);  // not empty
}

TEST_CASE("a truncated frame file is refused naming the file and the sizes", "[drivers][kinect]") {
  TempFolder t("truncated");
  writeTwoFrames(t.path);
  const auto name = indexLines(t.path)[1];  // a colour frame (the depth frames share a file)
  fs::resize_file(t.path / name, 1000);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path),
                    Catch::Contains(name) && Catch::Contains("truncated"));
}

TEST_CASE("a malformed, NaN-timed or missing INDEX entry is refused naming the line",
          "[drivers][kinect]") {
  TempFolder t("malformed");
  writeTwoFrames(t.path);
  auto lines = indexLines(t.path);
  auto bad = lines;
  bad[1] = "x-0.001-2.ppm";
  writeIndex(t.path, bad);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("INDEX.txt:2"));
  bad = lines;
  bad[1] = "r-nan-2.ppm";
  writeIndex(t.path, bad);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("finite"));
  bad = lines;
  bad[1] = "r-0.001-2-gone.ppm";
  writeIndex(t.path, bad);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("missing"));
  bad = lines;
  std::swap(bad[1], bad[2]);
  writeIndex(t.path, bad);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("earlier"));
  bad = lines;
  bad.insert(bad.begin() + 2, "");
  writeIndex(t.path, bad);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("empty line"));
}

TEST_CASE("an empty recording, or one without colour, is refused", "[drivers][kinect]") {
  TempFolder t("empty");
  fs::create_directories(t.path);
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("INDEX.txt"));
  writeIndex(t.path, {});
  CHECK_THROWS_WITH(checkFakenectRecording(t.path), Catch::Contains("both streams"));
  writeTwoFrames(t.path / "sub");
  auto lines = indexLines(t.path / "sub");
  writeIndex(t.path / "sub", {lines[0], lines[2]});
  CHECK_THROWS_WITH(checkFakenectRecording(t.path / "sub"), Catch::Contains("0 colour"));
}

}  // namespace fakenect_recording_test
