// tessera bench dds: what crossing hosts costs (docs/architecture.md#several-hosts).
//
// Latency: a leader pings a follower in another process, which answers with a pong of the same
// size, over the loopback interface (unicast discovery, a partition per round), for
//  * dds      our DdsTransport: a Runtime at each end, Cap'n Proto msg::Blob messages, an echo
//             actor that publishes each ping back as its pong;
//  * dds_raw  Cyclone DDS's C API alone with the same Frame type: the follower writes back the
//             sample it took; the floor under ours.
// One-way latency = round trip / 2 (both ends on one clock, so a direct one-way stamp would do
// too; the round trip halves the effect of either side's wake-up). The leader sleeps a gap
// (1 ms) before each ping so both sides are idle, as when sensor data arrives. The two transports
// take turns in rounds (a fresh follower process each), so machine noise hits both alike.
//
// Bandwidth: sim_slam_split (laser) and rgbd_slam_split (visual, --visual DIR) run as two hosts
// (`tessera launch --host`), robot -> server bytes per second of data: raw = the robot's sensor
// topics (every raw frame), sent = what DDS carried from the robot (after zstd), from the hosts'
// summaries; the laser run without the simulator's ground-truth scoring (a robot has none). The
// text output adds the server's throughput from its CPU time: keyframes per second per core
// (visual), robots per core (laser).
#include "bench_commands.hpp"
#include "bench_util.hpp"

#include <tessera/dds/dds_transport.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/runtime.hpp>

#include "tessera_frame.h"

#include <dds/dds.h>
#include <sys/wait.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>

