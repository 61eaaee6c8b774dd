// `tessera launch` end to end: the same outputs as `tessera run`, Ctrl-C, a killed worker
// restarted while the other keeps receiving, and the launcher (with its RouDi) killed.
#include "../../apps/cli_run.hpp"
#include "launch_fixtures.hpp"

#include <tessera/shm/roudi_host.hpp>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using tessera::test::freshDir;
using tessera::test::readFile;
using tessera::test::shmClean;

namespace {

/// `tessera launch ...` in the background, output in dir/launch.txt. Reaps everything it
/// started (the launcher, and workers re-parented to this process) when destroyed.
class Launch {
 public:
  Launch(const std::vector<std::string>& args, const fs::path& dir) : log_(dir / "launch.txt") {
    ::prctl(PR_SET_CHILD_SUBREAPER, 1);  // orphaned workers come back to this process
    pid_ = ::fork();
    if (pid_ == 0) {
      const int fd = ::open(log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(fd, 1);
      ::dup2(fd, 2);
      std::vector<std::string> all = {TESSERA_CLI_PATH, "launch"};
      all.insert(all.end(), args.begin(), args.end());
      std::vector<char*> argv;
      for (auto& s : all) argv.push_back(s.data());
      argv.push_back(nullptr);
      ::execv(TESSERA_CLI_PATH, argv.data());
      ::_exit(127);
    }
  }
  ~Launch() {
    // A failed test must not leave a deployment or its shared memory behind: ask the launcher
    // to stop, then kill what is left and remove what a killed RouDi could not.
    if (pid_ > 0 && !reaped_) {
      ::kill(pid_, SIGTERM);
      if (wait(15s) < 0) ::kill(pid_, SIGKILL);
    }
    // Workers that did not stop by themselves (re-parented here) must not outlive the test.
    if (!reapAll(10s)) {
      killChildren();
      reapAll(10s);
    }
    if (!clean_up_) return;
    try {
      tessera::removeStaleShm();
    } catch (const std::exception&) {
      // another RouDi runs (not ours): leave its memory alone
    }
  }
  pid_t pid() const { return pid_; }
  /// Leaves a killed RouDi's shared memory for the next launch to find.
  void keepLeftovers() { clean_up_ = false; }
  std::string output() const { return readFile(log_); }

  /// Waits until the output matches `pattern`; returns the first capture group (or "").
  std::string waitFor(const std::string& pattern, std::chrono::seconds timeout = 30s) const {
    const std::regex re(pattern);
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      std::smatch m;
      const std::string out = output();
      if (std::regex_search(out, m, re)) return m.size() > 1 ? m[1].str() : std::string("!");
      std::this_thread::sleep_for(20ms);
    }
    return "";
  }
  /// Exit code of the launcher (-1: still running after `timeout`, then killed).
  int wait(std::chrono::seconds timeout = 60s) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) != pid_) {
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        reaped_ = true;
        return -1;
      }
      std::this_thread::sleep_for(10ms);
    }
    reaped_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  /// SIGKILLs every process whose parent is this one.
  static void killChildren() {
    for (const auto& e : fs::directory_iterator("/proc")) {
      const std::string name = e.path().filename().string();
      if (name.find_first_not_of("0123456789") != std::string::npos) continue;
      std::ifstream stat(e.path() / "stat");
      std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
      const auto close = text.rfind(')');  // the command name may hold spaces
      if (close == std::string::npos) continue;
      std::istringstream rest(text.substr(close + 1));
      std::string state;
      pid_t parent = 0;
      rest >> state >> parent;
      if (parent == ::getpid()) ::kill(std::stoi(name), SIGKILL);
    }
  }
  /// Reaps every child of this process; false when some still run after `timeout`.
  static bool reapAll(std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      int status = 0;
      const pid_t r = ::waitpid(-1, &status, WNOHANG);
      if (r < 0) return true;  // no children left
      if (r == 0) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(10ms);
      }
    }
  }

 private:
  fs::path log_;
  pid_t pid_ = -1;
  bool reaped_ = false;
  bool clean_up_ = true;
};

/// Every number of a TUM trajectory file, in order.
std::vector<double> readNumbers(const fs::path& p) {
  std::ifstream in(p);
  std::vector<double> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    for (double v; s >> v;) out.push_back(v);
  }
  return out;
}

}  // namespace

