// `tessera launch PROFILE --host NAME`: one part of a deployment over several hosts. The actors
// of process group NAME run here in one process; every topic between this group and the others
// crosses hosts over DDS (tessera/dds/dds_transport.hpp). Each host runs the same command with
// its own NAME. docs/architecture.md#several-hosts
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/dds/dds_transport.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/shm/deployment.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

namespace tessera::app {

namespace {

/// A host waits this long for its peers before starting, and says who it waits for this often.
constexpr auto kPeerReport = std::chrono::seconds(5);
// How long a leaving host waits for the other hosts to acknowledge its last reliable samples.
constexpr auto kFlushTimeout = std::chrono::seconds(60);

std::vector<DdsTopic> ddsTopics(const std::vector<ShmTopic>& crossing) {
  std::vector<DdsTopic> out;
  for (const auto& t : crossing) {
    DdsTopic d;
    d.name = t.name;
    d.type = t.type;
    // A group that both publishes and reads a topic reads its own messages in process: DDS
    // carries only what another group publishes or reads.
    d.exported = t.exported && t.importing_processes > (t.imported ? 1u : 0u);
    d.imported = t.imported && t.publishing_processes > (t.exported ? 1u : 0u);
    if (!d.exported && !d.imported) continue;
    d.reliable = t.any_reliable;
    d.depth = std::max<std::uint32_t>(
        t.imported ? static_cast<std::uint32_t>(t.import_policy.capacity) : 4, 1);
    out.push_back(d);
  }
  return out;
}

}  // namespace

int launchHost(const HostLaunchArgs& a) {
  const std::string path = resolveProfilePath(a.profile, profileSearchDirs());
  const Profile profile = loadProfile(path, a.sets);
  if (!profile.has_dds) {
    throw ConfigError(path +
                      ": `launch --host` runs one part of a deployment over DDS and needs a `dds:` "
                      "section naming at least its partition (docs/architecture.md#several-hosts)");
  }
  if (profile.clock == ClockKind::kSimulated && profile.sim_rate <= 0) {
    throw ConfigError(path +
                      ": a deployment over several hosts needs a paced clock (clock: wall, or "
                      "sim_rate > 0): each host keeps its own time");
  }
  const DdsOptions options = loadDdsOptions(profile.dds);
  const DeploymentPlan plan = planDeployment(profile, a.host);
  if (plan.indexOf(a.host) < 0) {
    std::string names;
    for (const auto& p : plan.processes) names += (names.empty() ? "" : ", ") + p;
    throw ConfigError(path + ": --host " + a.host + ": no actor has `process: " + a.host +
                      "` (process groups: " + names + ")");
  }
  for (const auto& [actor, why] : plan.unchecked) {
    std::cerr << "host '" << a.host << "': actor '" << actor
              << "' runs on another host and cannot be checked here (" << why
              << "); what only it publishes or reads does not cross to this host\n";
  }
  for (const auto& [topic, level] : options.compression) {
    bool crosses = false;
    for (const auto& [process, topics] : plan.topics) {
      for (const auto& t : topics) crosses = crosses || t.name == topic;
    }
    if (!crosses) {
      throw ConfigError(profile.dds.where() + ".compression." + topic +
                        ": no such topic crosses between process groups");
    }
  }
  const auto crossing =
      plan.topics.count(a.host) ? plan.topics.at(a.host) : std::vector<ShmTopic>{};
  // A group without inputs of its own (a server) would end at once on a simulated clock, which
  // only moves on its own timers: it runs on the wall clock until its senders leave. Which
  // groups have inputs: a throw-away build, its imports standing in as outside inputs.
  Profile run_profile = profile;
  {
    Profile probe = profile;
    for (const auto& t : crossing) probe.external_inputs.push_back(t.name);
    RuntimeOptions quiet;
    quiet.manual = true;
    quiet.show_progress = false;
    if (buildProcessRuntime(probe, quiet, a.host, {})->finiteSources() == 0 &&
        profile.clock == ClockKind::kSimulated) {
      run_profile.clock = ClockKind::kWall;
      run_profile.max_duration_s = 0;  // the data time of the hosts sending to it
      std::cerr << "host '" << a.host
                << "': no input of its own: runs on the wall clock until the hosts sending to it "
                   "leave\n";
    }
  }
  DdsTransport transport(options, a.host);
  RuntimeOptions ro;
  ro.threads = a.threads;
  ro.output_dir = a.out;
  if (!a.out.empty()) std::filesystem::create_directories(a.out);
  const std::vector<DdsTopic> dds_topics = ddsTopics(crossing);
  auto runtime = buildProcessRuntime(run_profile, ro, a.host,
                                     [&](Runtime& rt) { transport.attach(rt, dds_topics); });
  transport.startReceiving();

  // Start once every topic to and from the other hosts has its peer: what is sent before a
  // reader matched would not reach it.
  std::string names;
  for (const auto& t : dds_topics) {
    names += (names.empty() ? "" : ", ") + t.name +
             (t.exported && t.imported ? " (out, in)"
              : t.exported             ? " (out)"
                                       : " (in)");
  }
  std::cerr << "host '" << a.host << "': DDS domain " << options.domain << ", partition '"
            << options.partition << "': " << names << "\n";
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(a.wait_peers_s);
  while (!transport.waitForPeers(kPeerReport)) {
    std::string waiting;
    for (const auto& u : transport.unconnected()) waiting += (waiting.empty() ? "" : ", ") + u;
    if (std::chrono::steady_clock::now() >= deadline) {
      std::cerr << "error: host '" << a.host << "': no peer within " << a.wait_peers_s << " s for "
                << waiting << "; start the other hosts with `tessera launch " << a.profile
                << " --host NAME`, with the same dds.domain and dds.partition, and check "
                   "dds.interface / dds.peers\n";
      transport.stopReceiving();
      return 1;
    }
    std::cerr << "host '" << a.host << "': waiting for " << waiting << "\n";
  }
  runtime->installSignalHandlers();

  // A host without inputs of its own (a server) ends when every host sending to it left.
  std::atomic<bool> done{false};
  std::thread watcher;
  if (runtime->finiteSources() == 0) {
    watcher = std::thread([&] {
      while (!done.load()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        if (!transport.upstreamLeft()) continue;
        // The senders waited for their last samples to be acknowledged, so those are in this
        // host's readers or being handed over; stop once the readers stayed empty for a moment
        // (the mailboxes drain before the actors stop).
        for (int quiet = 0; quiet < 3 && !done.load();) {
          quiet = transport.drained() ? quiet + 1 : 0;
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        if (done.load()) return;
        std::cerr << "host '" << a.host << "': every host sending to this one left: stopping\n";
        runtime->requestStop();
        return;
      }
    });
  }
  const RunReport report = runtime->run();
  done = true;
  if (watcher.joinable()) watcher.join();
  // Reliable samples still on their way to another host: wait for them before leaving.
  const auto unacknowledged = transport.flush(kFlushTimeout);
  if (!unacknowledged.empty()) {
    std::string names;
    for (const auto& n : unacknowledged) names += (names.empty() ? "" : ", ") + n;
    std::cerr << "warning: host '" << a.host << "': reliable samples on " << names
              << " were not acknowledged by the other hosts within "
              << std::chrono::duration_cast<std::chrono::seconds>(kFlushTimeout).count()
              << " s; they may be lost\n";
  }
  transport.stopReceiving();
  const DdsStats stats = transport.stats();
  std::cerr << report.table();
  const auto total = stats.total();
  std::fprintf(stderr,
               "dds: %llu sent (%.1f MB as %.1f MB on the wire), %llu received, %llu lost, "
               "%llu rejected, %llu replayed twice (skipped)\n",
               static_cast<unsigned long long>(total.sent), total.bytes_raw / 1e6,
               total.bytes_sent / 1e6, static_cast<unsigned long long>(total.received),
               static_cast<unsigned long long>(total.lost),
               static_cast<unsigned long long>(total.rejected),
               static_cast<unsigned long long>(total.duplicates));
  if (!a.out.empty()) {
    auto j = summaryJson(profile, report);
    j["host"] = a.host;
    auto& topics = j["dds_topics"];
    for (const auto& [name, s] : stats.topics) {
      topics[name] = {{"sent", s.sent},
                      {"received", s.received},
                      {"bytes_raw", s.bytes_raw},
                      {"bytes_sent", s.bytes_sent},
                      {"lost", s.lost},
                      {"rejected", s.rejected},
                      {"duplicates", s.duplicates},
                      {"compress_s", s.compress_s},
                      {"decompress_s", s.decompress_s}};
    }
    tessera::io::writeFileAtomically(std::filesystem::path(a.out) / ("summary_" + a.host + ".json"),
                                     j.dump(2) + "\n");
  }
  const bool actor_failure = report.interrupted && report.stop_reason.rfind("actor '", 0) == 0;
  return actor_failure ? 1 : 0;
}

}  // namespace tessera::app
