// `tessera launch PROFILE`: the profile's actors as one process per `process:` group, over
// shared memory. The launcher embeds RouDi (memory pools sized from the plan), starts one
// `tessera worker` per process (its output prefixed with the process name), coordinates
// simulated time and the end of the run through a control block (runtime/deployment.hpp),
// restarts processes the profile names under `restart:` when they die (wall clock), and stops
// everything cleanly on Ctrl-C (a second Ctrl-C terminates the workers, a third kills them).
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/runtime/process_stats.hpp>
#include <tessera/shm/deployment.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <thread>

namespace tessera::app {

namespace fs = std::filesystem;

namespace {

std::atomic<int> g_interrupts{0};
extern "C" void onLaunchSignal(int) {
  g_interrupts.fetch_add(1);
}

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

struct LaunchArgs {
  std::string profile;
  std::vector<std::string> sets;
  std::string out;
  int threads = 0;
  std::string shm_log = "error";
};

pid_t spawnWorker(const LaunchArgs& a, const std::string& profile_path, Worker& w,
                  const std::string& sync_name, std::size_t max_chunk, const std::string& out_dir) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw std::runtime_error("pipe: " + std::string(std::strerror(errno)));
  std::vector<std::string> args = {"tessera",
                                   "worker",
                                   profile_path,
                                   "--process",
                                   w.process,
                                   "--sync",
                                   sync_name,
                                   "--max-chunk",
                                   std::to_string(max_chunk),
                                   "--incarnation",
                                   std::to_string(w.incarnation),
                                   "--threads",
                                   std::to_string(a.threads),
                                   "--shm-log",
                                   a.shm_log};
  if (!out_dir.empty()) {
    args.push_back("--out");
    args.push_back(out_dir);
  }
  for (const auto& s : a.sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork: " + std::string(std::strerror(errno)));
  if (pid == 0) {
    ::setpgid(0, 0);                     // Ctrl-C reaches the launcher only; it stops workers
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);  // the launcher (and its RouDi) died: stop
    ::dup2(fds[1], 1);
    ::dup2(fds[1], 2);
    // Nothing of the launcher's may outlive it through a worker: not RouDi's lock file (a
    // worker holding it would make the next launch believe RouDi still runs), not its memory.
    ::close_range(3, ~0U, 0);
    std::vector<char*> argv;
    for (auto& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    ::execv("/proc/self/exe", argv.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  // The launcher's loop must never block on one quiet worker.
  ::fcntl(fds[0], F_SETFL, ::fcntl(fds[0], F_GETFL) | O_NONBLOCK);
  w.pid = pid;
  w.out = fds[0];
  w.running = true;
  return pid;
}

/// One launcher line, written at once: RouDi's threads print to the same terminal, and a line
/// written piecewise could be split by theirs.
void say(const std::string& line) {
  const std::string text = "[launch] " + line + "\n";
  std::fwrite(text.data(), 1, text.size(), stderr);
}

void pump(Worker& w, bool flush_all) {
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
    if (!line.empty()) {
      const std::string text = "[" + w.process + "] " + line + "\n";
      std::fwrite(text.data(), 1, text.size(), stderr);
    }
  }
  if (flush_all && !w.partial.empty()) {
    std::cerr << "[" << w.process << "] " << w.partial << "\n";
    w.partial.clear();
  }
}

int launch(const LaunchArgs& a) {
  ::prctl(PR_SET_TIMERSLACK, 1UL);  // the clock thread's short sleeps must stay short
  const std::string path = resolveProfilePath(a.profile, profileSearchDirs());
  const Profile profile = loadProfile(path, a.sets);
  const DeploymentPlan plan = planDeployment(profile);
  std::string out_dir;
  if (!a.out.empty()) {
    fs::create_directories(a.out);
    out_dir = fs::absolute(a.out).lexically_normal().string();
  }

  std::cerr << "tessera launch " << profile.name << " (" << path << "): " << plan.processes.size()
            << " processes over shared memory\n";
  for (const auto& p : plan.processes) {
    std::cerr << "  process " << std::left << std::setw(14) << p << " actors:";
    for (const auto& actor : plan.actors.at(p)) std::cerr << " " << actor;
    std::cerr << "\n";
    auto t = plan.topics.find(p);
    if (t != plan.topics.end()) {
      std::cerr << "  " << std::setw(22) << ""
                << " shared:";
      for (const auto& topic : t->second) {
        std::cerr << " " << topic.name << (topic.exported ? (topic.imported ? "<>" : ">") : "<");
      }
      std::cerr << "\n";
    }
  }

  RouDiHostOptions ro;
  ro.pools = memPoolsFor(plan.demands);
  ro.log_level = a.shm_log;
  RouDiHost roudi(ro);
  for (const auto& f : roudi.removedStale()) {
    std::cerr << "  removed stale shared memory of a crashed run: " << f << "\n";
  }
  std::size_t pool_bytes = 0;
  for (const auto& p : ro.pools) pool_bytes += p.chunk_bytes * p.count;
  std::cerr << "  RouDi embedded: " << ro.pools.size() << " memory pools, chunks up to "
            << (roudi.maxChunkBytes() >> 10) << " KiB, " << (pool_bytes >> 20)
            << " MiB of shared memory\n"
            << "  clock: "
            << (profile.clock == ClockKind::kSimulated ? "simulated, coordinated across processes"
                                                       : "wall")
            << ", output: " << (out_dir.empty() ? "(none; use --out DIR)" : out_dir)
            << "\n  Ctrl-C stops cleanly (a second Ctrl-C terminates the workers)\n";

  const std::string sync_name = "/tessera_sync_" + std::to_string(::getpid());
  SyncMemory sync(sync_name, true);
  const bool sim = profile.clock == ClockKind::kSimulated;
  std::vector<int> stage_owners;
  for (const auto& s : plan.stop_stages) stage_owners.push_back(s.process);
  DeploymentClock clock(sync.block(), static_cast<int>(plan.processes.size()), stage_owners, sim,
                        profile.sim_rate,
                        profile.max_duration_s > 0 ? secondsToNanos(profile.max_duration_s)
                                                   : std::numeric_limits<Nanos>::max());

  struct sigaction sa {};
  sa.sa_handler = onLaunchSignal;
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
  g_interrupts = 0;

  std::vector<Worker> workers(plan.processes.size());
  for (std::size_t i = 0; i < workers.size(); ++i) {
    auto& w = workers[i];
    w.process = plan.processes[i];
    w.index = static_cast<int>(i);
    w.restart = std::find(profile.restart.begin(), profile.restart.end(), w.process) !=
                profile.restart.end();
    spawnWorker(a, path, w, sync_name, roudi.maxChunkBytes(), out_dir);
    say("started '" + w.process + "' (pid " + std::to_string(w.pid) + ")");
  }

  std::atomic<bool> quit{false};
  std::thread clock_thread([&] {
    SyncBlock& block = sync.block();
    // What workers wait for; a change (from this loop or from requestStop) rings their bells.
    auto decisions = [&] {
      return std::array<std::uint64_t, 4>{block.go.load(), block.grant_seq.load(),
                                          block.command.load(), block.stop_turn.load()};
    };
    auto rung = decisions();
    int quiet_rounds = 0;
    while (!quit.load()) {
      // Read before the step, so that a worker's ring after it ends the wait below.
      const std::uint32_t bell = block.clock_bell.load();
      clock.step();
      if (const auto now = decisions(); now != rung) {
        rung = now;
        quiet_rounds = 0;
        for (int i = 0; i < static_cast<int>(workers.size()); ++i) {
          ringBell(block.slots[i].bell, block.slots[i].waiting);
        }
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
  });

  const Nanos start = steadyNow();
  int handled_interrupts = 0;
  Nanos stopping_since = 0, next_stop_report = 0;
  bool failed = false;
  std::string failure;
  for (;;) {
    std::vector<pollfd> fds;
    for (auto& w : workers) {
      if (w.out >= 0) fds.push_back({w.out, POLLIN, 0});
    }
    ::poll(fds.data(), fds.size(), 20);
    for (auto& w : workers) {
      if (w.out >= 0) pump(w, false);
    }
    const int interrupts = g_interrupts.load();
    if (interrupts > handled_interrupts) {
      handled_interrupts = interrupts;
      if (interrupts == 1) {
        std::cerr << "[launch] interrupt: stopping every process cleanly\n";
        clock.requestStop("interrupted (SIGINT/SIGTERM)");
      } else {
        std::cerr << "[launch] second interrupt: terminating the workers\n";
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
      pump(w, true);
      ::close(w.out);
      w.out = -1;
      const bool clean = WIFEXITED(status) &&
                         (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 130) &&
                         sync.block().slots[w.index].stopped.load() == 1;
      clock.markGone(w.index);
      if (clean) continue;
      std::cerr << "[launch] process '" << w.process << "' (pid " << w.pid << ") "
                << describeStatus(status) << "\n";
      // Killed inside a send, it would leave a port locked and wedge RouDi and its peers.
      for (const auto& port : roudi.releaseOrphanedPortLocks()) {
        std::cerr << "[launch] released the lock it held on " << port << "\n";
      }
      const bool ending = sync.block().command.load() != 0;
      if (w.restart && !sim && !ending) {
        ++w.incarnation;
        clock.markRestarted(w.index);
        std::cerr << "[launch] restarting '" << w.process << "' (restart " << w.incarnation
                  << ")\n";
        spawnWorker(a, path, w, sync_name, roudi.maxChunkBytes(), out_dir);
        say("started '" + w.process + "' (pid " + std::to_string(w.pid) + ")");
        any_running = true;
      } else if (!ending) {
        failed = true;
        failure = "process '" + w.process + "' " + describeStatus(status);
        std::cerr << "[launch] "
                  << (sim ? "a simulated-time deployment cannot continue without it"
                          : "it is not listed under restart:")
                  << "; stopping the others\n";
        clock.requestStop(failure);
      } else if (!failed) {
        failed = true;
        failure = "process '" + w.process + "' " + describeStatus(status) + " while stopping";
      }
    }
    if (!any_running) break;
    if (sync.block().command.load() != 0) {
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
        std::cerr << "[launch] still stopping after " << (now - stopping_since) / kNanosPerSecond
                  << " s (stop turn " << sync.block().stop_turn.load() << " of "
                  << stage_owners.size() + 1 << "); "
                  << (names.empty() ? "waiting for" + left + " to exit" : "waiting for" + names)
                  << "\n";
      }
    }
  }
  quit = true;
  clock_thread.join();

  // One summary for the deployment, from each process's own.
  const double wall_s = static_cast<double>(steadyNow() - start) * 1e-9;
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
  const std::string reason = failed ? failure : clock.reason();
  summary["cpu_s"] = cpu;
  summary["peak_rss_mb"] = rss;  // sum of the processes' peaks: an upper bound of the total
  summary["data_duration_s"] = data;
  summary["realtime_factor"] = wall_s > 0 ? data / wall_s : 0.0;
  summary["interrupted"] = failed || handled_interrupts > 0;
  summary["stop_reason"] = reason;
  summary["actors"] = actors;
  if (!out_dir.empty()) {
    std::ofstream(fs::path(out_dir) / "summary.json") << summary.dump(2) << "\n";
  }
  std::cerr << "[launch] stopped: " << reason << "\n"
            << std::fixed << std::setprecision(2) << "[launch] data " << data << " s in " << wall_s
            << " s wall, " << cpu << " s CPU over " << workers.size() << " processes\n";
  if (!out_dir.empty()) std::cerr << "[launch] outputs in " << out_dir << "\n";
  if (failed) return 1;
  return handled_interrupts > 0 ? 130 : 0;
}

struct WorkerArgs {
  std::string profile, process, sync, out, shm_log = "error";
  std::vector<std::string> sets;
  std::size_t max_chunk = 0;
  int incarnation = 0, threads = 0;
};

/// RouDi died with the launcher: iceoryx's teardown (deregistering from RouDi) could now block
/// for ever, so the worker leaves without it.
[[noreturn]] void leaveOrphaned(const std::string& what) {
  std::cerr << "the launcher (and its RouDi) died: stopped (" << what << ")\n";
  std::fflush(nullptr);
  std::_Exit(3);
}

int worker(const WorkerArgs& a) {
  ::prctl(PR_SET_TIMERSLACK, 1UL);  // waits for the deployment clock use short sleeps
  const Profile profile = loadProfile(a.profile, a.sets);
  const DeploymentPlan plan = planDeployment(profile);
  const int index = plan.indexOf(a.process);
  if (index < 0) throw ConfigError("worker: no process '" + a.process + "' in " + a.profile);
  SyncMemory sync(a.sync, false);
  WorkerCoordinator coordinator(sync.block(), index, plan.stop_stages);
  setIceoryxLogLevel(a.shm_log);
  ShmTransportOptions so;
  so.runtime_name = "tessera_" + a.process + "_" + std::to_string(a.incarnation);
  so.process_index = static_cast<std::uint32_t>(index);
  so.max_chunk_bytes = a.max_chunk;
  so.sent = &coordinator.slot().sent;
  so.received = &coordinator.slot().received;
  so.arrived = [&coordinator] { coordinator.messageArrived(); };
  ShmTransport transport(so);
  RuntimeOptions options;
  options.threads = a.threads;
  options.show_progress = false;
  options.output_dir = a.out;
  options.coordinator = &coordinator;
  const auto topics =
      plan.topics.count(a.process) ? plan.topics.at(a.process) : std::vector<ShmTopic>{};
  auto runtime = buildProcessRuntime(profile, options, a.process,
                                     [&](Runtime& rt) { transport.attach(rt, topics); });
  transport.startReceiving();
  // A peer that died before connecting stops the deployment: leave then, not after 30 s.
  if (!transport.waitForPublishers(std::chrono::seconds(30),
                                   [&] { return coordinator.ending(); }) &&
      !coordinator.ending()) {
    throw std::runtime_error("process '" + a.process + "': its peers did not connect within 30 s");
  }
  runtime->installSignalHandlers();
  if (!coordinator.readyAndWait()) {
    coordinator.slot().stopped = 1;  // nothing ran: nothing to stop
    if (coordinator.orphaned()) leaveOrphaned("before the run started");
    return 130;
  }
  const RunReport report = runtime->run();
  if (coordinator.orphaned()) leaveOrphaned(report.stop_reason);  // outputs written in run()
  transport.stopReceiving();
  const auto stats = transport.stats();
  std::cerr << report.table();
  std::cerr << "shared memory: " << stats.sent << " sent, " << stats.received << " received, "
            << stats.copies << " copied into a larger chunk, " << stats.drops
            << " discarded by full keep_latest queues\n";
  if (!a.out.empty()) {
    auto j = summaryJson(profile, report);
    j["shm_sent"] = stats.sent;
    j["shm_received"] = stats.received;
    j["shm_copies"] = stats.copies;
    std::ofstream(fs::path(a.out) / ("summary_" + a.process + ".json")) << j.dump(2) << "\n";
  }
  const bool actor_failure = report.interrupted && report.stop_reason.rfind("actor '", 0) == 0;
  return actor_failure ? 1 : 0;
}

}  // namespace

void addLaunchCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand("launch", "run a profile as several processes over shared memory");
  auto args = std::make_shared<LaunchArgs>();
  cmd->add_option("profile", args->profile, "profile name (apps/profiles/NAME.yaml) or path")
      ->required();
  cmd->add_option("--set", args->sets, "override: ACTOR.KEY=VALUE, KEY=VALUE (repeatable)");
  cmd->add_option("--out", args->out, "output folder (created); default: none, nothing is written");
  cmd->add_option("--threads", args->threads, "executor threads per process (0: all cores)");
  cmd->add_option("--shm-log", args->shm_log, "iceoryx log level: off, error, warn, info");
  cmd->callback([args, &result] { result = launch(*args); });

  auto* w = app.add_subcommand("worker", "");  // started by `launch`; hidden from --help
  w->group("");
  auto wargs = std::make_shared<WorkerArgs>();
  w->add_option("profile", wargs->profile)->required();
  w->add_option("--process", wargs->process)->required();
  w->add_option("--sync", wargs->sync)->required();
  w->add_option("--max-chunk", wargs->max_chunk)->required();
  w->add_option("--incarnation", wargs->incarnation);
  w->add_option("--threads", wargs->threads);
  w->add_option("--out", wargs->out);
  w->add_option("--shm-log", wargs->shm_log);
  w->add_option("--set", wargs->sets);
  w->callback([wargs, &result] {
    try {
      result = worker(*wargs);
    } catch (const std::exception& e) {
      // Leave without iceoryx's teardown: RouDi may be the reason (and may be gone); it frees a
      // dead process's ports itself. The launcher reports the exit status.
      std::cerr << "error: " << e.what() << "\n";
      std::fflush(nullptr);
      std::_Exit(e.what()[0] != '\0' && dynamic_cast<const ConfigError*>(&e) ? 2 : 1);
    }
  });
}

}  // namespace tessera::app
