// `tessera launch PROFILE`: the profile's actors as one process per `process:` group, over
// shared memory, through a Launcher (tessera/shm/launcher.hpp: embedded RouDi, one `tessera
// worker` per process, restarts, Ctrl-C). `tessera worker` is what the launcher starts: one
// process's actors in a Runtime, attached to the others through ShmTransport and coordinated
// through the launcher's control block.
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/shm/deployment.hpp>
#include <tessera/shm/launcher.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <mutex>
#include <stop_token>
#include <thread>
#include <utility>

namespace tessera::app {

namespace fs = std::filesystem;

namespace {

struct LaunchArgs {
  std::string profile;
  std::vector<std::string> sets;
  std::string out;
  int threads = 0;
  std::string shm_log = "error";
  double orphan_grace_s = LauncherOptions{}.orphan_grace_s;
  RunSettings view;  // only the --view options
  std::string host;  // --host: this host's part only, the others over DDS
  int wait_peers_s = 60;
};

// `launch --view`: the workers read the profile from its file, so the viewer goes into a copy
// of it (mode 0600: it may hold the token) that the launcher and every worker load instead. The
// viewer runs in a process of its own ("viewer"): a browser can never disturb the robot's
// processes, and the deployment plan brings it the topics it shows over shared memory.
std::string profileWithViewer(const std::string& path, const RunSettings& view) {
  YAML::Node root = YAML::LoadFile(path);
  if (!root["name"]) root["name"] = fs::path(path).stem().string();
  YAML::Node actors = root["actors"];
  std::string name = "viewer";
  for (int i = 2; actors[name]; ++i) name = "viewer_" + std::to_string(i);
  std::vector<ActorParams> edits;
  for (auto kv : actors) {
    if (!kv.second["params"]) kv.second["params"] = YAML::Node(YAML::NodeType::Map);
    edits.emplace_back(kv.second["type"] ? kv.second["type"].as<std::string>() : "",
                       kv.second["params"]);
  }
  YAML::Node viewer;
  viewer["type"] = "viewer";
  viewer["process"] = "viewer";
  viewer["params"] = viewerParams(view, edits);
  actors[name] = viewer;
  const fs::path copy =
      fs::temp_directory_path() / ("tessera_launch_view_" + std::to_string(::getpid()) + ".yaml");
  {
    std::ofstream out(copy);
    out << "# " << path << " with the live viewer (tessera launch --view)\n"
        << YAML::Dump(root) << "\n";
  }
  ::chmod(copy.c_str(), 0600);
  return copy.string();
}

int launch(const LaunchArgs& a) {
  if (!a.host.empty()) {
    if (a.view.view_port >= 0) throw ConfigError("launch --host: --view is not available yet");
    HostLaunchArgs h;
    h.profile = a.profile;
    h.host = a.host;
    h.out = a.out;
    h.sets = a.sets;
    h.threads = a.threads;
    h.wait_peers_s = a.wait_peers_s;
    return launchHost(h);
  }
  LauncherOptions o;
  o.profile_path = resolveProfilePath(a.profile, profileSearchDirs());
  std::string copy;
  if (a.view.view_port >= 0) o.profile_path = copy = profileWithViewer(o.profile_path, a.view);
  o.sets = a.sets;
  o.out_dir = a.out;
  o.threads = a.threads;
  o.shm_log = a.shm_log;
  o.orphan_grace_s = a.orphan_grace_s;
  Launcher launcher(std::move(o));
  const int code = launcher.run().exit_code;
  if (!copy.empty()) fs::remove(copy);
  return code;
}

struct WorkerArgs {
  std::string profile, process, sync, out, shm_log = "error";
  std::vector<std::string> sets;
  std::size_t max_chunk = 0;
  int incarnation = 0, threads = 0;
  double orphan_grace_s = LauncherOptions{}.orphan_grace_s;
};

/// Watches for the launcher's death on a thread of its own. Then `cut_off` runs at once and the
/// process has `grace` to stop by itself (writing what it holds); after that it leaves without
/// the rest. The grace is the last resort: a thread already blocked in a send to a peer that
/// died with a full queue can never return, as only RouDi (gone with the launcher) could remove
/// that queue.
class OrphanWatch {
 public:
  OrphanWatch(double grace_s, std::function<void()> cut_off)
      : thread_([launcher = ::getppid(), grace_s,
                 cut_off = std::move(cut_off)](const std::stop_token& stop) {
          std::mutex mutex;
          std::condition_variable_any wake;  // woken only by the stop request (the destructor)
          std::unique_lock lock(mutex);
          const auto stopped = [&] { return stop.stop_requested(); };
          // getppid() is a cheap system call; the parent-death signal (SIGHUP) stops the run at
          // the same moment, and the coordinator cuts the transport off before any stop stage.
          while (!wake.wait_for(lock, stop, std::chrono::milliseconds(50), stopped)) {
            if (::getppid() == launcher) continue;
            cut_off();
            if (wake.wait_for(lock, stop, std::chrono::duration<double>(grace_s), stopped)) return;
            std::fprintf(stderr,
                         "the launcher (and its RouDi) died and this process did not stop within "
                         "its %g s grace (a send to a dead peer never returns): leaving\n",
                         grace_s);
            std::_Exit(3);
          }
        }) {}