TEST_CASE("a launched profile writes the same outputs as the same profile run in one process",
          "[launch]") {
  const auto dir = freshDir("launch_same");
  const auto run =
      tessera::test::runCli("run sim_mapping --quiet --out " + (dir / "run").string(), dir);
  REQUIRE(run.exit_code == 0);
  Launch launch({"sim_mapping", "--out", (dir / "launch").string()}, dir);
  const int rc = launch.wait(120s);
  INFO(launch.output());
  REQUIRE(rc == 0);
  CHECK(launch.output().find("stopped: all inputs finished") != std::string::npos);
  for (const char* f :
       {"map.pgm", "map.yaml", "trajectory.tum", "odometry.tum", "ground_truth.tum"}) {
    INFO(f);
    REQUIRE(fs::exists(dir / "launch" / f));
    CHECK(readFile(dir / "run" / f) == readFile(dir / "launch" / f));
  }
  const auto summary = nlohmann::json::parse(readFile(dir / "launch" / "summary.json"));
  CHECK(summary["processes"].size() == 2);
  const auto single = nlohmann::json::parse(readFile(dir / "run" / "summary.json"));
  CHECK(summary["actors"]["mapper"]["messages_in"] == single["actors"]["mapper"]["messages_in"]);
  CHECK(shmClean());
}

