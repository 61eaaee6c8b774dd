// The live viewer as a user meets it: `tessera record sim_slam_global --view 0` runs the
// two-level SLAM with the viewer on a free port, headless Chromium (Debian's chromium, driven by
// playwright-core: tests/js/viewer_e2e.mjs) opens the page, waits for map tiles, the robot and
// its trajectory, checks the layer toggles, clicks a goal and saves a screenshot. Then the run is
// stopped with Ctrl-C and what the browser showed is compared with what the run wrote: the
// robot's pose against trajectory.tum at the same stamp, and the clicked goal on the goal topic
// (recorded by the same command).
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

#include "cli_run.hpp"

namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void skipOrFail(const std::string& why) {
  const char* ci = std::getenv("CI");
  if (ci && std::string(ci) == "true") FAIL("the viewer test needs a browser: " << why);
  WARN("SKIPPED: npm " << why);
}

// Why the browser test cannot run here, or "".
std::string missingBrowser(const fs::path& js) {
  if (!fs::exists(js / "node_modules" / "playwright-core"))
    return "no playwright-core in " + (js / "node_modules").string() + " (run scripts/js_deps.sh)";
  if (std::system("node --version > /dev/null 2>&1") != 0) return "no node on PATH";
  const char* chromium = std::getenv("CHROMIUM");
  if (!fs::exists(chromium ? chromium : "/usr/bin/chromium"))
    return "no /usr/bin/chromium (apt-get install chromium)";
  return "";
}

// A child `tessera ARGS` with stderr in a file; stopped with SIGINT (as Ctrl-C) on request.
class Child {
 public:
  Child(const std::string& args, const fs::path& err) {
    pid_ = ::fork();
    REQUIRE(pid_ >= 0);
    if (pid_ == 0) {
      const std::string cmd = "exec " + std::string(TESSERA_CLI_PATH) + " " + args + " 2> " +
                              err.string() + " > /dev/null";
      ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
  }
  ~Child() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  int interrupt() {
    ::kill(pid_, SIGINT);
    int status = 0;
    for (int i = 0; i < 600; ++i) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return -2;
  }

 private:
  pid_t pid_ = -1;
};

struct TumPose {
  double t, x, y;
};

std::vector<TumPose> readTum(const fs::path& p) {
  std::vector<TumPose> out;
  std::ifstream in(p);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    TumPose q{};
    s >> q.t >> q.x >> q.y;
    out.push_back(q);
  }
  return out;
}

}  // namespace

TEST_CASE("a browser watches sim_slam_global live and sends a goal", "[viewer][e2e]") {
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
  Child run("record sim_slam_global --view 0 --rate 4 --topics goal --out " +
                (dir / "goal.trec").string() + " --dir " + (dir / "out").string(),
            err);
  std::string url;
  const std::regex url_re(R"(live view: (http://127\.0\.0\.1:[0-9]+/))");
  for (int i = 0; i < 600 && url.empty(); ++i) {
    std::smatch m;
    const std::string text = slurp(err);
    if (std::regex_search(text, m, url_re)) url = m[1];
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  INFO(slurp(err));
  REQUIRE_FALSE(url.empty());

  const fs::path result = dir / "result.json";
  const std::string cmd = "node " + (js / "viewer_e2e.mjs").string() + " --url " + url +
                          " --goal 2.5,1.5 --screenshot " + (dir / "viewer.png").string() +
                          " --out " + result.string() + " --timeout-s 120 > " +
                          (dir / "e2e.log").string() + " 2>&1";
  const int e2e = std::system(cmd.c_str());
  const int stopped = run.interrupt();
  INFO(slurp(dir / "e2e.log"));
  INFO(slurp(err));
  REQUIRE(e2e == 0);
  CHECK(stopped == 130);  // stopped by Ctrl-C, outputs written
  const auto r = nlohmann::json::parse(slurp(result));
  CHECK(r["ok"] == true);
  CHECK(r["errors"].empty());
  CHECK(r["tiles"].get<int>() > 0);
  for (const char* topic : {"map/tiles", "scan", "pose", "tf"})
    CHECK(std::find(r["topics"].begin(), r["topics"].end(), topic) != r["topics"].end());

  // The robot the page drew is the run's estimate at that stamp.
  const auto traj = readTum(dir / "out" / "trajectory.tum");
  REQUIRE_FALSE(traj.empty());
  const double stamp = r["robot"]["stampNs"].get<double>() * 1e-9;
  const auto near = std::min_element(traj.begin(), traj.end(), [&](const auto& a, const auto& b) {
    return std::abs(a.t - stamp) < std::abs(b.t - stamp);
  });
  CHECK(std::abs(near->t - stamp) < 1e-3);
  CHECK(std::hypot(near->x - r["robot"]["x"].get<double>(),
                   near->y - r["robot"]["y"].get<double>()) < 0.1);

  // The clicked goal arrived on the goal topic: one message, recorded.
  CHECK(std::abs(r["goalSent"]["x"].get<double>() - 2.5) < 0.05);
  const auto info =
      tessera::test::runCli("replay " + (dir / "goal.trec").string() + " --info", dir);
  INFO(info.out);
  CHECK(std::regex_search(info.out, std::regex(R"(goal\b.*\b1 message)")));
  const auto summary = nlohmann::json::parse(slurp(dir / "out" / "summary.json"));
  CHECK(summary["actors"]["viewer"]["goals"] == 1);
  CHECK(summary["actors"]["viewer"]["clients_total"].get<int>() >= 1);
}