 private:
  std::jthread thread_;  // its destructor asks the watch to stop and joins it
};

/// RouDi died with the launcher: iceoryx's teardown (deregistering from RouDi) could now block
/// for ever, so the worker leaves without it.
[[noreturn]] void leaveOrphaned(const std::string& what, std::uint64_t unsent) {
  std::cerr << "the launcher (and its RouDi) died: stopped (" << what << "); " << unsent
            << " messages to other processes were not sent\n";
  std::fflush(nullptr);
  std::_Exit(3);
}

int worker(const WorkerArgs& a) {
  ::prctl(PR_SET_TIMERSLACK, 1UL);  // waits for the deployment clock use short sleeps
  // Output goes to a pipe the launcher reads. When the launcher dies, the next line written to
  // it would raise SIGPIPE and kill this process before it writes what it holds: a failed write
  // (EPIPE) is harmless instead.
  ::signal(SIGPIPE, SIG_IGN);
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
  so.routes = routeLedger(plan, sync.ledger());
  ShmTransport transport(so);
  coordinator.whenOrphaned([&transport] { transport.cutOff(); });
  const OrphanWatch orphan_watch(a.orphan_grace_s, [&transport] { transport.cutOff(); });
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
  runtime->installSignalHandlers();  // SIGHUP: the launcher died (PR_SET_PDEATHSIG)
  if (!coordinator.readyAndWait()) {
    coordinator.slot().stopped = 1;  // nothing ran: nothing to stop
    if (coordinator.orphaned()) leaveOrphaned("before the run started", transport.stats().unsent);
    return 130;
  }
  const RunReport report = runtime->run();
  if (coordinator.orphaned())
    leaveOrphaned(report.stop_reason, transport.stats().unsent);  // outputs written
  transport.stopReceiving();
  const auto stats = transport.stats();
  std::cerr << report.table();
  std::cerr << "shared memory: " << stats.sent << " sent, " << stats.received << " received, "
            << stats.copies << " copied into a larger chunk, " << stats.drops
            << " discarded by full keep_latest queues\n";
  bool summary_failed = false;
  if (!a.out.empty()) {
    auto j = summaryJson(profile, report);
    j["shm_sent"] = stats.sent;
    j["shm_received"] = stats.received;
    j["shm_copies"] = stats.copies;
    try {
      tessera::io::writeFileAtomically(fs::path(a.out) / ("summary_" + a.process + ".json"),
                                       j.dump(2) + "\n");
    } catch (const std::exception& e) {
      std::cerr << "error: " << e.what() << "\n";
      summary_failed = true;
    }
  }
  const bool actor_failure = report.interrupted && report.stop_reason.rfind("actor '", 0) == 0;
  return actor_failure || summary_failed ? 1 : 0;
}

}  // namespace

void addLaunchCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand("launch", "run a profile as several processes over shared memory");
  auto args = std::make_shared<LaunchArgs>();
  cmd->add_option("profile", args->profile, "profile name (apps/profiles/NAME.yaml) or path")
      ->required();
  cmd->add_option("--set", args->sets, "override: ACTOR.KEY=VALUE, KEY=VALUE (repeatable)");
  cmd->add_option("--out", args->out, "output folder (created); default: none, nothing is written");
  cmd->add_option(
      "--threads", args->threads,
      "executor threads per process (0: one with a simulated clock, all cores otherwise)");
  cmd->add_option("--shm-log", args->shm_log, "iceoryx log level: off, error, warn, info");
  cmd->add_option("--orphan-grace", args->orphan_grace_s,
                  "seconds a process whose launcher died may take to write what it holds and "
                  "stop before it leaves without the rest (default 30)")
      ->check(finiteNumberIn(0.0, 1e6, true));
  cmd->add_option("--host", args->host,
                  "run only process group NAME here; topics to the other groups cross hosts over "
                  "DDS (profile section dds:)");
  cmd->add_option("--wait-peers", args->wait_peers_s,
                  "--host: seconds to wait for the other hosts before giving up (default 60)");
  addViewOptions(*cmd, args->view);  // the viewer in a process of its own
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
  w->add_option("--orphan-grace", wargs->orphan_grace_s);
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