namespace {

/// Runs sim_slam_global in one process and launched with `sets` (process placement); the map
/// and online trajectory must be identical, the final trajectory equal to 1e-6.
void checkSlamLaunchMatchesOneProcess(const std::string& name,
                                      const std::vector<std::string>& sets) {
  const auto dir = freshDir(name);
  const auto run =
      tessera::test::runCli("run sim_slam_global --quiet --out " + (dir / "run").string(), dir);
  REQUIRE(run.exit_code == 0);
  std::vector<std::string> args = {"sim_slam_global", "--out", (dir / "launch").string()};
  for (const auto& s : sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  Launch launch(args, dir);
  const int rc = launch.wait(180s);
  INFO(launch.output());
  REQUIRE(rc == 0);
  CHECK(launch.output().find("stopped: all inputs finished") != std::string::npos);
  for (const char* f : {"map.pgm", "trajectory.tum"}) {
    INFO(f);
    REQUIRE(fs::exists(dir / "launch" / f));
    CHECK(readFile(dir / "run" / f) == readFile(dir / "launch" / f));
  }
  // The optimiser may see the loop constraints in another interleaving with the submaps (they
  // come from two processes) and so take other warm-started steps to the same optimum.
  const auto single = readNumbers(dir / "run" / "trajectory_final.tum");
  const auto multi = readNumbers(dir / "launch" / "trajectory_final.tum");
  REQUIRE(single.size() == multi.size());
  REQUIRE(single.size() > 1000);
  double worst = 0;
  for (std::size_t i = 0; i < single.size(); ++i)
    worst = std::max(worst, std::abs(single[i] - multi[i]));
  CHECK(worst < 1e-6);
  CHECK(shmClean());
}

}  // namespace

TEST_CASE("laser SLAM split over three processes gives the same trajectories and map as one",
          "[launch][slow]") {
  // Submaps, constraints and the final poses published in stop() cross processes; the
  // optimiser's stop-time output must still reach the writer in the last process.
  checkSlamLaunchMatchesOneProcess(
      "launch_slam", {"sim.process=robot", "loops.process=global", "optimizer.process=global",
                      "assembler.process=global", "map_writer.process=global",
                      "final_trajectory_writer.process=global"});
}

TEST_CASE(
    "laser SLAM with the map and trajectory writers beside the builder gives the same outputs",
    "[launch][slow]") {
  // The README split: main both sends and reads back submaps, poses and constraints, and reads
  // the optimiser's poses from global through a keep_latest queue (whose discards must still
  // count as received, or the clock stalls); the optimiser's stop-time output must reach the
  // writers in main, which stop after it although main's builder stops before global.
  checkSlamLaunchMatchesOneProcess("launch_slam_main", {"sim.process=robot", "loops.process=global",
                                                        "optimizer.process=global"});
}

TEST_CASE("Ctrl-C stops a launched deployment cleanly and its outputs are written", "[launch]") {
  const auto dir = freshDir("launch_interrupt");
  Launch launch({"sim_mapping", "--out", (dir / "out").string(), "--set", "sim_rate=2"}, dir);
  REQUIRE(!launch.waitFor(R"(the run starts)").empty());
  std::this_thread::sleep_for(1500ms);
  ::kill(launch.pid(), SIGINT);
  const int rc = launch.wait(60s);
  INFO(launch.output());
  CHECK(rc == 130);
  CHECK(launch.output().find("stopped: interrupted") != std::string::npos);
  CHECK(fs::exists(dir / "out" / "map.pgm"));
  CHECK(Launch::reapAll(10s));
  CHECK(shmClean());
}

namespace {
const std::string kWallMapping = tessera::test::wallMappingProfile("restart: [robot]");

/// Lets a launched kWallMapping run for `run_for`, kills its robot process with SIGKILL and
/// waits until the launcher restarts it.
void killRobotAndAwaitRestart(Launch& launch, std::chrono::milliseconds run_for) {
  const std::string robot = launch.waitFor(R"(started 'robot' \(pid (\d+)\))");
  REQUIRE(!robot.empty());
  // Run for a while from the start of the run, not of the processes (which can take seconds
  // on a loaded machine).
  REQUIRE(!launch.waitFor(R"(the run starts)").empty());
  std::this_thread::sleep_for(run_for);
  ::kill(std::stoi(robot), SIGKILL);
  CHECK(!launch.waitFor(R"(process 'robot' \(pid \d+\) was killed by SIGKILL)", 10s).empty());
  REQUIRE(!launch.waitFor(R"(restarting 'robot')", 10s).empty());
}
}  // namespace

TEST_CASE("a killed worker is reported and restarted while the other process keeps receiving",
          "[launch]") {
  const auto dir = freshDir("launch_restart");
  std::ofstream(dir / "wall.yaml") << kWallMapping;
  Launch launch({(dir / "wall.yaml").string(), "--out", (dir / "out").string()}, dir);
  killRobotAndAwaitRestart(launch, 1500ms);
  std::this_thread::sleep_for(2500ms);
  ::kill(launch.pid(), SIGINT);
  const int rc = launch.wait(60s);
  INFO(launch.output());
  CHECK(rc == 130);
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  CHECK(summary["processes"]["robot"]["restarts"] == 1);
  CHECK(summary["processes"]["mapping"]["restarts"] == 0);
  // About 15 scans before the kill; more arrived only from the restarted robot.
  CHECK(summary["actors"]["mapper"]["messages_in"].get<int>() > 25);
  CHECK(fs::exists(dir / "out" / "map.pgm"));
  CHECK(shmClean());
}

TEST_CASE("Ctrl-C while a restarted process is still starting stops the deployment", "[launch]") {
  // The new robot finds the run already stopping and leaves without running: the launcher must
  // not wait for its stop stage.
  const auto dir = freshDir("launch_restart_interrupt");
  std::ofstream(dir / "wall.yaml") << kWallMapping;
  Launch launch({(dir / "wall.yaml").string(), "--out", (dir / "out").string()}, dir);
  killRobotAndAwaitRestart(launch, 1000ms);
  ::kill(launch.pid(), SIGINT);
  const int rc = launch.wait(60s);
  INFO(launch.output());
  CHECK(rc == 130);
  CHECK(fs::exists(dir / "out" / "map.pgm"));
  CHECK(shmClean());
}

TEST_CASE("a process still waiting for its peers leaves at once when the deployment stops",
          "[launch]") {
  // The mapping process is frozen before it subscribes, so the robot waits for a subscriber that
  // never comes. Killing the mapping stops the run: the robot must notice instead of sitting out
  // its 30 s connection timeout.
  const auto dir = freshDir("launch_peer_wait");
  std::ofstream(dir / "wall.yaml") << kWallMapping;
  Launch launch({(dir / "wall.yaml").string()}, dir);
  const std::string mapping = launch.waitFor(R"(started 'mapping' \(pid (\d+)\))");
  REQUIRE(!mapping.empty());
  ::kill(std::stoi(mapping), SIGSTOP);
  std::this_thread::sleep_for(1500ms);
  ::kill(std::stoi(mapping), SIGKILL);
  const auto killed = std::chrono::steady_clock::now();
  const int rc = launch.wait(60s);
  const auto took = std::chrono::steady_clock::now() - killed;
  INFO(launch.output());
  CHECK(rc == 1);
  CHECK(took < 10s);
  CHECK(launch.output().find("process 'mapping' (pid " + mapping + ") was killed by SIGKILL") !=
        std::string::npos);
  CHECK(Launch::reapAll(10s));
  CHECK(shmClean());
}

TEST_CASE("when the launcher and its RouDi die the workers stop and the next launch cleans up",
          "[launch]") {
  const auto dir = freshDir("launch_roudi_death");
  {
    Launch launch({"sim_mapping", "--set", "sim_rate=1", "--out", (dir / "out").string()}, dir);
    launch.keepLeftovers();
    const std::string robot = launch.waitFor(R"(started 'robot' \(pid (\d+)\))");
    const std::string mapping = launch.waitFor(R"(started 'mapping' \(pid (\d+)\))");
    REQUIRE(!robot.empty());
    REQUIRE(!mapping.empty());
    REQUIRE(!launch.waitFor(R"(the run starts)").empty());
    std::this_thread::sleep_for(1000ms);
    ::kill(launch.pid(), SIGKILL);
    CHECK(launch.wait(10s) == 128 + SIGKILL);
    // The workers notice (parent-death signal, re-parenting) and exit by themselves.
    CHECK(Launch::reapAll(15s));
    CHECK(::kill(std::stoi(robot), 0) != 0);
    CHECK(::kill(std::stoi(mapping), 0) != 0);
    // What they held was written whole (their output pipe to the dead launcher is broken: a
    // write to it must not kill them before they finish), and no temporary file is left.
    CHECK(fs::exists(dir / "out" / "map.pgm"));
    CHECK(fs::exists(dir / "out" / "trajectory.tum"));
    for (const auto& e : fs::directory_iterator(dir / "out")) {
      CHECK(e.path().filename().string().find(".tmp.") == std::string::npos);
    }
  }
  CHECK_FALSE(shmClean());  // RouDi had no chance to remove its shared memory
  const auto again = freshDir("launch_roudi_death_again");
  Launch launch({"sim_mapping", "--set", "max_duration_s=20"}, again);
  const int rc = launch.wait(60s);
  INFO(launch.output());
  CHECK(rc == 0);
  CHECK(
      launch.output().find("removed stale shared memory of a crashed run: /dev/shm/iceoryx_mgmt") !=
      std::string::npos);
  CHECK(shmClean());
}

namespace {
/// A wall-clock profile of two processes: the simulator in 'robot' sends `hz` ground-truth
/// poses a second over a reliable topic to a trajectory writer in 'writer'.
std::string poseWriterProfile(int hz) {
  return R"(name: pose_writer
clock: wall
actors:
  sim:
    type: simulator
    process: robot
    params: {world: builtin:office, laps: 1, scan_hz: 10, step_hz: )" +
         std::to_string(hz) + ", odom_hz: " + std::to_string(hz) + R"(}
  writer:
    type: trajectory_writer
    process: writer
    remap: {poses: ground_truth}
)";
}
}  // namespace

