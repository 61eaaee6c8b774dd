// `tessera bench marker_detection` end to end on a few frames: the JSON has the documented shape,
// both modes find the marker, the tracking mode answers most frames from its window, a single mode
// can be asked for, and bad options are named. Nothing here depends on the time measured.
#include <nlohmann/json.hpp>

#include <set>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

namespace bench_marker_detection_cli_test {

std::set<std::string> keysOf(const nlohmann::json& j) {
  std::set<std::string> keys;
  for (const auto& [k, v] : j.items()) keys.insert(k);
  return keys;
}

TEST_CASE("bench marker_detection reports both modes as one JSON object",
          "[bench_marker_detection]") {
  const auto dir = tessera::test::scratchDir("bench_marker_detection");
  const auto run = runCli("bench marker_detection --json --frames 40 --repeats 1", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(keysOf(j) == std::set<std::string>{"machine", "frames", "width", "height", "cameras",
                                           "repeats", "seed", "blur_px", "noise_std",
                                           "marker_size_m", "threshold_windows_px", "track_margin",
                                           "opencv_threads", "modes"});
  CHECK(j["frames"] == 40);
  CHECK(j["width"] == 640);
  CHECK(j["height"] == 480);
  CHECK(j["cameras"] == 7);
  CHECK(!j["machine"].get<std::string>().empty());
  REQUIRE(j["modes"].size() == 2);
  const std::set<std::string> keys{"mode",
                                   "frames",
                                   "frames_in_view",
                                   "detected_fraction",
                                   "centre_rms_px",
                                   "corner_rms_px",
                                   "ms_per_frame_median",
                                   "ms_per_frame_p95",
                                   "ms_per_frame_mean",
                                   "false_markers"};
  CHECK(j["modes"][0]["mode"] == "full");
  CHECK(j["modes"][1]["mode"] == "tracking");
  for (const auto& m : j["modes"]) {
    INFO(m.dump());
    std::set<std::string> want = keys;
    if (m["mode"] == "tracking") want.insert("window_fraction");
    CHECK(keysOf(m) == want);
    CHECK(m["frames"] == 40);
    CHECK(m["frames_in_view"].get<int>() >= 30);
    CHECK(m["detected_fraction"].get<double>() >= 0.95);
    CHECK(m["corner_rms_px"].get<double>() < 1.0);
    CHECK(m["centre_rms_px"].get<double>() < 1.0);
    CHECK(m["false_markers"] == 0);
    CHECK(m["ms_per_frame_median"].get<double>() > 0);
    CHECK(m["ms_per_frame_p95"].get<double>() >= m["ms_per_frame_median"].get<double>());
  }
  // Following the robot's drive, most frames are answered from the window around the marker.
  CHECK(j["modes"][1]["window_fraction"].get<double>() > 0.5);
  // Every frame of the full mode shows the whole marker.
  CHECK(j["modes"][0]["frames_in_view"] == 40);
}

TEST_CASE("bench marker_detection runs one mode and prints a table without --json",
          "[bench_marker_detection]") {
  const auto dir = tessera::test::scratchDir("bench_marker_detection_table");
  const auto json = runCli(
      "bench marker_detection --json --frames 10 --repeats 1 --mode full "
      "--window-min 3 --window-max 23",
      dir);
  INFO(json.err);
  REQUIRE(json.exit_code == 0);
  const auto j = nlohmann::json::parse(json.out);
  REQUIRE(j["modes"].size() == 1);
  CHECK(j["modes"][0]["mode"] == "full");
  CHECK(j["threshold_windows_px"] == nlohmann::json::array({3, 23, 10}));
  CHECK(j["modes"][0]["detected_fraction"].get<double>() >= 0.9);

  const auto table = runCli("bench marker_detection --frames 5 --repeats 1 --mode tracking", dir);
  INFO(table.err);
  REQUIRE(table.exit_code == 0);
  CHECK(table.out.find("machine: ") != std::string::npos);
  CHECK(table.out.find("tracking") != std::string::npos);
  CHECK(table.out.find("ms median") != std::string::npos);
}

TEST_CASE("bench marker_detection names a bad option", "[bench_marker_detection]") {
  const auto dir = tessera::test::scratchDir("bench_marker_detection_bad");
  const auto mode = runCli("bench marker_detection --mode sometimes", dir);
  CHECK(mode.exit_code != 0);
  CHECK(mode.err.find("--mode") != std::string::npos);
  const auto frames = runCli("bench marker_detection --frames 0", dir);
  CHECK(frames.exit_code != 0);
  CHECK(frames.err.find("--frames") != std::string::npos);
  const auto window = runCli("bench marker_detection --window-min 1", dir);
  CHECK(window.exit_code != 0);
  CHECK(window.err.find("threshold_window_min_px") != std::string::npos);
}

}  // namespace bench_marker_detection_cli_test
