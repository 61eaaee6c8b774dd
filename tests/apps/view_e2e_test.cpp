// The live viewer as a user meets it: `tessera record sim_slam_global --view 0` runs the
// two-level SLAM with the viewer on a free port, headless Chromium (Debian's chromium, driven by
// playwright-core: tests/js/viewer_e2e.mjs) opens the page, waits for map tiles, the robot and
// its trajectory, checks the layer toggles, clicks a goal and saves a screenshot. Then the run is
// stopped with Ctrl-C and what the browser showed is compared with what the run wrote: the
// robot's pose against trajectory.tum at the same stamp, and the clicked goal on the goal topic
// (recorded by the same command). Foxglove's own client (@foxglove/ws-protocol,
// tests/js/foxglove_check.mjs) then subscribes to the same server and its decoded scan, map,
// pose, transforms and metrics are compared with the run too.
#include <tessera/mapping/trajectory_io.hpp>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <thread>

#include "cli_child.hpp"
#include "cli_run.hpp"

// Everything in a namespace of its own: unity builds put test files together.
namespace view_e2e_test {

namespace fs = std::filesystem;
using tessera::test::fileText;

namespace {

void skipOrFail(const std::string& why) {
  const char* ci = std::getenv("CI");
  if (ci && std::string(ci) == "true") FAIL("the viewer test needs a browser: " << why);
  WARN("SKIPPED: npm " << why);
}

// Why the browser test cannot run here, or "".
std::string missingBrowser(const fs::path& js) {
  for (const char* package : {"playwright-core", "@foxglove/ws-protocol", "ws"})
    if (!fs::exists(js / "node_modules" / package))
      return std::string("no ") + package + " in " + (js / "node_modules").string() +
             " (run scripts/js_deps.sh)";
  if (std::system("node --version > /dev/null 2>&1") != 0) return "no node on PATH";
  const char* chromium = std::getenv("CHROMIUM");
  if (!fs::exists(chromium ? chromium : "/usr/bin/chromium"))
    return "no /usr/bin/chromium (apt-get install chromium)";
  return "";
}

using tessera::mapping::TumPose;

// The pose of a TUM trajectory closest in time to `stamp_ns`.
const TumPose& nearest(const std::vector<TumPose>& trajectory, double stamp_ns) {
  REQUIRE_FALSE(trajectory.empty());
  return *std::min_element(trajectory.begin(), trajectory.end(), [&](const auto& a, const auto& b) {
    return std::abs(static_cast<double>(a.stamp_ns) - stamp_ns) <
           std::abs(static_cast<double>(b.stamp_ns) - stamp_ns);
  });
}

// Within 1 ms of `stamp_ns` and 0.1 m of (x, y): the same estimate.
void checkOnTrajectory(const std::vector<TumPose>& trajectory, double stamp_ns, double x,
                       double y) {
  const TumPose& near = nearest(trajectory, stamp_ns);
  CHECK(std::abs(static_cast<double>(near.stamp_ns) - stamp_ns) < 1e6);
  CHECK(std::hypot(near.position.x() - x, near.position.y() - y) < 0.1);
}

}  // namespace

TEST_CASE("a browser and Foxglove's client watch sim_slam_global live; the browser sends a goal",
          "[viewer][e2e]") {
  const fs::path js = fs::path(TESSERA_SOURCE_DIR) / "tests" / "js";
  if (const std::string why = missingBrowser(js); !why.empty()) {
    skipOrFail(why);
    return;
  }
  const fs::path dir = fs::temp_directory_path() / "tessera_view_e2e";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path err = dir / "stderr.txt";
  // Four times real time: a map within seconds, still slow enough to watch.
  tessera::test::CliChild run("record sim_slam_global --view 0 --rate 4 --topics goal --out " +
                                  (dir / "goal.trec").string() + " --dir " + (dir / "out").string(),
                              err);
  const std::string url = tessera::test::waitForViewerUrl(err);
  INFO(fileText(err));
  REQUIRE_FALSE(url.empty());

  const fs::path result = dir / "result.json";
  const std::string cmd = "node " + (js / "viewer_e2e.mjs").string() + " --url " + url +
                          " --goal 2.5,1.5 --screenshot " + (dir / "viewer.png").string() +
                          " --out " + result.string() + " --timeout-s 120 > " +
                          (dir / "e2e.log").string() + " 2>&1";
  const int e2e = std::system(cmd.c_str());
  // Then Foxglove's own client on the same server, as Foxglove Studio would connect.
  const std::string ws = "ws://" + url.substr(7, url.size() - 8);
  const std::string fcmd = "node " + (js / "foxglove_check.mjs").string() + " " + ws +
                           " --timeout-s 60 > " + (dir / "foxglove.json").string() + " 2> " +
                           (dir / "foxglove.err").string();
  const int foxglove = std::system(fcmd.c_str());
  const int stopped = run.interrupt();
  INFO(fileText(dir / "foxglove.err"));
  INFO(fileText(dir / "e2e.log"));
  INFO(fileText(err));
  REQUIRE(e2e == 0);
  REQUIRE(foxglove == 0);
  CHECK(stopped == 130);  // stopped by Ctrl-C, outputs written
  const auto r = nlohmann::json::parse(fileText(result));
  CHECK(r["ok"] == true);
  CHECK(r["errors"].empty());
  CHECK(r["tiles"].get<int>() > 0);
  for (const char* topic : {"map/tiles", "scan", "pose", "tf"})
    CHECK(std::find(r["topics"].begin(), r["topics"].end(), topic) != r["topics"].end());

  // The robot the page drew is the run's estimate at that stamp.
  const auto traj = tessera::mapping::readTum(dir / "out" / "trajectory.tum");
  checkOnTrajectory(traj, r["robot"]["stampNs"].get<double>(), r["robot"]["x"].get<double>(),
                    r["robot"]["y"].get<double>());

  // The clicked goal arrived on the goal topic: one message, recorded.
  CHECK(std::abs(r["goalSent"]["x"].get<double>() - 2.5) < 0.05);
  const auto info =
      tessera::test::runCli("replay " + (dir / "goal.trec").string() + " --info", dir);
  INFO(info.out);
  CHECK(std::regex_search(info.out, std::regex(R"(goal\b.*\b1 message)")));

  // What Foxglove's client decoded matches the run.
  const auto f = nlohmann::json::parse(fileText(dir / "foxglove.json"));
  CHECK(f["server"]["name"] == "tessera");
  CHECK(f["decoded"]["scan"]["ranges"].get<int>() > 100);
  CHECK(f["decoded"]["scan"]["finite"].get<int>() > 0);
  CHECK(f["decoded"]["map"]["cell_size"]["x"].get<double>() == Approx(0.05));
  CHECK(f["decoded"]["map"]["fields"] == nlohmann::json::array({"occupancy"}));
  CHECK(f["decoded"]["map"]["rows"].get<double>() > 10);
  const auto& fp = f["decoded"]["pose"];
  checkOnTrajectory(traj, fp["stamp_ns"].get<double>(), fp["x"].get<double>(),
                    fp["y"].get<double>());
  const auto actors = f["decoded"]["tessera/metrics"]["actors"];
  CHECK(std::find(actors.begin(), actors.end(), "slam") != actors.end());

  const auto summary = nlohmann::json::parse(fileText(dir / "out" / "summary.json"));
  CHECK(summary["actors"]["viewer"]["goals"] == 1);
  CHECK(summary["actors"]["viewer"]["clients_total"].get<int>() >= 1);
}

TEST_CASE("an initial pose placed in the browser restarts the localiser, which keeps its track",
          "[viewer][e2e]") {
  const fs::path js = fs::path(TESSERA_SOURCE_DIR) / "tests" / "js";
  if (const std::string why = missingBrowser(js); !why.empty()) {
    skipOrFail(why);
    return;
  }
  const fs::path dir = fs::temp_directory_path() / "tessera_view_mcl";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path err = dir / "stderr.txt";
  // sim_nav: the world's map, MCL, the navigator driving a goal sequence.
  tessera::test::CliChild run(
      // Twice real time: the robot moves ~1 m per wall second, so the pose the page places (read
      // when the tool is picked, dragged along the heading) is a few centimetres old on arrival.
      "run sim_nav --view 0 --rate 2 --quiet --out " + (dir / "out").string(), err);
  const std::string url = tessera::test::waitForViewerUrl(err);
  INFO(fileText(err));
  REQUIRE_FALSE(url.empty());
  const std::string cmd = "node " + (js / "viewer_e2e.mjs").string() + " --url " + url +
                          " --initial-pose robot --need map,robot,costmap,local_plan" +
                          " --screenshot " + (dir / "viewer.png").string() + " --out " +
                          (dir / "result.json").string() + " --timeout-s 120 > " +
                          (dir / "e2e.log").string() + " 2>&1";
  const int e2e = std::system(cmd.c_str());
  // Some more driving after the restart before stopping.
  std::this_thread::sleep_for(std::chrono::seconds(5));
  const int stopped = run.interrupt();
  INFO(fileText(dir / "e2e.log"));
  REQUIRE(e2e == 0);
  CHECK(stopped == 130);
  const auto r = nlohmann::json::parse(fileText(dir / "result.json"));
  REQUIRE_FALSE(r["initialPoseSent"].is_null());
  const auto summary = nlohmann::json::parse(fileText(dir / "out" / "summary.json"));
  CHECK(summary["actors"]["viewer"]["initial_poses"] == 1);
  CHECK(summary["actors"]["mcl"]["initial_poses"] == 1);
  // Restarted where the page drew the robot, MCL still follows the truth at the end.
  const auto estimate = tessera::mapping::readTum(dir / "out" / "trajectory.tum");
  const auto truth = tessera::mapping::readTum(dir / "out" / "ground_truth.tum");
  REQUIRE(estimate.size() > 10);
  const TumPose& last = estimate.back();
  const TumPose& near = nearest(truth, static_cast<double>(last.stamp_ns));
  CHECK((near.position - last.position).head<2>().norm() < 0.3);
}

// Runs `tessera run PROFILE --view 0 ARGS` and the browser check with `need`; returns what the
// page saw (result.json), the run stopped with Ctrl-C.
nlohmann::json watch(const std::string& profile, const std::string& args, const std::string& need,
                     const fs::path& dir) {
  const fs::path js = fs::path(TESSERA_SOURCE_DIR) / "tests" / "js";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path err = dir / "stderr.txt";
  tessera::test::CliChild run(
      "run " + profile + " --view 0 --quiet " + args + " --out " + (dir / "out").string(), err);
  const std::string url = tessera::test::waitForViewerUrl(err);
  INFO(fileText(err));
  REQUIRE_FALSE(url.empty());
  const std::string cmd = "node " + (js / "viewer_e2e.mjs").string() + " --url " + url +
                          " --need " + need + " --screenshot " + (dir / "viewer.png").string() +
                          " --out " + (dir / "result.json").string() + " --timeout-s 120 > " +
                          (dir / "e2e.log").string() + " 2>&1";
  const int e2e = std::system(cmd.c_str());
  const int stopped = run.interrupt();
  INFO(fileText(dir / "e2e.log"));
  REQUIRE(e2e == 0);
  CHECK(stopped == 130);
  return nlohmann::json::parse(fileText(dir / "result.json"));
}

TEST_CASE("the browser draws the camera network's footprints and the RGB-D SLAM's 3D map",
          "[viewer][e2e]") {
  const fs::path js = fs::path(TESSERA_SOURCE_DIR) / "tests" / "js";
  if (const std::string why = missingBrowser(js); !why.empty()) {
    skipOrFail(why);
    return;
  }
  const fs::path cameras_dir = fs::temp_directory_path() / "tessera_view_cameras";
  const auto cameras = watch("sim_camera_network", "--rate 8", "map,cameras", cameras_dir);
  // Every camera of the run's cameras file (one line per camera after the comments).
  std::ifstream list(cameras_dir / "out" / "cameras.txt");
  int listed = 0;
  for (std::string line; std::getline(list, line);)
    if (!line.empty() && line[0] != '#') ++listed;
  CHECK(listed == 7);
  CHECK(cameras["scenes"]["camera_footprints"]["entities"] == listed);
  CHECK(cameras["scenes"]["camera_footprints"]["lines"] == listed);

  // The 3D map as the mapper holds it: voxel centres on its 5 cm OctoMap lattice.
  const auto rgbd = watch("sim_rgbd", "", "cloud", fs::temp_directory_path() / "tessera_view_rgbd");
  CHECK(rgbd["cloudPoints"].get<int>() > 1000);
  CHECK(rgbd["cloudVoxel"].get<double>() == Approx(0.05).margin(1e-4));
  CHECK(rgbd["messages"]["map_cloud"].get<int>() >= 1);
}

}  // namespace view_e2e_test