namespace tessera::app {

namespace {

using namespace std::chrono_literals;

constexpr std::array<std::size_t, 3> kPayloads{64, std::size_t{64} << 10, std::size_t{1} << 20};
constexpr std::uint64_t kQuit = ~std::uint64_t{0};

DdsOptions benchDds(const std::string& partition) {
  DdsOptions o;
  o.domain = 42;
  o.interface = "lo";
  o.peers = {"127.0.0.1"};
  o.partition = partition;
  return o;
}

DdsTopic blobTopic(const std::string& name, bool exported) {
  DdsTopic t;
  t.name = name;
  t.type = messageTypeOf<msg::Blob>();
  t.exported = exported;
  t.imported = !exported;
  t.reliable = true;
  return t;
}

RuntimeOptions wallOne() {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 1;
  ro.show_progress = false;
  return ro;
}

double nowUs() {
  return std::chrono::duration<double, std::micro>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// ---------------------------------------------------------------- dds (ours)

/// Follower: a pong of the ping's size and sequence number for every ping; quits on kQuit.
class Echo final : public Actor {
 public:
  explicit Echo(std::atomic<bool>& quit) : quit_(quit) {}
  void configure(ActorContext& ctx) override {
    out_ = ctx.advertise<msg::Blob>("pong");
    ctx.subscribe<msg::Blob>("ping", MailboxPolicy::reliable(16), [this](const auto& m) {
      const std::uint64_t seq = m->getHeader().getSeq();
      out_.publish(m);  // the ping goes back as it came, as raw DDS's follower does
      if (seq == kQuit) {
        quit_ = true;
        quit_.notify_all();
      }
    });
  }

 private:
  std::atomic<bool>& quit_;
  Publisher<msg::Blob> out_;
};

/// Leader side: the sequence number of the last pong.
class Catcher final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("pong", MailboxPolicy::reliable(16), [this](const auto& m) {
      last.store(m->getHeader().getSeq());
      last.notify_all();
    });
  }
  std::atomic<std::uint64_t> last{kQuit - 1};
};

int ddsFollower(const std::string& partition) {
  DdsTransport transport(benchDds(partition), "bench_follower");
  Runtime rt(wallOne());
  std::atomic<bool> quit{false};
  rt.add("echo", std::make_unique<Echo>(quit));
  transport.attach(rt, {blobTopic("ping", false), blobTopic("pong", true)});
  rt.configure();
  rt.start();
  transport.startReceiving();
  quit.wait(false);
  std::this_thread::sleep_for(200ms);  // the last pong out before the participant goes
  transport.stopReceiving();
  rt.stop();
  return 0;
}

/// One-way latencies [us] per payload size.
std::vector<std::vector<double>> ddsLeader(const std::string& partition, int samples) {
  DdsTransport transport(benchDds(partition), "bench_leader");
  Runtime rt(wallOne());
  auto& catcher = static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
  transport.attach(rt, {blobTopic("ping", true), blobTopic("pong", false)});
  auto pub = rt.externalPublisher<msg::Blob>("ping");
  rt.configure(true);
  rt.start();
  transport.startReceiving();
  if (!transport.waitForPeers(30s)) throw std::runtime_error("bench dds: no follower (dds)");
  std::vector<std::vector<double>> out;
  std::uint64_t seq = 0;
  for (std::size_t bytes : kPayloads) {
    auto& lat = out.emplace_back();
    for (int i = -2; i < samples; ++i, ++seq) {  // two warm-up exchanges per size
      auto loan = pub.loan(bytes + 256);
      setHeader(loan->initHeader(), 0, "ping", seq);
      loan->initPayload(static_cast<unsigned>(bytes));
      std::this_thread::sleep_for(1ms);
      const double t0 = nowUs();
      pub.publish(std::move(loan));
      for (auto v = catcher.last.load(); v != seq; v = catcher.last.load()) catcher.last.wait(v);
      if (i >= 0) lat.push_back((nowUs() - t0) / 2);
    }
  }
  auto quit = pub.loan();
  setHeader(quit->initHeader(), 0, "ping", kQuit);
  pub.publish(std::move(quit));
  std::this_thread::sleep_for(300ms);
  transport.stopReceiving();
  rt.stop();
  return out;
}

// ---------------------------------------------------------------- dds_raw

struct RawEnd {
  dds_entity_t participant = 0, writer = 0, reader = 0, waitset = 0;
  explicit RawEnd(const std::string& partition, bool leader) {
    const auto o = benchDds(partition);
    dds_create_domain(o.domain, DdsTransport::configXml(o).c_str());
    participant = dds_create_participant(o.domain, nullptr, nullptr);
    if (participant < 0) throw std::runtime_error("bench dds: no DDS participant");
    dds_qos_t* qos = dds_create_qos();
    dds_qset_partition1(qos, partition.c_str());
    const auto pub = dds_create_publisher(participant, qos, nullptr);
    const auto sub = dds_create_subscriber(participant, qos, nullptr);
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_resource_limits(qos, 64, DDS_LENGTH_UNLIMITED, 64);
    const auto ping =
        dds_create_topic(participant, &tessera_dds_Frame_desc, "raw/ping", nullptr, nullptr);
    const auto pong =
        dds_create_topic(participant, &tessera_dds_Frame_desc, "raw/pong", nullptr, nullptr);
    writer = dds_create_writer(pub, leader ? ping : pong, qos, nullptr);
    reader = dds_create_reader(sub, leader ? pong : ping, qos, nullptr);
    dds_delete_qos(qos);
    waitset = dds_create_waitset(participant);
    dds_waitset_attach(waitset, dds_create_readcondition(reader, DDS_ANY_STATE), 0);
  }
  ~RawEnd() { dds_delete(participant); }
  bool matched() const {
    dds_publication_matched_status_t p{};
    dds_subscription_matched_status_t s{};
    dds_get_publication_matched_status(writer, &p);
    dds_get_subscription_matched_status(reader, &s);
    return p.current_count > 0 && s.current_count > 0;
  }
  /// Takes samples until `handle` returns true for one; false when nothing came for `timeout`.
  template <typename Handle>
  bool take(Handle&& handle, dds_duration_t timeout = DDS_SECS(10)) {
    for (;;) {
      void* samples[1] = {nullptr};
      dds_sample_info_t info;
      const auto n = dds_take(reader, samples, &info, 1, 1);
      if (n > 0) {
        const bool done = info.valid_data && handle(*static_cast<tessera_dds_Frame*>(samples[0]));
        dds_return_loan(reader, samples, n);
        if (done) return true;
        continue;
      }
      dds_attach_t fired;
      if (dds_waitset_wait(waitset, &fired, 1, timeout) <= 0) return false;
    }
  }
};

int rawFollower(const std::string& partition) {
  RawEnd end(partition, false);
  bool quit = false;
  while (!quit) {
    if (!end.take(
            [&](tessera_dds_Frame& f) {
              quit = f.seq == kQuit;
              dds_write(end.writer, &f);  // the taken sample goes back as it is
              return true;
            },
            DDS_SECS(60)))
      return 3;
  }
  std::this_thread::sleep_for(200ms);
  return 0;
}

std::vector<std::vector<double>> rawLeader(const std::string& partition, int samples) {
  RawEnd end(partition, true);
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!end.matched()) {
    if (std::chrono::steady_clock::now() > deadline)
      throw std::runtime_error("bench dds: no follower (dds_raw)");
    std::this_thread::sleep_for(5ms);
  }
  std::vector<std::vector<double>> out;
  std::uint64_t seq = 0;
  for (std::size_t bytes : kPayloads) {
    std::vector<std::uint8_t> payload(bytes);
    auto& lat = out.emplace_back();
    for (int i = -2; i < samples; ++i, ++seq) {
      tessera_dds_Frame f{};
      f.seq = seq;
      f.raw_bytes = static_cast<std::uint32_t>(bytes);
      f.payload._buffer = payload.data();
      f.payload._length = f.payload._maximum = static_cast<std::uint32_t>(bytes);
      std::this_thread::sleep_for(1ms);
      const double t0 = nowUs();
      dds_write(end.writer, &f);
      if (!end.take([&](tessera_dds_Frame& r) { return r.seq == seq; }))
        throw std::runtime_error("bench dds: pong lost (dds_raw)");
      if (i >= 0) lat.push_back((nowUs() - t0) / 2);
    }
  }
  tessera_dds_Frame q{};
  q.seq = kQuit;
  dds_write(end.writer, &q);
  end.take([](tessera_dds_Frame& r) { return r.seq == kQuit; }, DDS_SECS(2));
  return out;
}