TEST_CASE("a worker blocked sending to a dead peer leaves within its grace after the launcher dies",
          "[launch]") {
  // The writer stops taking poses (frozen), so the robot's reliable publisher waits for room in
  // its queue; then the launcher, with RouDi, and the writer die. Only RouDi could remove the
  // dead writer's full queue: the robot's send never returns, and only its grace ends it.
  const auto dir = freshDir("launch_orphan_blocked");
  std::ofstream(dir / "writer.yaml") << poseWriterProfile(200);
  Launch launch({(dir / "writer.yaml").string(), "--orphan-grace", "2"}, dir);
  launch.keepLeftovers();
  const std::string robot = launch.waitFor(R"(started 'robot' \(pid (\d+)\))");
  const std::string writer = launch.waitFor(R"(started 'writer' \(pid (\d+)\))");
  REQUIRE(!robot.empty());
  REQUIRE(!writer.empty());
  REQUIRE(!launch.waitFor(R"(the run starts)").empty());
  ::kill(std::stoi(writer), SIGSTOP);
  // 200 poses a second fill the writer's queue (64) within 0.35 s. Not much longer: RouDi takes
  // a process that sent no heartbeat for 1.5 s for dead and removes its queue.
  std::this_thread::sleep_for(800ms);
  ::kill(launch.pid(), SIGKILL);
  CHECK(launch.wait(10s) == 128 + SIGKILL);
  ::kill(std::stoi(writer), SIGKILL);
  const auto killed = std::chrono::steady_clock::now();
  CHECK(Launch::reapAll(20s));
  CHECK(std::chrono::steady_clock::now() - killed < 15s);
  CHECK(::kill(std::stoi(robot), 0) != 0);
  tessera::removeStaleShm();
}

