// Launcher (launcher.hpp): embeds RouDi, starts one worker process per process group, forwards
// their output, coordinates simulated time and the end of the run through the control block
// (deployment.hpp), restarts processes the profile names under `restart:` when they die (wall
// clock), and merges the processes' summaries into one.
#include <tessera/shm/launcher.hpp>

#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/options.hpp>

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace tessera {

namespace fs = std::filesystem;

namespace {

/// The launcher whose run() handles SIGINT/SIGTERM now.
std::atomic<Launcher*> g_signalled{nullptr};
extern "C" void onLaunchSignal(int) {
  if (Launcher* l = g_signalled.load()) l->interrupt();
}

/// Routes SIGINT and SIGTERM to `launcher` while this lives (when `enabled`).
class SignalRoute {
 public:
  SignalRoute(Launcher* launcher, bool enabled) : enabled_(enabled) {
    if (!enabled_) return;
    g_signalled = launcher;
    struct sigaction sa {};
    sa.sa_handler = onLaunchSignal;
    ::sigaction(SIGINT, &sa, &old_int_);
    ::sigaction(SIGTERM, &sa, &old_term_);
  }
  ~SignalRoute() {
    if (!enabled_) return;
    ::sigaction(SIGINT, &old_int_, nullptr);
    ::sigaction(SIGTERM, &old_term_, nullptr);
    g_signalled = nullptr;
  }
  SignalRoute(const SignalRoute&) = delete;
  SignalRoute& operator=(const SignalRoute&) = delete;

 private:
  bool enabled_;
  struct sigaction old_int_ = {};
  struct sigaction old_term_ = {};
};

std::string signalName(int sig) {
  const char* d = ::sigabbrev_np(sig);
  return d != nullptr ? std::string("SIG") + d : "signal " + std::to_string(sig);
}

std::string describeStatus(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    return "was killed by " + signalName(WTERMSIG(status)) +
           (WCOREDUMP(status) ? " (core dumped)" : "");
  }
  return "ended (status " + std::to_string(status) + ")";
}

/// A worker's end that is not a failure: it finished (0) or stopped on an interrupt (130).
bool exitedCleanly(int status) {
  return WIFEXITED(status) && (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 130);
}

using Log = std::function<void(const std::string&)>;

/// One line written at once: RouDi's threads print to the same terminal, and a line written
/// piecewise could be split by theirs.
void logToStderr(const std::string& line) {
  const std::string text = line + "\n";
  std::fwrite(text.data(), 1, text.size(), stderr);
}

struct Worker {
  std::string process;
  int index = 0;
  pid_t pid = -1;
  int out = -1;         // read end of the worker's stdout+stderr
  std::string partial;  // an unfinished output line
  int incarnation = 0;
  bool running = false;
  bool restart = false;
  int status = 0;
};

/// What every incarnation of every worker is started with.
struct SpawnArgs {
  const LauncherOptions& options;
  std::string sync_name;
  std::size_t max_chunk = 0;
  std::string out_dir;
};

void spawnWorker(const SpawnArgs& a, Worker& w) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw std::runtime_error("pipe: " + std::string(std::strerror(errno)));
  const LauncherOptions& o = a.options;
  std::vector<std::string> args = o.worker_argv;
  for (const std::string& s :
       {o.profile_path, std::string("--process"), w.process, std::string("--sync"), a.sync_name,
        std::string("--max-chunk"), std::to_string(a.max_chunk), std::string("--incarnation"),
        std::to_string(w.incarnation), std::string("--threads"), std::to_string(o.threads),
        std::string("--shm-log"), o.shm_log, std::string("--orphan-grace"),
        std::to_string(o.orphan_grace_s)}) {
    args.push_back(s);
  }
  if (!a.out_dir.empty()) {
    args.push_back("--out");
    args.push_back(a.out_dir);
  }
  for (const auto& s : o.sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  std::vector<char*> argv;
  for (auto& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork: " + std::string(std::strerror(errno)));
  if (pid == 0) {
    ::setpgid(0, 0);  // Ctrl-C reaches the launcher only; it stops workers
    // The launcher (and its RouDi) died: stop cleanly. SIGHUP, not SIGTERM: the kernel sends it
    // once per launcher thread as they die, and a worker takes a second SIGTERM as Ctrl-C twice.
    ::prctl(PR_SET_PDEATHSIG, SIGHUP);
    ::dup2(fds[1], 1);
    ::dup2(fds[1], 2);
    // Nothing of the launcher's may outlive it through a worker: not RouDi's lock file (a
    // worker holding it would make the next launch believe RouDi still runs), not its memory.
    ::close_range(3, ~0U, 0);
    ::execv(o.worker_program.c_str(), argv.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  // The launcher's loop must never block on one quiet worker.
  ::fcntl(fds[0], F_SETFL, ::fcntl(fds[0], F_GETFL) | O_NONBLOCK);
  w.pid = pid;
  w.out = fds[0];
  w.running = true;
}

/// Forwards the worker's complete output lines (all of it with `flush_all`) to `log`.
void pump(Worker& w, bool flush_all, const Log& log) {
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(w.out, buf, sizeof(buf));
    if (n <= 0) break;  // no more for now (EAGAIN), or the worker closed it
    w.partial.append(buf, static_cast<std::size_t>(n));
  }
  std::size_t at;
  while ((at = w.partial.find_first_of("\n\r")) != std::string::npos) {
    const std::string line = w.partial.substr(0, at);
    w.partial.erase(0, at + 1);
    if (!line.empty()) log("[" + w.process + "] " + line);
  }
  if (flush_all && !w.partial.empty()) {
    log("[" + w.process + "] " + w.partial);
    w.partial.clear();
  }
}

/// The plan as the launch prints it: each process's actors and the topics it shares.
void logPlan(const Profile& profile, const std::string& path, const DeploymentPlan& plan,
             const Log& log) {
  log("tessera launch " + profile.name + " (" + path +
      "): " + std::to_string(plan.processes.size()) + " processes over shared memory");
  for (const auto& p : plan.processes) {
    std::ostringstream line;
    line << "  process " << std::left << std::setw(14) << p << " actors:";
    for (const auto& actor : plan.actors.at(p)) line << " " << actor;
    log(line.str());
    auto t = plan.topics.find(p);
    if (t != plan.topics.end()) {
      std::ostringstream shared;
      shared << "  " << std::left << std::setw(22) << ""
             << " shared:";
      for (const auto& topic : t->second) {
        shared << " " << topic.name << (topic.exported ? (topic.imported ? "<>" : ">") : "<");
      }
      log(shared.str());
    }
  }
}

/// The moving part of the control block: steps the DeploymentClock and rings the workers' bells
/// when its decisions change, on a thread of its own until stopped.
class ClockThread {
 public:
  ClockThread(SyncBlock& block, DeploymentClock& clock, int workers, bool sim)
      : thread_([this, &block, &clock, workers, sim] { loop(block, clock, workers, sim); }) {}
  ~ClockThread() { stop(); }
  ClockThread(const ClockThread&) = delete;
  ClockThread& operator=(const ClockThread&) = delete;
  void stop() {
    quit_ = true;
    if (thread_.joinable()) thread_.join();
  }

 private:
  void loop(SyncBlock& block, DeploymentClock& clock, int workers, bool sim) {
    // What workers wait for; a change (from this loop or from requestStop) rings their bells.
    auto decisions = [&] {
      return std::array<std::uint64_t, 4>{block.go.load(), block.grant_seq.load(),
                                          static_cast<std::uint64_t>(block.command.load()),
                                          block.stop_turn.load()};
    };
    auto rung = decisions();
    int quiet_rounds = 0;
    while (!quit_.load()) {
      // Read before the step, so that a worker's ring after it ends the wait below.
      const std::uint32_t bell = block.clock_bell.load();
      clock.step();
      if (const auto now = decisions(); now != rung) {
        rung = now;
        quiet_rounds = 0;
        for (int i = 0; i < workers; ++i) ringBell(block.slots[i].bell, block.slots[i].waiting);
      }
      // Simulated time: sleep until a worker's slot changes (a few yields first, as the next
      // step often follows within microseconds). Wall clock: only the end of the run is decided
      // here.
      if (!sim) {
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      } else if (++quiet_rounds < 4) {
        std::this_thread::yield();
      } else {
        waitBell(block.clock_bell, block.clock_waiting, bell, std::chrono::milliseconds(2));
      }
    }
  }

  std::atomic<bool> quit_{false};
  std::thread thread_;  // last: starts once the members above exist
};

/// Kills and reaps the workers still running (a run() that throws leaves none behind).
void killAll(std::vector<Worker>& workers) {
  for (auto& w : workers) {
    if (w.running) {
      ::kill(w.pid, SIGKILL);
      ::waitpid(w.pid, nullptr, 0);
      w.running = false;
    }
    if (w.out >= 0) ::close(w.out);
    w.out = -1;
  }
}

/// One summary for the deployment, from each process's own (out_dir/summary_<process>.json).
nlohmann::json mergeSummaries(const Profile& profile, const std::vector<Worker>& workers,
                              const std::string& out_dir, double wall_s) {
  nlohmann::json summary;
  summary["profile"] = profile.name;
  summary["processes"] = nlohmann::json::object();
  summary["wall_s"] = wall_s;
  double cpu = 0, rss = 0, data = 0;
  nlohmann::json actors = nlohmann::json::object();
  for (const auto& w : workers) {
    const fs::path file = fs::path(out_dir) / ("summary_" + w.process + ".json");
    if (out_dir.empty() || !fs::exists(file)) continue;
    nlohmann::json j;
    try {
      std::ifstream(file) >> j;
    } catch (const std::exception&) {
      continue;
    }
    cpu += j.value("cpu_s", 0.0);
    rss += j.value("peak_rss_mb", 0.0);
    data = std::max(data, j.value("data_duration_s", 0.0));
    for (auto& [k, v] : j["actors"].items()) actors[k] = v;
    for (auto& [k, v] : j.items()) {
      if (k == "actors" || k == "profile" || k == "wall_s" || k == "cpu_s" || k == "peak_rss_mb" ||
          k == "data_duration_s" || k == "realtime_factor" || k == "interrupted" ||
          k == "stop_reason" || summary.contains(k))
        continue;  // on a clash the first process (in stop order) wins
      summary[k] = v;
    }
    summary["processes"][w.process] = {{"cpu_s", j.value("cpu_s", 0.0)},
                                       {"peak_rss_mb", j.value("peak_rss_mb", 0.0)},
                                       {"restarts", w.incarnation}};
  }
  summary["cpu_s"] = cpu;
  summary["peak_rss_mb"] = rss;  // sum of the processes' peaks: an upper bound of the total
  summary["data_duration_s"] = data;
  summary["realtime_factor"] = wall_s > 0 ? data / wall_s : 0.0;
  summary["actors"] = actors;
  return summary;
}

nlohmann::json deliveryJson(const std::vector<RouteDelivery>& delivery,
                            const std::vector<std::string>& processes) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& d : delivery) {
    out.push_back({{"topic", d.route.topic},
                   {"from", processes.at(d.route.from)},
                   {"to", processes.at(d.route.to)},
                   {"reliable", d.route.reliable},
                   {"sent", d.sent},
                   {"received", d.received},
                   {"lost_live", d.lost_live},
                   {"lost_with_dead", d.lost_with_dead},
                   {"dead", d.dead}});
  }
  return out;
}

/// One line for the reliable routes: what crossed, what was lost between live processes (never
/// expected), and what was lost with a process that died, naming it.
void logDelivery(const std::vector<RouteDelivery>& delivery, const Log& log) {
  std::uint64_t sent = 0, received = 0, lost_live = 0, lost_dead = 0;
  std::set<std::string> dead;
  int routes = 0;
  for (const auto& d : delivery) {
    if (!d.route.reliable) continue;
    ++routes;
    sent += d.sent;
    received += d.received;
    lost_live += d.lost_live;
    lost_dead += d.lost_with_dead;
    if (d.lost_with_dead > 0) dead.insert(d.dead.begin(), d.dead.end());
  }
  if (routes == 0) return;
  std::string line = "[launch] reliable topics: " + std::to_string(sent) + " sent, " +
                     std::to_string(received) + " received over " + std::to_string(routes) +
                     " routes; " + std::to_string(lost_live) + " lost between live processes";
  if (lost_dead > 0) {
    line += ", " + std::to_string(lost_dead) + " lost with processes that died (";
    for (auto it = dead.begin(); it != dead.end(); ++it) {
      line += (it == dead.begin() ? "'" : ", '") + *it + "'";
    }
    line += ")";
  }
  log(line);
  for (const auto& d : delivery) {
    if (d.route.reliable && d.lost_live > 0) {
      log("[launch] warning: topic '" + d.route.topic + "' lost " + std::to_string(d.lost_live) +
          " reliable messages between live processes");
    }
  }
}

}  // namespace