// ---------------------------------------------------------------- processes

/// `tessera bench dds --follow TRANSPORT --partition P` in a fresh process (no DDS state
/// inherited); returns its pid.
pid_t spawnFollower(const std::string& transport, const std::string& partition) {
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("bench dds: fork failed");
  if (pid == 0) {
    ::execl("/proc/self/exe", "tessera", "bench", "dds", "--follow", transport.c_str(),
            "--partition", partition.c_str(), static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  return pid;
}

int reap(pid_t pid) {
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

struct Options {
  int samples = 200;
  int rounds = 3;
  double bandwidth_seconds = 120;
  std::string visual = "../shared/data/7scenes-redkitchen-rgbd";
  bool visual_given = false;
  bool json = false;
  std::string follow, partition;  // internal: follower mode
};

/// One pipeline's robot -> server figures, from a two-host run of its split profile.
struct Pipeline {
  std::string name;                        // "laser" | "visual"
  std::string profile;                     // the split profile
  std::vector<std::string> sensor_topics;  // what sending every raw frame would carry
  std::string robot_sets;                  // extra --set options for the robot
  std::string common_sets;                 // for both hosts
  /// Server throughput: per message of this topic ("keyframes"), or, when empty, per data second
  /// (robots one server core keeps up with).
  std::string unit_topic;
};

/// Runs `p` as two hosts; raw = the robot's sensor topics' bytes, sent = the bytes DDS carried
/// from the robot, both per data second. Also prints both and the bytes before compression.
nlohmann::json pipelineBandwidth(const Pipeline& p, bool quiet) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() /
                       ("tessera_bench_dds_" + std::to_string(::getpid()) + "_" + p.name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string common = " --set dds.partition=tessera_bench_dds_" +
                             std::to_string(::getpid()) + "_" + p.name +
                             " --set dds.interface=lo --set dds.peers=[127.0.0.1]" + p.common_sets;
  auto host = [&](const std::string& name, const std::string& extra) {
    const std::string cmd = fs::read_symlink("/proc/self/exe").string() + " launch " + p.profile +
                            " --host " + name + " --out " + (dir / name).string() + common + extra +
                            " > " + (dir / (name + ".log")).string() + " 2>&1";
    return std::system(cmd.c_str());
  };
  if (!quiet) std::cerr << "bandwidth: " << p.profile << " as two hosts\n";
  int server_rc = -1;
  std::thread server_host([&] { server_rc = host("server", ""); });
  const int robot_rc = host("robot", p.robot_sets);
  server_host.join();
  if (robot_rc != 0 || server_rc != 0) {
    throw std::runtime_error("bench dds: the two-host " + p.profile + " run failed; logs in " +
                             dir.string());
  }
  std::ifstream in(dir / "robot" / "summary_robot.json");
  const auto robot = nlohmann::json::parse(in);
  std::ifstream server_in(dir / "server" / "summary_server.json");
  const auto server = nlohmann::json::parse(server_in);
  double raw = 0, crossing = 0, sent = 0;
  for (const auto& t : p.sensor_topics) {
    if (!robot["topics"].contains(t)) {
      throw std::runtime_error("bench dds: " + p.profile + "'s robot published no '" + t + "'");
    }
    raw += robot["topics"][t]["bytes"].get<double>();
  }
  for (const auto& [topic, s] : robot["dds_topics"].items()) {
    crossing += s["bytes_raw"].get<double>();
    sent += s["bytes_sent"].get<double>();
  }
  const double data_s = robot["data_duration_s"].get<double>();
  fs::remove_all(dir);
  if (!quiet) {
    std::printf(
        "bandwidth robot -> server, %s (%s, %.0f s of data): every raw frame %.0f B/s; sent %.0f "
        "B/s (%.0f B/s before zstd): %.1fx less\n",
        p.name.c_str(), p.profile.c_str(), data_s, raw / data_s, sent / data_s, crossing / data_s,
        sent > 0 ? raw / sent : 0.0);
    // The server's CPU time (all its threads, the DDS receiver included) for what it processed.
    const double server_cpu_s = server["cpu_s"].get<double>();
    if (!p.unit_topic.empty()) {
      const double units = server["dds_topics"][p.unit_topic]["received"].get<double>();
      std::printf("server throughput, %s: %.0f %s in %.2f s of CPU: %.1f %s per second per core\n",
                  p.name.c_str(), units, p.unit_topic.c_str(), server_cpu_s,
                  server_cpu_s > 0 ? units / server_cpu_s : 0.0, p.unit_topic.c_str());
    } else {
      std::printf(
          "server throughput, %s: %.2f s of CPU for %.0f s of data: one core keeps up with %.1f "
          "robots\n",
          p.name.c_str(), server_cpu_s, data_s, server_cpu_s > 0 ? data_s / server_cpu_s : 0.0);
    }
    // Work a saturated server skipped (keep_latest queues) makes its CPU figure too low.
    std::uint64_t drops = 0;
    for (const auto& [name, a] : server["actors"].items()) drops += a["drops"].get<std::uint64_t>();
    if (drops > 0) {
      std::printf(
          "  (the server dropped %llu messages from keep_latest queues: it fell behind, "
          "so this throughput is an upper bound)\n",
          static_cast<unsigned long long>(drops));
    }
  }
  return {
      {"pipeline", p.name}, {"bytes_per_s_raw", raw / data_s}, {"bytes_per_s_sent", sent / data_s}};
}

void runBench(const Options& o) {
  if (o.samples < 1 || o.rounds < 1) throw ConfigError("bench dds: --samples and --rounds >= 1");
  const bool visual = !o.visual.empty() && std::filesystem::is_directory(o.visual);
  if (!o.visual.empty() && !visual) {
    if (o.visual_given) {
      throw ConfigError("bench dds: --visual " + o.visual +
                        ": no such folder (expected a TUM RGB-D or 7-Scenes folder; '' skips the "
                        "visual pipeline)");
    }
    std::cerr << "bench dds: " << o.visual
              << " is absent: the visual pipeline is skipped (--visual DIR names the frames)\n";
  }
  std::map<std::string, std::vector<std::vector<double>>> all;  // transport -> size -> samples
  const int per_round = (o.samples + o.rounds - 1) / o.rounds;
  // Each side of every round in a fresh process; this one only starts and reaps them, so it
  // never holds DDS state across a fork.
  for (int r = 0; r < o.rounds; ++r) {
    for (const std::string transport : {"dds", "dds_raw"}) {
      const std::string partition = "tessera_bench_dds_" + std::to_string(::getpid()) + "_" +
                                    transport + "_" + std::to_string(r);
      const pid_t follower = spawnFollower(transport, partition);
      int pipe_fds[2];
      if (::pipe(pipe_fds) != 0) throw std::runtime_error("bench dds: pipe failed");
      const pid_t leader = ::fork();
      if (leader == 0) {
        ::close(pipe_fds[0]);
        int code = 0;
        try {
          const auto lat = transport == "dds" ? ddsLeader(partition, per_round)
                                              : rawLeader(partition, per_round);
          std::string text;
          for (const auto& size : lat) {
            for (double v : size) text.append(std::to_string(v)).append(" ");
            text.append("\n");
          }
          (void)!::write(pipe_fds[1], text.data(), text.size());
        } catch (const std::exception& e) {
          std::fprintf(stderr, "error: %s\n", e.what());
          code = 1;
        }
        ::close(pipe_fds[1]);
        std::fflush(nullptr);
        std::_Exit(code);
      }
      ::close(pipe_fds[1]);
      std::string text;
      char buf[4096];
      for (ssize_t n; (n = ::read(pipe_fds[0], buf, sizeof buf)) > 0;) text.append(buf, n);
      ::close(pipe_fds[0]);
      const int leader_rc = reap(leader);
      const int follower_rc = reap(follower);
      if (leader_rc != 0 || follower_rc != 0) {
        throw std::runtime_error("bench dds: round " + std::to_string(r) + " of " + transport +
                                 " failed (leader " + std::to_string(leader_rc) + ", follower " +
                                 std::to_string(follower_rc) + ")");
      }
      auto& sizes = all[transport];
      sizes.resize(kPayloads.size());
      std::istringstream lines(text);
      std::string line;
      for (std::size_t s = 0; s < kPayloads.size() && std::getline(lines, line); ++s) {
        std::istringstream values(line);
        for (double v; values >> v;) sizes[s].push_back(v);
      }
      if (!o.json) std::cerr << "round " << r + 1 << "/" << o.rounds << ": " << transport << "\n";
    }
  }
  nlohmann::json results = nlohmann::json::array();
  for (const std::string transport : {"dds", "dds_raw"}) {
    for (std::size_t s = 0; s < kPayloads.size(); ++s) {
      const auto& v = all[transport][s];
      results.push_back({{"transport", transport},
                         {"payload_bytes", kPayloads[s]},
                         {"p50_us", percentile(v, 0.5)},
                         {"p99_us", percentile(v, 0.99)}});
    }
  }
  if (!o.json) {
    std::cout << "machine: " << machineDescription() << "\n"
              << "one-way latency over loopback (round trip / 2), " << o.samples
              << " ping-pongs per size, 1 ms apart\n";
    std::printf("%-8s %10s %10s %10s %12s\n", "transport", "payload", "p50 us", "p99 us",
                "p50 / raw");
    for (std::size_t s = 0; s < kPayloads.size(); ++s) {
      for (const auto& r : results) {
        if (r["payload_bytes"] != kPayloads[s]) continue;
        const double raw = results[kPayloads.size() + s]["p50_us"].get<double>();
        std::printf("%-8s %10zu %10.1f %10.1f %12.2f\n", r["transport"].get<std::string>().c_str(),
                    kPayloads[s], r["p50_us"].get<double>(), r["p99_us"].get<double>(),
                    r["p50_us"].get<double>() / raw);
      }
    }
    std::fflush(stdout);
  }
  nlohmann::json bandwidth = nlohmann::json::array();
  if (o.bandwidth_seconds > 0) {
    bandwidth.push_back(
        pipelineBandwidth({"laser",
                           "sim_slam_split",
                           {"scan", "odom"},
                           " --set sim_rate=12",
                           // Ground-truth scoring off: a real robot has no ground truth to
                           // send, and the simulator's would be half of what crosses.
                           " --set max_duration_s=" + std::to_string(o.bandwidth_seconds) +
                               " --set loops.score_ground_truth=false",
                           ""},
                          o.json));
  }
  if (visual) {
    bandwidth.push_back(pipelineBandwidth({"visual",
                                           "rgbd_slam_split",
                                           {"rgbd"},
                                           " --set sim_rate=3 --set player.path=" + o.visual,
                                           "",
                                           "keyframes"},
                                          o.json));
  }
  if (o.json) {
    std::cout << nlohmann::json{{"machine", machineDescription()},
                                {"results", results},
                                {"bandwidth", bandwidth}}
                     .dump(2)
              << "\n";
    return;
  }
}

}  // namespace

void addBenchDdsCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "dds",
      "latency between two processes over DDS (ours vs raw Cyclone DDS) and the robot -> "
      "server bandwidth of sim_slam_split");
  auto o = std::make_shared<Options>();
  cmd->add_option("--samples", o->samples, "ping-pongs per transport and payload size");
  cmd->add_option("--rounds", o->rounds, "rounds in which the two transports take turns");
  cmd->add_option("--bandwidth-seconds", o->bandwidth_seconds,
                  "data seconds of the two-host sim_slam_split run (0: skip)");
  auto* visual = cmd->add_option("--visual", o->visual,
                                 "RGB-D folder for the two-host rgbd_slam_split run ('' skips it)");
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->add_option("--follow", o->follow)->group("");  // internal: a follower process
  cmd->add_option("--partition", o->partition)->group("");
  cmd->callback([o, visual, &result] {
    if (!o->follow.empty()) {
      result = o->follow == "dds" ? ddsFollower(o->partition) : rawFollower(o->partition);
      return;
    }
    o->visual_given = visual->count() > 0;
    runBench(*o);
    result = 0;
  });
}

}  // namespace tessera::app
