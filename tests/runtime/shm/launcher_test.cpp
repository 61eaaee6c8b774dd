// Launcher driven directly (no CLI in front): a clean run, a worker that dies and is restarted,
// one that dies without a restart entry, and a profile rejected before anything starts. Workers
// are the built CLI's `tessera worker`, or a shell script in front of it that makes chosen
// processes fail.
#include "launch_fixtures.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/shm/launcher.hpp>
#include <tessera/shm/roudi_host.hpp>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using tessera::Launcher;
using tessera::LauncherOptions;
using tessera::LaunchResult;
using tessera::test::freshDir;
using tessera::test::readFile;
using tessera::test::shmClean;

namespace {

/// Every line the launcher logs, readable from another thread while it runs.
class Lines {
 public:
  std::function<void(const std::string&)> sink() {
    return [this](const std::string& line) {
      {
        std::lock_guard lock(mutex_);
        text_ += line + "\n";
      }
      changed_.notify_all();
    };
  }
  std::string text() const {
    std::lock_guard lock(mutex_);
    return text_;
  }
  /// Waits until the log matches `pattern` (at least `count` times); returns the last match's
  /// first group ("" on timeout).
  std::string waitFor(const std::string& pattern, int count = 1,
                      std::chrono::seconds timeout = 30s) const {
    const std::regex re(pattern);
    std::unique_lock lock(mutex_);
    std::string found;
    changed_.wait_for(lock, timeout, [&] {
      int n = 0;
      for (auto it = std::sregex_iterator(text_.begin(), text_.end(), re);
           it != std::sregex_iterator(); ++it) {
        found = it->size() > 1 ? (*it)[1].str() : std::string("!");
        ++n;
      }
      return n >= count;
    });
    return found;
  }

 private:
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  std::string text_;
};

/// Launcher options for the built CLI's workers, logging into `lines`, without signal handlers
/// (the test process keeps its own).
LauncherOptions cliWorkers(const fs::path& profile, Lines& lines) {
  LauncherOptions o;
  o.profile_path = profile.string();
  o.worker_program = TESSERA_CLI_PATH;
  o.log = lines.sink();
  o.handle_signals = false;
  return o;
}

/// The wall-clock profile (with `restart`, e.g. "restart: [robot]") written into `dir`, its
/// workers through /bin/sh: the first incarnation of `failing` exits with status 3 at once,
/// every other runs the CLI's `tessera worker`.
LauncherOptions wallProfileFailingOnce(const fs::path& dir, const std::string& restart,
                                       const std::string& failing, Lines& lines) {
  std::ofstream(dir / "wall.yaml") << tessera::test::wallMappingProfile(restart);
  auto o = cliWorkers(dir / "wall.yaml", lines);
  o.worker_program = "/bin/sh";
  o.worker_argv = {"sh", "-c",
                   "case \" $* \" in *\" --process " + failing +
                       " \"*\" --incarnation 0 \"*) exit 3;; esac; exec \"" + TESSERA_CLI_PATH +
                       "\" worker \"$@\"",
                   "sh"};
  return o;
}

/// Reaps what a failed check may have left (workers re-parented to the test process).
struct ReapOnExit {
  ReapOnExit() { ::prctl(PR_SET_CHILD_SUBREAPER, 1); }
  ~ReapOnExit() {
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (std::chrono::steady_clock::now() < deadline) {
      if (::waitpid(-1, nullptr, WNOHANG) < 0) return;  // no children left
      std::this_thread::sleep_for(10ms);
    }
  }
};

}  // namespace

TEST_CASE("a Launcher runs a small profile to its end in two processes", "[launcher]") {
  ReapOnExit reap;
  const auto dir = freshDir("launcher_clean");
  Lines lines;
  auto o = cliWorkers(fs::path(TESSERA_SOURCE_DIR) / "apps/profiles/sim_mapping.yaml", lines);
  o.sets = {"max_duration_s=20"};
  o.out_dir = (dir / "out").string();
  Launcher launcher(o);
  CHECK(launcher.plan().processes.size() == 2);
  const LaunchResult result = launcher.run();
  INFO(lines.text());
  CHECK(result.exit_code == 0);
  CHECK_FALSE(result.failed);
  CHECK_FALSE(result.interrupted);
  CHECK(result.stop_reason == "reached max_duration_s");
  CHECK(result.restarts.at("robot") == 0);
  CHECK(result.restarts.at("mapping") == 0);
  CHECK(lines.text().find("[launch] started 'robot' (pid ") != std::string::npos);
  CHECK(fs::exists(dir / "out" / "map.pgm"));
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  CHECK(summary["processes"].size() == 2);
  CHECK(summary["stop_reason"] == "reached max_duration_s");
  CHECK(summary["interrupted"] == false);
  // Every route between the two processes delivered all it sent, and says so.
  REQUIRE_FALSE(result.delivery.empty());
  std::uint64_t reliable_sent = 0;
  for (const auto& d : result.delivery) {
    INFO(d.route.topic);
    CHECK(d.received == d.sent);
    CHECK(d.lost_live == 0);
    CHECK(d.dead.empty());
    if (d.route.reliable) reliable_sent += d.sent;
  }
  CHECK(reliable_sent > 0);
  CHECK(summary["delivery"].size() == result.delivery.size());
  CHECK(lines.text().find("0 lost between live processes") != std::string::npos);
  CHECK(shmClean());
}

