// End to end: the seed 000 / 001 / 004 scenario profiles write the files later SLAM issues are
// scored with (the camera network run is cut to 300 simulated seconds).
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/profile.hpp>

#include <catch2/catch.hpp>

#include "../shared_data.hpp"
#include "run_profile.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace tessera;
using test::runProfile;
namespace fs = std::filesystem;

namespace {

// Data lines (not '#' comments, not the CSV header) of a text file, split on spaces or commas.
std::vector<std::vector<double>> rows(const fs::path& path, bool csv_header) {
  std::ifstream in(path);
  std::vector<std::vector<double>> out;
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (csv_header && first) {
      first = false;
      continue;
    }
    for (char& c : line)
      if (c == ',') c = ' ';
    std::istringstream s(line);
    std::vector<double> row;
    double v;
    while (s >> v) row.push_back(v);
    out.push_back(row);
  }
  return out;
}

}  // namespace

TEST_CASE("sim_camera_network writes trajectories, camera logs and camera truth", "[e2e]") {
  const fs::path out = test::scratchDir("e2e_sim_camera_network");
  const RunReport report = runProfile("sim_camera_network", out, {"max_duration_s=300"});
  CHECK(report.stop_reason == "reached max_duration_s");
  for (const auto& a : report.actors) CHECK(a.drops == 0);
  for (const char* f : {"ground_truth.tum", "odometry.tum", "camera_detections.csv",
                        "camera_events.csv", "cameras.txt", "map.yaml", "map.png"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  CHECK(tessera::mapping::readTum(out / "ground_truth.tum").size() > 10000);
  CHECK(tessera::mapping::readTum(out / "odometry.tum").size() > 10000);
  const auto det = rows(out / "camera_detections.csv", true);
  const auto ev = rows(out / "camera_events.csv", true);
  REQUIRE(ev.size() >= 2);  // under camera 0 at the start, then on to camera 1
  CHECK(ev[0][1] == 0);
  CHECK(ev[0][2] == 1);
  REQUIRE(det.size() > 100);
  for (const auto& r : det) REQUIRE(r.size() == 6);
  CHECK(rows(out / "cameras.txt", false).size() == 7);
  fs::remove_all(out);
}

TEST_CASE("sim_room writes trajectories, a map and the true walls", "[e2e]") {
  const fs::path out = test::scratchDir("e2e_sim_room");
  const RunReport report = runProfile("sim_room", out);
  CHECK(report.stop_reason == "all inputs finished");
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  REQUIRE(truth.size() > 1000);
  double length = 0;
  for (std::size_t i = 1; i < truth.size(); ++i)
    length += (truth[i].position - truth[i - 1].position).norm();
  CHECK(length == Approx(15).margin(0.5));
  CHECK(report.sim_duration_s > 15 / 0.4);
  CHECK(tessera::mapping::readTum(out / "odometry.tum").size() == truth.size());
  const auto walls = rows(out / "walls.txt", false);
  CHECK(walls.size() == 23);
  for (const auto& w : walls) CHECK(w.size() == 4);
  const auto map = tessera::mapping::loadMap(out / "map.yaml");
  CHECK(map.resolution == Approx(0.05));
  fs::remove_all(out);
}

TEST_CASE("sim_landmarks writes trajectories, true landmarks, observations and controls", "[e2e]") {
  const fs::path out = test::scratchDir("e2e_sim_landmarks");
  const RunReport report = runProfile("sim_landmarks", out);
  CHECK(report.stop_reason == "all inputs finished");
  const auto lms = rows(out / "landmarks_truth.txt", false);
  REQUIRE(lms.size() == 27);
  for (std::size_t i = 0; i < lms.size(); ++i) {
    REQUIRE(lms[i].size() == 3);
    CHECK(lms[i][0] == static_cast<double>(i));
  }
  const auto truth = tessera::mapping::readTum(out / "ground_truth.tum");
  const auto odom = tessera::mapping::readTum(out / "odometry.tum");
  REQUIRE(truth.size() > 3000);
  REQUIRE(odom.size() == truth.size());
  CHECK((truth.back().position - odom.back().position).norm() > 0.5);  // noisy controls drift
  const auto obs = rows(out / "landmark_observations.csv", true);
  const auto ctl = rows(out / "controls.csv", true);
  CHECK(obs.size() > 500);
  CHECK(ctl.size() == truth.size() - 1);
  fs::remove_all(out);
}