TEST_CASE(
    "a worker frozen longer than RouDi's keep-alive keeps its topics and the run stops cleanly",
    "[launch]") {
  // A stopped process (SIGSTOP, a debugger's breakpoint, swapping) sends RouDi no heartbeat, but
  // it is alive: its queues must stay, the reliable poses must wait for it, and Ctrl-C must stop
  // the deployment once it runs again. RouDi's own monitor took it for dead after 1.5 s.
  const auto dir = freshDir("launch_frozen_worker");
  std::ofstream(dir / "writer.yaml") << poseWriterProfile(100);
  Launch launch({(dir / "writer.yaml").string(), "--out", (dir / "out").string()}, dir);
  const std::string writer = launch.waitFor(R"(started 'writer' \(pid (\d+)\))");
  REQUIRE(!writer.empty());
  REQUIRE(!launch.waitFor(R"(the run starts)").empty());
  std::this_thread::sleep_for(500ms);
  ::kill(std::stoi(writer), SIGSTOP);
  std::this_thread::sleep_for(3500ms);  // more than twice RouDi's 1.5 s keep-alive
  ::kill(std::stoi(writer), SIGCONT);
  std::this_thread::sleep_for(1000ms);
  ::kill(launch.pid(), SIGINT);
  const int rc = launch.wait(30s);
  INFO(launch.output());
  CHECK(rc == 130);
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  REQUIRE(summary["delivery"].size() == 1);
  const auto& poses = summary["delivery"][0];
  CHECK(poses["topic"] == "ground_truth");
  // 0.5 s before the freeze and 1 s after it at 100 Hz, plus the 64 the writer's queue held
  // while the robot waited for room: it ran on after the freeze.
  CHECK(poses["sent"].get<int>() > 150);
  CHECK(poses["lost_live"] == 0);
  CHECK(poses["received"] == poses["sent"]);
  CHECK(poses["dead"].empty());
  CHECK(readNumbers(dir / "out" / "trajectory.tum").size() == 8 * poses["received"].get<size_t>());
  CHECK(Launch::reapAll(10s));
  CHECK(shmClean());
}

TEST_CASE("tessera goal without a running deployment fails at once instead of waiting",
          "[launch][goal]") {
  const auto dir = freshDir("goal_no_deployment");
  REQUIRE_FALSE(tessera::rouDiRunning());  // the shm tests run one at a time
  const auto start = std::chrono::steady_clock::now();
  const auto run = tessera::test::runCli("goal 1 2 0 --wait", dir);
  const auto took = std::chrono::steady_clock::now() - start;
  INFO(run.err);
  CHECK(run.exit_code == 3);
  CHECK(run.err.find("no deployment runs on this machine") != std::string::npos);
  CHECK(took < 10s);  // not iceoryx's minute-long wait for a RouDi
  CHECK(shmClean());
}

namespace {
/// The robot (simulator following cmd_vel, true map) and the navigator (ground-truth poses) in two
/// processes; goals only from outside. Simulated time at twice real time.
const char* kGoalProfile = R"(name: goal_nav
clock: sim
sim_rate: 2
external: {inputs: [goal], outputs: [nav_status]}
actors:
  sim:
    type: simulator
    process: robot
    params: {world: builtin:office, drive: commands, command_timeout_s: 0.5, scan_hz: 10,
             odom_hz: 50, seed: 3}
  world:
    type: world_writer
    process: robot
    params: {world: builtin:office, walls_file: "", publish_map: true, map_period_s: 3600}
  nav:
    type: navigator
    process: nav
    remap: {pose: ground_truth}
    params: {pose_message: ground_truth}
)";
}  // namespace

