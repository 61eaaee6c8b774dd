// Launcher: a profile run as one process per `process:` group over shared memory (what
// `tessera launch` does; docs/architecture.md describes the deployment).
//
// While run() runs, a Launcher owns
//  * an embedded RouDi (RouDiHost) with memory pools sized from the deployment plan,
//  * the control block (SyncMemory "/tessera_sync_<pid>") and the thread that moves it
//    (DeploymentClock: start, simulated time, end of the run, stop turns),
//  * one worker process per process group, exec'd from LauncherOptions::worker_program in a process
//    group of its own (so Ctrl-C reaches the launcher only) and sent SIGHUP if the launcher dies
//    (it then stops cleanly and writes its outputs),
//  * the pipes carrying each worker's stdout and stderr, forwarded line by line to the log with
//    the process name in front.
// Workers the profile lists under `restart:` are started again when they die (wall clock only);
// any other death stops the deployment. Everything is released before run() returns or throws:
// workers reaped, RouDi and the control block removed.
#pragma once

#include <tessera/runtime/profile.hpp>
#include <tessera/shm/deployment.hpp>

#include <atomic>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace tessera {

struct LauncherOptions {
  /// The profile file (names are resolved by the caller, e.g. with resolveProfilePath).
  std::string profile_path;
  /// Overrides as `--set` takes them: ACTOR.KEY=VALUE, KEY=VALUE.
  std::vector<std::string> sets;
  /// Output folder, created and given to every worker; "" writes nothing.
  std::string out_dir;
  /// Executor threads per worker (0: all cores).
  int threads = 0;
  /// iceoryx log level of RouDi and the workers: off, error, warn, info.
  std::string shm_log = "error";
  /// Seconds a worker whose launcher died may take to write what it holds and stop before it
  /// leaves without the rest (a thread blocked in a send to a dead peer never returns).
  double orphan_grace_s = 30;
  /// The worker: the program exec'd and its argv up to the worker's own arguments (argv[0]
  /// first). The launcher appends the profile path, then --process, --sync, --max-chunk,
  /// --incarnation, --threads, --shm-log, --orphan-grace, --out (when set) and each --set. Default:
  /// this executable's `tessera worker` command.
  std::string worker_program = "/proc/self/exe";
  std::vector<std::string> worker_argv = {"tessera", "worker"};
  /// Receives every line the launcher prints and every line of the workers' output (prefixed
  /// "[process] "), without the newline, on the thread that called run(). Default: stderr.
  std::function<void(const std::string&)> log;
  /// Installs SIGINT/SIGTERM handlers for the run that call interrupt() (restored after it).
  bool handle_signals = true;
};

/// How a run ended.
struct LaunchResult {
  /// 0 when the deployment finished, 1 when a process failed, 130 when interrupted.
  int exit_code = 0;
  /// Why it stopped ("all inputs finished", "process 'x' exited with status 3", ...).
  std::string stop_reason;
  bool failed = false;       // a process died (and was not restarted)
  bool interrupted = false;  // interrupt() was called (Ctrl-C)
  /// Times each process was restarted, by name.
  std::map<std::string, int> restarts;
  double wall_s = 0;
  /// Messages sent and received on every route between processes (also in summary.json,
  /// "delivery"), with what was lost between live processes and what with a dead one.
  std::vector<RouteDelivery> delivery;
};

class Launcher {
 public:
  /// Loads the profile and plans the deployment; throws ConfigError for a profile that cannot be
  /// run or deployed, before any process or shared memory exists.
  explicit Launcher(LauncherOptions options);
  Launcher(const Launcher&) = delete;
  Launcher& operator=(const Launcher&) = delete;

  const Profile& profile() const { return profile_; }
  const DeploymentPlan& plan() const { return plan_; }

  /// Starts RouDi and the workers, forwards their output, restarts or stops as the profile says,
  /// and returns once every worker ended, after writing out_dir/summary.json (the deployment's
  /// figures from each process's own summary). Called once.
  LaunchResult run();

  /// What Ctrl-C does: the first call stops every process cleanly, the second terminates the
  /// workers (SIGTERM), a third kills them. Async-signal-safe; callable from any thread.
  void interrupt() noexcept { interrupts_.fetch_add(1); }

 private:
  LauncherOptions options_;
  Profile profile_;
  DeploymentPlan plan_;
  std::atomic<int> interrupts_{0};
  bool ran_ = false;
};

}  // namespace tessera
