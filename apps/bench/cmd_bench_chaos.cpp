// tessera bench chaos: a multi-process deployment under fire (docs/benchmarks.md#chaos). Runs
// `tessera launch` of a wall-clock profile whose processes are listed under restart: and, at
// random moments, SIGKILLs a random worker or stalls one (SIGSTOP, then SIGCONT 0.05-3 s later,
// wherever it was: in a handler, in a send; longer than RouDi's heartbeat timeout too). Each kill
// is timed until the new incarnation is back (its control-block slot names a new pid and says it is
// connected and ready). The launch's summary.json gives what each route between processes sent and
// received (its delivery ledger survives a SIGKILLed process), so what was lost between live
// processes and what was lost with a dead one are told apart. Then the launcher itself (which hosts
// RouDi) is SIGKILLed a few times mid-run, the orphaned workers must stop on their own, and the
// next launch in the same folder must start (clearing the dead RouDi's shared memory). Every output
// file left behind is checked to be complete. Writes chaos.json in the output folder; --json prints
// it.
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "child_process.hpp"
#include "cli_inputs.hpp"

#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/shm/deployment.hpp>

#include <yaml-cpp/yaml.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

namespace tessera::app {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string profile = "chaos_mapping";
  std::vector<std::string> sets;
  double duration_s = 120;
  int kills = 100;
  int stalls = 20;
  int roudi_kills = 5;
  // Stalls straddle RouDi's 1.5 s heartbeat timeout: a stopped process must keep its queues.
  double min_stall_s = 0.05;
  double max_stall_s = 3.0;
  unsigned seed = 1;
  int threads = 1;
  std::string out = "out/bench_chaos";
  bool json = false;
};

double secondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// The launcher's control block, once it exists (the launcher creates it after RouDi).
std::unique_ptr<SyncMemory> attachControlBlock(pid_t launcher, double timeout_s) {
  const std::string name = "/tessera_sync_" + std::to_string(launcher);
  const auto t0 = Clock::now();
  while (secondsSince(t0) < timeout_s) {
    if (fs::exists("/dev/shm" + name)) {
      try {
        return std::make_unique<SyncMemory>(name, false);
      } catch (const std::exception&) {
        // created but not yet sized: try again
      }
    }
    int status = 0;
    if (::waitpid(launcher, &status, WNOHANG) == launcher) {
      throw std::runtime_error("the launch ended before its control block existed (exit " +
                               std::to_string(exitCodeOf(status)) + ")");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  throw std::runtime_error("no control block " + name + " within " +
                           std::to_string(static_cast<int>(timeout_s)) + " s");
}

/// Waits until every worker is ready and the run started; false on timeout or if the launch died.
bool waitStarted(pid_t launcher, SyncBlock& block, double timeout_s) {
  const auto t0 = Clock::now();
  while (secondsSince(t0) < timeout_s) {
    if (block.go.load() != 0) return true;
    if (::kill(launcher, 0) != 0) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

/// Why `file` is not a complete output, or "" when it is: JSON and YAML parse, trajectories
/// (.tum) have 8 numbers a line, a PGM holds the pixels its header promises.
std::string incompleteReason(const fs::path& file) {
  const std::string name = file.filename().string();
  if (name.find(".tmp.") != std::string::npos) return "";  // a temporary file, not an output
  const std::string ext = file.extension().string();
  std::ifstream in(file, std::ios::binary);
  if (!in) return "cannot open";
  try {
    if (ext == ".json") {
      const auto parsed = nlohmann::json::parse(in);
      if (parsed.is_discarded()) return "not JSON";
    } else if (ext == ".yaml") {
      (void)YAML::LoadFile(file.string());
    } else if (ext == ".tum") {
      std::string line;
      for (int n = 1; std::getline(in, line); ++n) {
        if (line.empty() || line[0] == '#') continue;
        std::istringstream s(line);
        double v[8];
        for (double& x : v) {
          if (!(s >> x) || !std::isfinite(x)) return "line " + std::to_string(n) + " is cut short";
        }
      }
    } else if (ext == ".pgm") {
      std::string magic;
      long w = 0, h = 0, max = 0;
      in >> magic >> std::ws;
      while (in.peek() == '#') in.ignore(1 << 20, '\n');
      in >> w >> h >> max;
      in.get();
      if (magic != "P5" || w <= 0 || h <= 0 || max <= 0) return "bad PGM header";
      const auto at = in.tellg();
      in.seekg(0, std::ios::end);
      if (in.tellg() - at < static_cast<std::streamoff>(w * h))
        return "PGM shorter than its header";
    } else if (fs::file_size(file) == 0) {
      return "empty";
    }
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

struct OutputCheck {
  int files = 0, temporaries = 0;
  std::vector<std::string> incomplete;  // "file: reason"
};

OutputCheck checkOutputs(const fs::path& dir) {
  OutputCheck c;
  if (!fs::exists(dir)) return c;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file() || e.path().extension() == ".log") continue;  // the bench's own
    if (e.path().filename().string().find(".tmp.") != std::string::npos) {
      ++c.temporaries;  // left by a process killed mid-write; the target is untouched
      continue;
    }
    ++c.files;
    const std::string why = incompleteReason(e.path());
    if (!why.empty()) c.incomplete.push_back(e.path().string() + ": " + why);
  }
  return c;
}

std::vector<std::string> launchArgs(const Options& o, const fs::path& out, double duration_s) {
  std::vector<std::string> args = {"tessera",
                                   "launch",
                                   o.profile,
                                   "--out",
                                   out.string(),
                                   "--threads",
                                   std::to_string(o.threads)};
  for (const auto& s : o.sets) args.insert(args.end(), {"--set", s});
  std::ostringstream d;
  d << "max_duration_s=" << duration_s;
  args.insert(args.end(), {"--set", d.str()});
  return args;
}

struct Pending {
  int slot = 0;
  std::int64_t old_pid = 0;
  Clock::time_point since;
};

struct Stall {
  pid_t pid = 0;
  Clock::time_point until;
};

/// The main run: one launch for duration_s, kills and stalls spread over it.
nlohmann::json chaosRun(const Options& o, const DeploymentPlan& plan,
                        const std::vector<int>& restartable, const fs::path& dir,
                        std::mt19937& rng) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const pid_t launcher = spawnTessera(launchArgs(o, dir, o.duration_s), dir / "launch.log");
  auto control = attachControlBlock(launcher, 60);
  SyncBlock& block = control->block();
  if (!waitStarted(launcher, block, 60)) {
    ::kill(launcher, SIGKILL);
    waitChild(launcher);
    throw std::runtime_error("the deployment did not start within 60 s (see " +
                             (dir / "launch.log").string() + ")");
  }
  const auto start = Clock::now();
  // Events between 3 s after the start and 5 s before the end: kills (true) and stalls.
  const double from = std::min(3.0, o.duration_s * 0.1);
  const double to = std::max(from, o.duration_s - 5.0);
  std::uniform_real_distribution<double> when(from, to);
  std::vector<std::pair<double, bool>> events;
  for (int i = 0; i < o.kills; ++i) events.emplace_back(when(rng), true);
  for (int i = 0; i < o.stalls; ++i) events.emplace_back(when(rng), false);
  std::sort(events.begin(), events.end());

  std::vector<Pending> pending;
  std::vector<Stall> stalled;
  std::vector<double> recovery;
  std::map<std::string, int> kills_of;
  int kills = 0, stalls = 0, deferred = 0;
  std::vector<double> stall_s;
  std::size_t next = 0;
  int launch_status = 0;
  bool launch_ended = false;
  const auto busy = [&](int slot) {
    const auto pid = static_cast<pid_t>(block.slots[slot].pid.load());
    return std::any_of(pending.begin(), pending.end(),
                       [&](const Pending& p) { return p.slot == slot; }) ||
           std::any_of(stalled.begin(), stalled.end(),
                       [&](const Stall& s) { return s.pid == pid; });
  };
  while (!launch_ended) {
    const double now_s = secondsSince(start);
    // Recoveries: the slot names a new process that is connected and ready.
    for (auto it = pending.begin(); it != pending.end();) {
      const SyncSlot& s = block.slots[it->slot];
      if (s.pid.load() != it->old_pid && s.ready.load() == 1) {
        recovery.push_back(secondsSince(it->since));
        it = pending.erase(it);
      } else {
        ++it;
      }
    }
    for (auto it = stalled.begin(); it != stalled.end();) {
      if (Clock::now() >= it->until) {
        ::kill(it->pid, SIGCONT);
        it = stalled.erase(it);
      } else {
        ++it;
      }
    }
    // The next event, on a process that is up and neither recovering nor stalled.
    if (next < events.size() && now_s >= events[next].first) {
      std::vector<int> candidates;
      for (int slot : restartable) {
        if (!busy(slot) && block.slots[slot].ready.load() == 1 && block.slots[slot].pid.load() > 0)
          candidates.push_back(slot);
      }
      if (candidates.empty()) {
        ++deferred;  // everything is down or stalled: try again in a moment
        events[next].first = now_s + 0.05;
      } else {
        const int slot =
            candidates[std::uniform_int_distribution<std::size_t>(0, candidates.size() - 1)(rng)];
        const auto pid = static_cast<pid_t>(block.slots[slot].pid.load());
        if (events[next].second) {
          pending.push_back({slot, pid, Clock::now()});
          ::kill(pid, SIGKILL);
          ++kills;
          ++kills_of[plan.processes[slot]];
        } else {
          ::kill(pid, SIGSTOP);
          const double hold =
              std::uniform_real_distribution<double>(o.min_stall_s, o.max_stall_s)(rng);
          stall_s.push_back(hold);
          stalled.push_back({pid, Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                     std::chrono::duration<double>(hold))});
          ++stalls;
        }
        ++next;
      }
    }
    if (::waitpid(launcher, &launch_status, WNOHANG) == launcher) launch_ended = true;
    if (!launch_ended && secondsSince(start) > o.duration_s + 120) {
      ::kill(launcher, SIGKILL);
      waitChild(launcher);
      throw std::runtime_error("the launch did not end within 120 s of its time limit (see " +
                               (dir / "launch.log").string() + ")");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  for (const auto& s : stalled) ::kill(s.pid, SIGCONT);
  control.reset();

  nlohmann::json summary;
  try {
    std::ifstream in(dir / "summary.json");
    summary = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw std::runtime_error((dir / "summary.json").string() + ": " + e.what());
  }
  std::uint64_t sent = 0, received = 0, lost_live = 0, lost_dead = 0;
  nlohmann::json routes = nlohmann::json::array();
  for (const auto& r : summary.value("delivery", nlohmann::json::array())) {
    if (!r.value("reliable", false)) continue;
    sent += r.value("sent", 0ull);
    received += r.value("received", 0ull);
    lost_live += r.value("lost_live", 0ull);
    lost_dead += r.value("lost_with_dead", 0ull);
    routes.push_back(r);
  }
  const OutputCheck outputs = checkOutputs(dir);
  nlohmann::json restarts = nlohmann::json::object();
  for (const auto& [p, v] : summary["processes"].items()) restarts[p] = v.value("restarts", 0);
  return {{"exit_code", exitCodeOf(launch_status)},
          {"kills", kills},
          {"stalls", stalls},
          {"stall_s",
           {{"median", median(stall_s)},
            {"max", stall_s.empty() ? 0.0 : *std::max_element(stall_s.begin(), stall_s.end())},
            {"over_1_5s",
             std::count_if(stall_s.begin(), stall_s.end(), [](double h) { return h > 1.5; })}}},
          {"kills_by_process", kills_of},
          {"restarts", restarts},
          {"not_back", static_cast<int>(pending.size())},
          {"recovery_s",
           {{"median", median(recovery)},
            {"p99", percentile(recovery, 0.99)},
            {"max", recovery.empty() ? 0.0 : *std::max_element(recovery.begin(), recovery.end())},
            {"over_2s",
             std::count_if(recovery.begin(), recovery.end(), [](double r) { return r > 2.0; })}}},
          {"reliable",
           {{"sent", sent},
            {"received", received},
            {"lost_live", lost_live},
            {"lost_with_dead", lost_dead},
            {"routes", routes}}},
          {"outputs",
           {{"files", outputs.files},
            {"incomplete", outputs.incomplete},
            {"temporaries", outputs.temporaries}}}};
}

/// The launcher (and its RouDi) SIGKILLed `count` times mid-run in one output folder; each time
/// the orphaned workers must stop by themselves and the next launch must start. A last launch
/// runs to its end.
nlohmann::json roudiKills(const Options& o, const fs::path& dir, std::mt19937& rng) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::vector<double> orphans_s, relaunch_s;
  std::vector<std::string> incomplete;
  int stale_cleared = 0, orphans_left = 0;
  for (int k = 0; k <= o.roudi_kills; ++k) {
    const bool last = k == o.roudi_kills;
    const fs::path log = dir / ("launch_" + std::to_string(k) + ".log");
    const auto t_spawn = Clock::now();
    const pid_t launcher = spawnTessera(launchArgs(o, dir, last ? 8.0 : 60.0), log);
    auto control = attachControlBlock(launcher, 60);
    if (!waitStarted(launcher, control->block(), 60)) {
      ::kill(launcher, SIGKILL);
      waitChild(launcher);
      throw std::runtime_error("launch " + std::to_string(k) + " did not start within 60 s (see " +
                               log.string() + ")");
    }
    if (k > 0) relaunch_s.push_back(secondsSince(t_spawn));
    std::ifstream in(log);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.find("removed stale shared memory") != std::string::npos) ++stale_cleared;
    if (last) {
      control.reset();
      const int code = waitChild(launcher, 120);
      if (code != 0) {
        throw std::runtime_error("the launch after the last kill ended with " +
                                 std::to_string(code) + " (see " + log.string() + ")");
      }
      break;
    }
    std::vector<pid_t> workers;
    for (int i = 0; i < kMaxDeploymentProcesses; ++i) {
      const auto pid = control->block().slots[i].pid.load();
      if (pid > 0) workers.push_back(static_cast<pid_t>(pid));
    }
    std::this_thread::sleep_for(
        std::chrono::duration<double>(std::uniform_real_distribution<double>(1.0, 4.0)(rng)));
    control.reset();
    ::kill(launcher, SIGKILL);
    const auto t_kill = Clock::now();
    waitChild(launcher);
    // The workers see their parent gone (SIGHUP from the kernel), write what they hold and stop.
    // They are re-parented to this process (a subreaper, see run()), which reaps them: a zombie
    // would still answer kill(pid, 0).
    for (;;) {
      while (::waitpid(-1, nullptr, WNOHANG) > 0) {
      }
      const bool any =
          std::any_of(workers.begin(), workers.end(), [](pid_t p) { return ::kill(p, 0) == 0; });
      if (!any) break;
      if (secondsSince(t_kill) > 30) {
        for (pid_t p : workers) {
          if (::kill(p, 0) == 0) {
            ++orphans_left;
            ::kill(p, SIGKILL);
          }
        }
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    orphans_s.push_back(secondsSince(t_kill));
    for (const auto& bad : checkOutputs(dir).incomplete) incomplete.push_back(bad);
  }
  const OutputCheck final_check = checkOutputs(dir);
  for (const auto& bad : final_check.incomplete) incomplete.push_back(bad);
  return {
      {"kills", o.roudi_kills},
      {"orphans_stopped_s",
       {{"median", median(orphans_s)},
        {"max", orphans_s.empty() ? 0.0 : *std::max_element(orphans_s.begin(), orphans_s.end())}}},
      {"orphans_killed", orphans_left},
      {"relaunch_s",
       {{"median", median(relaunch_s)},
        {"max",
         relaunch_s.empty() ? 0.0 : *std::max_element(relaunch_s.begin(), relaunch_s.end())}}},
      {"stale_memory_cleared", stale_cleared},
      {"outputs", {{"files", final_check.files}, {"incomplete", incomplete}}}};
}

int run(const Options& o) {
  if (o.min_stall_s > o.max_stall_s) {
    std::ostringstream m;
    m << "bench chaos: --min-stall " << o.min_stall_s << " s is longer than --max-stall "
      << o.max_stall_s << " s";
    throw ConfigError(m.str());
  }
  const std::string path = resolveProfilePath(o.profile, profileSearchDirs());
  const Profile profile = loadProfile(path, o.sets);
  if (profile.clock != ClockKind::kWall) {
    throw ConfigError(path +
                      ": bench chaos needs a wall-clock profile (clock: wall); a "
                      "simulated-time deployment cannot restart a process");
  }
  const DeploymentPlan plan = planDeployment(profile);
  std::vector<int> restartable;
  for (const auto& r : profile.restart) restartable.push_back(plan.indexOf(r));
  if (restartable.empty()) {
    throw ConfigError(path +
                      ": bench chaos kills the processes listed under restart:, and it "
                      "lists none");
  }
  const fs::path out = o.out;
  fs::create_directories(out);
  std::mt19937 rng(o.seed);
  // Workers orphaned by a killed launcher come back to this process rather than to init (which
  // in a container may never reap them), so that their end is seen and their status collected.
  ::prctl(PR_SET_CHILD_SUBREAPER, 1);
  if (!o.json) {
    std::cout << "machine: " << machineDescription() << "\n"
              << "bench chaos: " << profile.name << ", " << o.duration_s << " s, " << o.kills
              << " kills and " << o.stalls << " stalls of " << restartable.size()
              << " restartable processes, then " << o.roudi_kills << " kills of the launcher\n"
              << std::flush;
  }
  nlohmann::json run_json = chaosRun(o, plan, restartable, out / "run", rng);
  nlohmann::json roudi_json = roudiKills(o, out / "launcher_kills", rng);
  const nlohmann::json result = {{"machine", machineDescription()},
                                 {"profile", profile.name},
                                 {"duration_s", o.duration_s},
                                 {"seed", o.seed},
                                 {"run", run_json},
                                 {"launcher_kills", roudi_json}};
  io::writeFileAtomically(out / "chaos.json", result.dump(2) + "\n");
  if (o.json) {
    std::cout << result.dump(2) << "\n";
  } else {
    const auto& r = run_json;
    const auto& rel = r["reliable"];
    std::cout << std::fixed << std::setprecision(3) << "  kills " << r["kills"] << ", stalls "
              << r["stalls"] << " (median " << r["stall_s"]["median"].get<double>() << " s, max "
              << r["stall_s"]["max"].get<double>() << " s, " << r["stall_s"]["over_1_5s"]
              << " over RouDi's 1.5 s heartbeat timeout), restarts " << r["restarts"].dump() << "\n"
              << "  back after a kill: median " << r["recovery_s"]["median"].get<double>()
              << " s, p99 " << r["recovery_s"]["p99"].get<double>() << " s, max "
              << r["recovery_s"]["max"].get<double>() << " s (" << r["recovery_s"]["over_2s"]
              << " over 2 s, " << r["not_back"] << " not back)\n"
              << "  reliable messages: " << rel["sent"] << " sent, " << rel["received"]
              << " received, " << rel["lost_live"] << " lost between live processes, "
              << rel["lost_with_dead"] << " lost with a killed process\n"
              << "  outputs: " << r["outputs"]["files"] << " files, "
              << r["outputs"]["incomplete"].size() << " incomplete; launch exit code "
              << r["exit_code"] << "\n"
              << "  launcher kills: " << roudi_json["kills"] << ", orphans stopped in (max) "
              << roudi_json["orphans_stopped_s"]["max"].get<double>() << " s, next launch up in "
              << "(max) " << roudi_json["relaunch_s"]["max"].get<double>() << " s, "
              << roudi_json["outputs"]["incomplete"].size() << " incomplete outputs\n"
              << "wrote " << (out / "chaos.json").string() << "\n";
  }
  // Failures, not figures: a figure (recovery over 2 s on a loaded machine) is reported only.
  const bool ok = run_json["exit_code"] == 0 && run_json["not_back"] == 0 &&
                  run_json["reliable"]["lost_live"] == 0 &&
                  run_json["outputs"]["incomplete"].empty() &&
                  roudi_json["outputs"]["incomplete"].empty() && roudi_json["orphans_killed"] == 0;
  if (!ok) std::cerr << "bench chaos: FAILED (see " << (out / "chaos.json").string() << ")\n";
  return ok ? 0 : 1;
}

}  // namespace

void addBenchChaosCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "chaos",
      "kill and stall the processes of a launch at random: restarts, recovery times, reliable "
      "messages sent vs received, outputs complete (chaos.json)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profile", o->profile, "wall-clock profile with restart: entries")
      ->capture_default_str();
  cmd->add_option("--duration", o->duration_s, "seconds of the main run")
      ->check(finiteNumberIn(5.0, 86400.0))
      ->capture_default_str();
  cmd->add_option("--kills", o->kills, "SIGKILLs of random restartable workers")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  cmd->add_option("--stalls", o->stalls, "SIGSTOP/SIGCONT stalls of random workers")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  cmd->add_option("--min-stall", o->min_stall_s, "shortest stall, seconds")
      ->check(finiteNumberIn(0.01, 60.0))
      ->capture_default_str();
  cmd->add_option("--max-stall", o->max_stall_s, "longest stall, seconds")
      ->check(finiteNumberIn(0.01, 60.0))
      ->capture_default_str();
  cmd->add_option("--launcher-kills", o->roudi_kills,
                  "SIGKILLs of the launcher (and its RouDi), each followed by a new launch")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "random seed of the schedule")->capture_default_str();
  cmd->add_option("--threads", o->threads, "executor threads per worker")->capture_default_str();
  cmd->add_option("--set", o->sets, "override passed to the launch (ACTOR.KEY=VALUE)");
  cmd->add_option("--out", o->out, "folder for the runs and chaos.json")->capture_default_str();
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o, &result] { result = run(*o); });
}

}  // namespace tessera::app
