// `tessera bench viewer`: what the live viewer costs a running pipeline, and how soon a map
// update reaches a client (docs/viewer.md#live). A profile (--profile: sim_slam_global, the
// two-level SLAM, or sim_nav, MCL + navigation; both 10 Hz scans) runs at real time for
// --seconds, alternately without and with a viewer that has one client attached, for --rounds
// pairs (interleaved: the machine's noise hits both alike). The client subscribes to what the
// web page shows by default (map and costmap tiles, scan, poses, frames, trajectories, submaps,
// loops, path, the dynamic window's arcs, navigation status, metrics) and runs in this process:
// its own CPU (its threads' clocks) is taken out of the "with" figure, as a browser's would be
// in its own process. sim_slam_global's map assembler publishes once a second in both variants,
// as it does under --view.
//
// Map latency: from the viewer receiving a map or costmap (the wall time in the tiles' header) to
// the client having its tiles; the mailbox hand-off before it is the runtime's (bench runtime).
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "cli_inputs.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/viewer/foxglove_client.hpp>
#include <tessera/viewer/foxglove_server.hpp>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <iomanip>
#include <iostream>
#include <set>
#include <thread>

namespace tessera::app {

namespace {

struct Options {
  std::string profile = "sim_slam_global";
  double seconds = 30;
  int rounds = 3;
  bool json = false;
};

// A port nobody listens on now (the viewer binds it a moment later).
int freePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0)
    throw std::runtime_error("bench viewer: no free local port");
  ::close(fd);
  return ntohs(a.sin_port);
}

struct Round {
  double cpu_s = 0;         // the run's process CPU, minus the client's
  double client_cpu_s = 0;  // the client's threads
  double wall_s = 0;
  std::vector<double> latency_ms;
  std::uint64_t messages = 0;
};

std::int64_t wallNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Round runOnce(const std::string& name, double seconds, bool with_viewer) {
  std::vector<std::string> sets;
  if (name == "sim_slam_global") sets.push_back("assembler.publish_period_s=1");
  Profile profile = loadProfile(resolveProfilePath(name, profileSearchDirs()), sets);
  profile.sim_rate = 1;
  profile.max_duration_s = seconds;  // buildRuntime takes the limit from the profile
  const int port = with_viewer ? freePort() : 0;
  if (with_viewer) {
    YAML::Node params;
    params["port"] = port;
    ActorSpec viewer;
    viewer.name = "viewer";
    viewer.type = "viewer";
    viewer.params = Params(params, "bench viewer");
    profile.actors.push_back(viewer);
  }
  RuntimeOptions ro;
  ro.show_progress = false;
  ro.threads = 2;
  auto runtime = buildRuntime(profile, ro);

  Round r;
  std::atomic<bool> done{false};
  std::thread client_thread;
  if (with_viewer) {
    client_thread = std::thread([&] {
      const double cpu0 = threadCpuSeconds();
      std::unique_ptr<viewer::FoxgloveClient> client;
      for (int i = 0; i < 100 && !client && !done; ++i) {
        try {
          client = std::make_unique<viewer::FoxgloveClient>(
              "ws://127.0.0.1:" + std::to_string(port), 1000);
        } catch (const viewer::ServerError&) {
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
      }
      if (!client) return;
      const std::set<std::string> page = {
          "map/tiles",  "costmap/tiles",    "scan",           "pose",        "localized_pose",
          "tf",         "trajectory_final", "submap_poses",   "constraints", "path",
          "local_plan", "nav_status",       "tessera/metrics"};
      std::set<std::uint32_t> tiles;  // the map's and the costmap's
      std::set<std::uint32_t> first_seen;
      for (const auto& c : client->channels())
        if (page.count(c.topic)) {
          client->subscribe(c.id);
          if (c.encoding == "tessera.tiles") tiles.insert(c.id);
        }
      while (!done) {
        auto m = client->next(100);
        if (!m) continue;
        ++r.messages;
        // Parts header: u8 reset | u32 header bytes | f64 res, f64 x, f64 y, u32 T, i64 stamp,
        // i64 wall time the viewer received the map.
        // The first tiles a client gets on subscribing are as old as the grid is: not a
        // delivery time.
        if (tiles.count(m->channel) && !first_seen.insert(m->channel).second &&
            m->payload.size() >= 5 + 44) {
          std::int64_t received;
          std::memcpy(&received, m->payload.data() + 5 + 36, 8);
          r.latency_ms.push_back(static_cast<double>(wallNowNs() - received) * 1e-6);
        }
      }
      r.client_cpu_s = threadCpuSeconds() - cpu0 + client->networkCpuSeconds();
    });
  }
  const RunReport report = runtime->run();
  done = true;
  if (client_thread.joinable()) client_thread.join();
  r.wall_s = report.wall_s;
  r.cpu_s = report.cpu_s - r.client_cpu_s;

  return r;
}

}  // namespace

void addBenchViewerCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "viewer",
      "the live viewer's cost to a real-time run (sim_slam_global or sim_nav) with one client "
      "attached, and its map-update latency");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profile", o->profile, "sim_slam_global (SLAM) or sim_nav (navigation)")
      ->check(CLI::IsMember({"sim_slam_global", "sim_nav"}))
      ->capture_default_str();
  cmd->add_option("--seconds", o->seconds, "simulated = wall seconds per run")
      ->capture_default_str();
  cmd->add_option("--rounds", o->rounds, "pairs of runs (without, with the viewer)")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (!(o->seconds >= 5)) throw std::runtime_error("bench viewer: --seconds must be >= 5");
    if (o->rounds < 1) throw std::runtime_error("bench viewer: --rounds must be >= 1");
    std::vector<double> without, with, client, overhead_pct, overhead_core, latency;
    std::uint64_t messages = 0;
    for (int i = 0; i < o->rounds; ++i) {
      std::cerr << "[bench viewer] round " << i + 1 << "/" << o->rounds << ": without ...\n";
      const Round a = runOnce(o->profile, o->seconds, false);
      std::cerr << "[bench viewer] round " << i + 1 << "/" << o->rounds
                << ": with the viewer and one client ...\n";
      const Round b = runOnce(o->profile, o->seconds, true);
      without.push_back(a.cpu_s);
      with.push_back(b.cpu_s);
      client.push_back(b.client_cpu_s);
      overhead_pct.push_back(100.0 * (b.cpu_s - a.cpu_s) / a.cpu_s);
      overhead_core.push_back((b.cpu_s - a.cpu_s) / b.wall_s);
      latency.insert(latency.end(), b.latency_ms.begin(), b.latency_ms.end());
      messages += b.messages;
    }
    const nlohmann::json j{{"machine", machineDescription()},
                           {"profile", o->profile},
                           {"seconds", o->seconds},
                           {"rounds", o->rounds},
                           {"cpu_without_s", without},
                           {"cpu_with_s", with},
                           {"client_cpu_s", client},
                           {"overhead_pct_median", percentile(overhead_pct, 0.5)},
                           {"overhead_core_fraction_median", percentile(overhead_core, 0.5)},
                           {"map_updates", latency.size()},
                           {"map_latency_ms_median", percentile(latency, 0.5)},
                           {"map_latency_ms_p95", percentile(latency, 0.95)},
                           {"client_messages", messages}};
    if (o->json) {
      std::cout << j.dump(2) << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << std::fixed << std::setprecision(2) << "pipeline CPU         "
              << percentile(without, 0.5) << " s without, " << percentile(with, 0.5)
              << " s with the viewer (medians of " << o->rounds << " x " << o->seconds << " s of "
              << o->profile << " at real time)\n"
              << "viewer overhead      " << percentile(overhead_pct, 0.5) << " % of the pipeline ("
              << std::setprecision(3) << percentile(overhead_core, 0.5) << " of a core)\n"
              << std::setprecision(2) << "client               " << percentile(client, 0.5)
              << " s CPU, " << messages << " messages (not counted above)\n"
              << "map update latency   " << percentile(latency, 0.5) << " ms median, "
              << percentile(latency, 0.95) << " ms p95 (" << latency.size()
              << " updates; viewer receipt to client)\n";
    result = 0;
  });
}

}  // namespace tessera::app