TEST_CASE("a SIGKILLed receiver's deliveries are still counted, and what died with it is named",
          "[launcher]") {
  ReapOnExit reap;
  const auto dir = freshDir("launcher_delivery_kill");
  Lines lines;
  std::ofstream(dir / "wall.yaml")
      << tessera::test::wallMappingProfile("restart: [mapping]\nmax_duration_s: 9");
  auto o = cliWorkers(dir / "wall.yaml", lines);
  o.out_dir = (dir / "out").string();
  Launcher launcher(o);
  std::thread killer([&] {
    const std::string pid = lines.waitFor(R"(started 'mapping' \(pid (\d+)\))");
    lines.waitFor(R"(the run starts)");
    std::this_thread::sleep_for(4s);
    if (!pid.empty()) ::kill(std::stoi(pid), SIGKILL);
  });
  const LaunchResult result = launcher.run();
  killer.join();
  INFO(lines.text());
  CHECK(result.exit_code == 0);
  CHECK(result.restarts.at("mapping") == 1);
  bool counted_scans = false;
  for (const auto& d : result.delivery) {
    INFO(d.route.topic);
    CHECK(d.lost_live == 0);
    REQUIRE(d.dead == std::vector<std::string>{"mapping"});
    // The killed incarnation took ~40 of ~90 scans before it died, the next one at most 50 in
    // what was left of the run: the dead one's count survived it.
    if (d.route.topic == "scan")
      counted_scans = d.received * 10 > d.sent * 6 && d.received <= d.sent;
    CHECK(d.lost_with_dead == d.sent - d.received);
  }
  CHECK(counted_scans);
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  REQUIRE(summary["delivery"].is_array());
  CHECK(summary["delivery"][0]["dead"][0] == "mapping");
  CHECK(shmClean());
}

TEST_CASE("a Launcher restarts a worker that dies when the profile lists it under restart:",
          "[launcher]") {
  ReapOnExit reap;
  const auto dir = freshDir("launcher_restart");
  Lines lines;
  auto o = wallProfileFailingOnce(dir, "restart: [robot]", "robot", lines);
  o.out_dir = (dir / "out").string();
  Launcher launcher(o);
  std::thread stopper([&] {
    // The second robot streams a while, then the run is stopped as Ctrl-C would.
    lines.waitFor(R"(started 'robot' \(pid (\d+)\))", 2);
    std::this_thread::sleep_for(2500ms);
    launcher.interrupt();
  });
  const LaunchResult result = launcher.run();
  stopper.join();
  INFO(lines.text());
  CHECK(result.exit_code == 130);
  CHECK(result.interrupted);
  CHECK_FALSE(result.failed);
  CHECK(result.restarts.at("robot") == 1);
  CHECK(result.restarts.at("mapping") == 0);
  const std::string log = lines.text();
  CHECK(std::regex_search(log, std::regex(R"(process 'robot' \(pid \d+\) exited with status 3)")));
  CHECK(log.find("[launch] restarting 'robot' (restart 1)") != std::string::npos);
  CHECK(log.find("[launch] stopped: interrupted") != std::string::npos);
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  CHECK(summary["processes"]["robot"]["restarts"] == 1);
  CHECK(summary["actors"]["mapper"]["messages_in"].get<int>() > 0);
  CHECK(shmClean());
}

TEST_CASE("a worker that dies without a restart entry ends the run with an error naming it",
          "[launcher]") {
  ReapOnExit reap;
  const auto dir = freshDir("launcher_failure");
  Lines lines;
  auto o = wallProfileFailingOnce(dir, "", "mapping", lines);
  Launcher launcher(o);
  const auto start = std::chrono::steady_clock::now();
  const LaunchResult result = launcher.run();
  INFO(lines.text());
  // The robot, still waiting for its subscriber, leaves as soon as the deployment stops.
  CHECK(std::chrono::steady_clock::now() - start < 20s);
  CHECK(result.exit_code == 1);
  CHECK(result.failed);
  CHECK(result.stop_reason == "process 'mapping' exited with status 3");
  CHECK(result.restarts.at("mapping") == 0);
  CHECK(lines.text().find("it is not listed under restart:; stopping the others") !=
        std::string::npos);
  CHECK(shmClean());
}

TEST_CASE("a Launcher rejects a bad profile before any process or shared memory exists",
          "[launcher]") {
  const auto dir = freshDir("launcher_bad_profile");
  // Any worker started would leave this file behind.
  const fs::path marker = dir / "a_worker_ran";
  LauncherOptions o;
  o.worker_program = "/bin/sh";
  o.worker_argv = {"sh", "-c", "touch '" + marker.string() + "'", "sh"};
  o.handle_signals = false;
  std::vector<std::string> logged;
  o.log = [&](const std::string& line) { logged.push_back(line); };

  SECTION("a restart entry naming no process") {
    std::ofstream(dir / "bad.yaml") << tessera::test::wallMappingProfile("restart: [nowhere]");
    o.profile_path = (dir / "bad.yaml").string();
    CHECK_THROWS_AS(Launcher(o), tessera::ConfigError);
  }
  SECTION("an unknown actor type") {
    std::ofstream(dir / "bad.yaml") << "name: bad\nactors:\n  x:\n    type: no_such_actor\n";
    o.profile_path = (dir / "bad.yaml").string();
    CHECK_THROWS_AS(Launcher(o), tessera::ConfigError);
  }
  SECTION("an override of a key the actor does not have") {
    o.profile_path = (fs::path(TESSERA_SOURCE_DIR) / "apps/profiles/sim_mapping.yaml").string();
    o.sets = {"mapper.no_such_key=1"};
    CHECK_THROWS_AS(Launcher(o), tessera::ConfigError);
  }
  CHECK(logged.empty());
  CHECK_FALSE(fs::exists(marker));
  CHECK_FALSE(tessera::rouDiRunning());
  CHECK(shmClean());
}