Launcher::Launcher(LauncherOptions options)
    : options_(std::move(options)),
      profile_(loadProfile(options_.profile_path, options_.sets)),
      plan_(planDeployment(profile_)) {
  if (!options_.log) options_.log = logToStderr;
}

LaunchResult Launcher::run() {
  if (ran_) throw std::logic_error("Launcher::run() called twice");
  ran_ = true;
  ::prctl(PR_SET_TIMERSLACK, 1UL);  // the clock thread's short sleeps must stay short
  const Log& log = options_.log;
  std::string out_dir;
  if (!options_.out_dir.empty()) {
    fs::create_directories(options_.out_dir);
    out_dir = fs::absolute(options_.out_dir).lexically_normal().string();
  }
  logPlan(profile_, options_.profile_path, plan_, log);

  RouDiHostOptions ro;
  ro.pools = memPoolsFor(plan_.demands);
  ro.log_level = options_.shm_log;
  RouDiHost roudi(ro);
  for (const auto& f : roudi.removedStale()) {
    log("  removed stale shared memory of a crashed run: " + f);
  }
  std::size_t pool_bytes = 0;
  for (const auto& p : ro.pools) pool_bytes += p.chunk_bytes * p.count;
  const bool sim = profile_.clock == ClockKind::kSimulated;
  log("  RouDi embedded: " + std::to_string(ro.pools.size()) + " memory pools, chunks up to " +
      std::to_string(roudi.maxChunkBytes() >> 10) + " KiB, " + std::to_string(pool_bytes >> 20) +
      " MiB of shared memory");
  log(std::string("  clock: ") + (sim ? "simulated, coordinated across processes" : "wall") +
      ", output: " + (out_dir.empty() ? "(none; use --out DIR)" : out_dir));
  if (options_.handle_signals) {
    log("  Ctrl-C stops cleanly (a second Ctrl-C terminates the workers)");
  }

  const SpawnArgs spawn{options_, "/tessera_sync_" + std::to_string(::getpid()),
                        roudi.maxChunkBytes(), out_dir};
  SyncMemory sync(spawn.sync_name, true);
  SyncBlock& block = sync.block();
  std::vector<int> stage_owners;
  for (const auto& s : plan_.stop_stages) stage_owners.push_back(s.process);
  DeploymentClock clock(block, static_cast<int>(plan_.processes.size()), stage_owners, sim,
                        profile_.sim_rate,
                        profile_.max_duration_s > 0 ? secondsToNanos(profile_.max_duration_s)
                                                    : std::numeric_limits<Nanos>::max());
  SignalRoute signals(this, options_.handle_signals);

  std::vector<Worker> workers(plan_.processes.size());
  const Nanos start = steadyNow();
  int handled_interrupts = 0;
  bool failed = false;
  std::string failure;
  try {
    auto started = [&](const Worker& w) {
      log("[launch] started '" + w.process + "' (pid " + std::to_string(w.pid) + ")");
    };
    for (std::size_t i = 0; i < workers.size(); ++i) {
      auto& w = workers[i];
      w.process = plan_.processes[i];
      w.index = static_cast<int>(i);
      w.restart = std::find(profile_.restart.begin(), profile_.restart.end(), w.process) !=
                  profile_.restart.end();
      spawnWorker(spawn, w);
      started(w);
    }
    ClockThread clock_thread(block, clock, static_cast<int>(workers.size()), sim);

    Nanos stopping_since = 0, next_stop_report = 0;
    bool announced_start = false;
    for (;;) {
      std::vector<pollfd> fds;
      for (auto& w : workers) {
        if (w.out >= 0) fds.push_back({w.out, POLLIN, 0});
      }
      ::poll(fds.data(), fds.size(), 20);
      for (auto& w : workers) {
        if (w.out >= 0) pump(w, false, log);
      }
      // Starting a process (loading, connecting its topics) can take seconds on a loaded
      // machine: say when the run itself begins.
      if (!announced_start && block.go.load() != 0) {
        announced_start = true;
        log("[launch] every process connected: the run starts");
      }
      const int interrupts = interrupts_.load();
      if (interrupts > handled_interrupts) {
        handled_interrupts = interrupts;
        if (interrupts == 1) {
          log("[launch] interrupt: stopping every process cleanly");
          clock.requestStop("interrupted (SIGINT/SIGTERM)");
        } else {
          log("[launch] second interrupt: terminating the workers");
          for (auto& w : workers) {
            if (w.running) ::kill(w.pid, interrupts == 2 ? SIGTERM : SIGKILL);
          }
        }
      }
      bool any_running = false;
      for (auto& w : workers) {
        if (!w.running) continue;
        int status = 0;
        if (::waitpid(w.pid, &status, WNOHANG) != w.pid) {
          any_running = true;
          continue;
        }
        w.running = false;
        w.status = status;
        pump(w, true, log);
        ::close(w.out);
        w.out = -1;
        const bool clean = exitedCleanly(status) && block.slots[w.index].stopped.load() == 1;
        clock.markGone(w.index);
        if (clean) continue;
        log("[launch] process '" + w.process + "' (pid " + std::to_string(w.pid) + ") " +
            describeStatus(status));
        // Killed inside a send, it would leave a port locked and wedge RouDi and its peers.
        for (const auto& port : roudi.releaseOrphanedPortLocks()) {
          log("[launch] released the lock it held on " + port);
        }
        const bool ending = block.command.load() != RunCommand::kRun;
        if (w.restart && !sim && !ending) {
          ++w.incarnation;
          clock.markRestarted(w.index);
          log("[launch] restarting '" + w.process + "' (restart " + std::to_string(w.incarnation) +
              ")");
          spawnWorker(spawn, w);
          started(w);
          any_running = true;
        } else if (!ending) {
          failed = true;
          failure = "process '" + w.process + "' " + describeStatus(status);
          log(std::string("[launch] ") +
              (sim ? "a simulated-time deployment cannot continue without it"
                   : "it is not listed under restart:") +
              "; stopping the others");
          clock.requestStop(failure);
        } else if (!failed) {
          failed = true;
          failure = "process '" + w.process + "' " + describeStatus(status) + " while stopping";
        }
      }
      if (!any_running) break;
      if (block.command.load() != RunCommand::kRun) {
        // A stop that hangs (a process stuck in a handler) says what it waits for.
        const Nanos now = steadyNow();
        if (stopping_since == 0) {
          stopping_since = now;
          next_stop_report = now + 10 * kNanosPerSecond;
        } else if (now >= next_stop_report) {
          next_stop_report = now + 10 * kNanosPerSecond;
          std::string names, left;
          for (const int i : clock.holdingUpStop()) names += " '" + workers[i].process + "'";
          for (const auto& w : workers) {
            if (w.running) left += " '" + w.process + "' (pid " + std::to_string(w.pid) + ")";
          }
          log("[launch] still stopping after " +
              std::to_string((now - stopping_since) / kNanosPerSecond) + " s (stop turn " +
              std::to_string(block.stop_turn.load()) + " of " +
              std::to_string(stage_owners.size() + 1) + "); " +
              (names.empty() ? "waiting for" + left + " to exit" : "waiting for" + names));
        }
      }
    }
  } catch (...) {
    killAll(workers);
    throw;
  }

  LaunchResult result;
  result.wall_s = static_cast<double>(steadyNow() - start) * 1e-9;
  result.failed = failed;
  result.interrupted = handled_interrupts > 0;
  result.stop_reason = failed ? failure : clock.reason();
  for (const auto& w : workers) result.restarts[w.process] = w.incarnation;
  std::vector<bool> died;
  for (const auto& w : workers) died.push_back(w.incarnation > 0 || !exitedCleanly(w.status));
  result.delivery = readDelivery(plan_, sync.ledger(), died);
  nlohmann::json summary = mergeSummaries(profile_, workers, out_dir, result.wall_s);
  summary["delivery"] = deliveryJson(result.delivery, plan_.processes);
  summary["interrupted"] = failed || result.interrupted;
  summary["stop_reason"] = result.stop_reason;
  bool summary_failed = false;
  if (!out_dir.empty()) {
    try {
      io::writeFileAtomically(fs::path(out_dir) / "summary.json", summary.dump(2) + "\n");
    } catch (const std::exception& e) {
      log(std::string("[launch] error: ") + e.what());
      summary_failed = true;
    }
  }
  std::ostringstream figures;
  figures << std::fixed << std::setprecision(2) << "[launch] data "
          << summary["data_duration_s"].get<double>() << " s in " << result.wall_s << " s wall, "
          << summary["cpu_s"].get<double>() << " s CPU over " << workers.size() << " processes";
  log("[launch] stopped: " + result.stop_reason);
  log(figures.str());
  logDelivery(result.delivery, log);
  if (!out_dir.empty()) log("[launch] outputs in " + out_dir);
  result.exit_code = failed || summary_failed ? 1 : (result.interrupted ? 130 : 0);
  return result;
}

}  // namespace tessera