TEST_CASE("tessera goal reaches a launched navigator and --wait ends with the goal's final state",
          "[launch][goal]") {
  const auto dir = freshDir("goal_launch");
  std::ofstream(dir / "goal_nav.yaml") << kGoalProfile;
  Launch launch({(dir / "goal_nav.yaml").string(), "--out", (dir / "out").string()}, dir);
  REQUIRE(!launch.waitFor(R"(started 'nav')").empty());

  // A reachable goal 1.5 m ahead of the start (7.5, 7.5): planning, driving, reached.
  const auto reached = tessera::test::runCli("goal 9 7.5 0 --id 7 --wait --timeout 30", dir);
  INFO(reached.out + reached.err);
  CHECK(reached.exit_code == 0);
  CHECK(reached.out.find("goal 7 sent on 'goal'") != std::string::npos);
  CHECK(reached.out.find("goal 7: driving") != std::string::npos);
  CHECK(reached.out.find("goal 7: reached") != std::string::npos);

  // Off the map (negative coordinates are numbers, not options): refused, with the reason.
  const auto refused = tessera::test::runCli("goal -50 -50 0 --id 8 --wait --timeout 30", dir);
  INFO(refused.out + refused.err);
  CHECK(refused.exit_code == 1);
  CHECK(refused.out.find("goal 8: refused: ") != std::string::npos);

  // In another frame: the navigator refuses it too.
  const auto frame = tessera::test::runCli("goal 9 7.5 0 --id 9 --frame odom --wait", dir);
  INFO(frame.out + frame.err);
  CHECK(frame.exit_code == 1);
  CHECK(frame.out.find("goal 9: refused: goal in frame 'odom'") != std::string::npos);

  // A topic nobody in the deployment reads: a clear error after the connect wait, not a hang.
  const auto nowhere = tessera::test::runCli("goal 9 7.5 0 --topic nowhere", dir);
  INFO(nowhere.err);
  CHECK(nowhere.exit_code == 3);
  CHECK(nowhere.err.find("'nowhere' (no subscriber)") != std::string::npos);

  // Without finite inputs the deployment runs until stopped: SIGTERM stops it cleanly.
  ::kill(launch.pid(), SIGTERM);
  const int rc = launch.wait(60s);
  INFO(launch.output());
  CHECK(rc == 130);
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  CHECK(summary["actors"]["nav"]["goals"] == 3);
  CHECK(summary["actors"]["nav"]["reached"] == 1);
  CHECK(summary["actors"]["nav"]["refused"] == 2);
  CHECK(Launch::reapAll(10s));
  CHECK(shmClean());
}

TEST_CASE("launch --view serves the live viewer from its own process with every process's topics",
          "[launch][viewer]") {
  const auto dir = freshDir("view_launch");
  std::ofstream(dir / "goal_nav.yaml") << kGoalProfile;
  Launch launch({(dir / "goal_nav.yaml").string(), "--view", "0", "--out", (dir / "out").string()},
                dir);
  const std::string port = launch.waitFor(R"(live view: http://127\.0\.0\.1:([0-9]+)/)");
  INFO(launch.output());
  REQUIRE_FALSE(port.empty());
  REQUIRE(!launch.waitFor(R"(started 'nav')").empty());
  const auto topics = tessera::test::runCli("topics --port " + port, dir);
  INFO(topics.out + topics.err);
  CHECK(topics.exit_code == 0);
  CHECK(topics.out.find("nav_status") != std::string::npos);  // from the nav process
  CHECK(topics.out.find("scan") != std::string::npos);        // from the robot process
  const auto pose =
      tessera::test::runCli("echo ground_truth -n 1 --timeout 20 --port " + port, dir);
  INFO(pose.err);
  CHECK(pose.exit_code == 0);
  CHECK(nlohmann::json::parse(pose.out)["pose"]["position"]["x"].is_number());
  ::kill(launch.pid(), SIGTERM);
  CHECK(launch.wait(60s) == 130);
  CHECK(fs::exists(dir / "out" / "summary_viewer.json"));
  CHECK(Launch::reapAll(10s));
  CHECK(shmClean());
  // The profile copy with the viewer (it may hold a token) is gone.
  int copies = 0;
  for (const auto& e : fs::directory_iterator(fs::temp_directory_path()))
    copies += e.path().filename().string().rfind("tessera_launch_view_", 0) == 0;
  CHECK(copies == 0);
}
