// Split profiles as several hosts: `tessera launch --host server` and `--host robot` (or r1, r2)
// as processes that share no memory, their topics over Cyclone DDS, checked against the same
// profile in one process. Where the machine allows it (root and iproute2: CI), each host runs in
// its own network namespace, the namespaces joined by veth pairs on a bridge of their own, so
// the hosts share no network interface either; elsewhere they meet on the loopback interface
// (unicast discovery, a partition of this test alone) and the test says so.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/mapping3d/cloud_map.hpp>

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "../shared_data.hpp"
#include "run_profile.hpp"

namespace split_hosts_test {

using namespace tessera;
namespace fs = std::filesystem;

/// `PREFIX tessera ARGS` (a prefix such as `ip netns exec NS `), output in `log`; the exit
/// status.
int runTessera(const std::string& prefix, const std::string& args, const fs::path& log) {
  const std::string command =
      prefix + std::string(TESSERA_CLI_PATH) + " " + args + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string readText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Fraction of `reference`'s occupied cells with an occupied cell of `map` within one cell.
double occupiedAgreement(const grid::OccupancyMap& reference, const grid::OccupancyMap& map) {
  std::size_t occupied = 0, found = 0;
  for (int row = 0; row < reference.height; ++row)
    for (int col = 0; col < reference.width; ++col) {
      if (reference.at(col, row) < 65) continue;
      ++occupied;
      const Eigen::Vector2i c = map.cellOf(reference.cellCenter(col, row));
      bool hit = false;
      for (int dr = -1; dr <= 1 && !hit; ++dr)
        for (int dc = -1; dc <= 1 && !hit; ++dc)
          hit = map.contains(c.x() + dc, c.y() + dr) && map.at(c.x() + dc, c.y() + dr) >= 65;
      found += hit ? 1 : 0;
    }
  return occupied == 0 ? 0.0 : static_cast<double>(found) / static_cast<double>(occupied);
}

/// Translation ATE (rmse, m) of `out`/one/`file` and of `out`/`host`/`file` against the
/// one-process run's ground truth.
std::pair<double, double> ateOneAndSplit(const fs::path& out, const std::string& file,
                                         const std::string& host) {
  const auto truth = mapping::readTum(out / "one" / "ground_truth.tum");
  const auto ate = [&](const fs::path& tum) {
    return evaluation::computeAte(mapping::readTum(tum), truth).translation.rmse;
  };
  return {ate(out / "one" / file), ate(out / host / file)};
}

/// Network namespaces for `hosts` (one each, 10.213.0.k/24 on a veth pair to a bridge in a
/// namespace of its own), removed on destruction. isolated() is false, with why(), where they
/// cannot be made (not root, no `ip`, a sandbox without network namespaces).
class HostNetwork {
 public:
  explicit HostNetwork(std::size_t hosts) {
    const std::string id = std::to_string(::getpid() % 100000) + "_" + std::to_string(next_++);
    const auto ip = [](const std::string& args) {
      return std::system(("ip " + args + " > /dev/null 2>&1").c_str()) == 0;
    };
    switch_ = "tsw_" + id;
    if (!ip("netns add " + switch_)) {
      why_ = "cannot create network namespaces (needs root and iproute2)";
      switch_.clear();
      return;
    }
    bool ok = ip("-n " + switch_ + " link add br0 type bridge") &&
              ip("-n " + switch_ + " link set br0 up");
    for (std::size_t k = 0; k < hosts && ok; ++k) {
      const std::string ns = "th" + std::to_string(k) + "_" + id;
      const std::string dev = "vh" + std::to_string(k) + "_" + id;
      const std::string peer = "vs" + std::to_string(k) + "_" + id;
      const std::string address = "10.213.0." + std::to_string(k + 1);
      ok = ip("netns add " + ns);
      if (ok) namespaces_.push_back(ns);
      ok = ok &&
           ip("link add " + dev + " netns " + ns + " type veth peer name " + peer + " netns " +
              switch_) &&
           ip("-n " + switch_ + " link set " + peer + " master br0") &&
           ip("-n " + switch_ + " link set " + peer + " up") &&
           ip("-n " + ns + " addr add " + address + "/24 dev " + dev) &&
           ip("-n " + ns + " link set " + dev + " up") && ip("-n " + ns + " link set lo up");
      devices_.push_back(dev);
      addresses_.push_back(address);
    }
    if (!ok) {
      why_ = "could not wire the network namespaces (veth, bridge)";
      remove();
    }
  }
  ~HostNetwork() { remove(); }
  HostNetwork(const HostNetwork&) = delete;
  HostNetwork& operator=(const HostNetwork&) = delete;

  bool isolated() const { return !switch_.empty(); }
  const std::string& why() const { return why_; }
  /// The command prefix that runs host k in its namespace ("" on loopback).
  std::string prefix(std::size_t k) const {
    return isolated() ? "ip netns exec " + namespaces_[k] + " " : "";
  }
  /// The dds settings of host k: its interface and every host's address as peers.
  std::string ddsSets(std::size_t k) const {
    if (!isolated()) return " --set dds.interface=lo --set dds.peers=[127.0.0.1]";
    std::string peers;
    for (const auto& a : addresses_) peers += (peers.empty() ? "" : ",") + a;
    return " --set dds.interface=" + devices_[k] + " --set dds.peers=[" + peers + "]";
  }

 private:
  void remove() {
    for (const auto& ns : namespaces_)
      std::system(("ip netns del " + ns + " > /dev/null 2>&1").c_str());
    if (!switch_.empty()) std::system(("ip netns del " + switch_ + " > /dev/null 2>&1").c_str());
    namespaces_.clear();
    switch_.clear();
  }

  static inline int next_ = 0;
  std::string switch_, why_;
  std::vector<std::string> namespaces_, devices_, addresses_;
};

/// Runs `profile` as a server and the given robot hosts, each `tessera launch --host NAME` (all
/// at once), each in its own network namespace where possible (HostNetwork), else on the loopback
/// interface, in a partition of this test; outputs and logs under `out` (NAME/, NAME.log).
/// `robot_sets` go to the robots, `server_sets` to the server. Returns the exit codes in the
/// order of `robots`, the server's last.
std::vector<int> runHosts(const std::string& profile, const fs::path& out,
                          const std::vector<std::string>& robots, const std::string& robot_sets,
                          const std::string& server_sets = "") {
  const std::string dds =
      " --set dds.partition=tessera_e2e_" + profile + "_" + std::to_string(::getpid());
  std::vector<std::string> names = robots;
  names.push_back("server");
  const HostNetwork network(names.size());
  if (network.isolated())
    std::cout << "[split_hosts] " << profile << ": " << names.size()
              << " hosts in their own network namespaces (veth pairs on a bridge)\n";
  else
    WARN(profile << ": hosts on the loopback interface: " << network.why());
  std::vector<int> status(names.size(), -1);
  std::vector<std::thread> hosts;
  for (std::size_t k = 0; k < names.size(); ++k)
    hosts.emplace_back([&, k] {
      status[k] =
          runTessera(network.prefix(k),
                     "launch " + profile + " --host " + names[k] + " --wait-peers 60 --out " +
                         (out / names[k]).string() + dds + network.ddsSets(k) +
                         (k < robots.size() ? robot_sets : server_sets),
                     out / (names[k] + ".log"));
    });
  for (auto& h : hosts) h.join();
  return status;
}

/// runHosts with one robot host, "robot": (robot, server) exit codes.
std::pair<int, int> runTwoHosts(const std::string& profile, const fs::path& out,
                                const std::string& robot_sets) {
  const auto status = runHosts(profile, out, {"robot"}, robot_sets);
  return {status[0], status[1]};
}

/// The two reliable-topic checks of a split run: every message the robot sent arrived.
void checkNothingLost(const nlohmann::json& robot, const nlohmann::json& server,
                      std::initializer_list<const char*> topics) {
  for (const char* topic : topics) {
    INFO(topic);
    CHECK(robot["dds_topics"][topic]["sent"].get<std::int64_t>() > 0);
    CHECK(server["dds_topics"][topic]["received"] == robot["dds_topics"][topic]["sent"]);
    CHECK(server["dds_topics"][topic]["lost"] == 0);
  }
}

TEST_CASE("sim_slam_split on two hosts over DDS maps as one process does, nothing reliable lost",
          "[e2e][dds]") {
  const fs::path out = test::scratchDir("sim_slam_split");
  const auto [robot_status, server_status] =
      runTwoHosts("sim_slam_split", out, " --set sim_rate=12");
  INFO("robot:\n" << readText(out / "robot.log").substr(0, 4000));
  INFO("server:\n" << readText(out / "server.log").substr(0, 4000));
  REQUIRE(robot_status == 0);
  REQUIRE(server_status == 0);

  const RunReport one = test::runProfile("sim_slam_split", out / "one", {"sim_rate=0"});
  const auto [one_final, split_final] = ateOneAndSplit(out, "trajectory_final.tum", "server");
  const auto [one_live, split_live] = ateOneAndSplit(out, "trajectory.tum", "robot");
  INFO("final ATE one process " << one_final << " m, two hosts " << split_final << " m; live ATE "
                                << one_live << " / " << split_live << " m");
  CHECK(split_final < one_final + 0.03);
  CHECK(split_live < one_live + 0.05);

  const auto server = nlohmann::json::parse(readText(out / "server" / "summary_server.json"));
  const auto robot = nlohmann::json::parse(readText(out / "robot" / "summary_robot.json"));
  // Every message the robot sent on a reliable topic arrived. chained_pose, ground_truth and the
  // loop scans have only keep_latest subscribers, so they cross best-effort: a sample can be
  // dropped (it was, once, the last pose in the burst at the robot's stop); nearly all arrive.
  checkNothingLost(robot, server, {"submaps", "constraints", "final_poses"});
  for (const char* topic : {"chained_pose", "ground_truth", "loop_scans"}) {
    INFO(topic);
    CHECK(server["dds_topics"][topic]["received"].get<double>() >=
          0.99 * robot["dds_topics"][topic]["sent"].get<double>());
  }
  // Submaps cross compressed.
  CHECK(robot["dds_topics"]["submaps"]["bytes_sent"].get<double>() <
        0.8 * robot["dds_topics"]["submaps"]["bytes_raw"].get<double>());
  const std::int64_t loops_true = server["loops_true"];
  const std::int64_t loops_false = server["loops_false"];
  INFO("loops on the server: " << loops_true << " true, " << loops_false << " false; one process "
                               << test::summaryInt(one, "loops", "loops_true"));
  // On the wall clock the server's loop detector skips scans when it falls behind (a keep_latest
  // queue, as in one process on a real robot), so it closes fewer loops than a simulated-time run.
  CHECK(loops_false == 0);
  CHECK(loops_true >= 8);

  const auto one_map = mapping::loadMap(out / "one" / "map.yaml");
  const auto split_map = mapping::loadMap(out / "server" / "map.yaml");
  const double agreement = occupiedAgreement(one_map, split_map);
  INFO("occupied cells of the one-process map found in the two-host map: " << agreement);
  CHECK(agreement > 0.9);
}

TEST_CASE(
    "rgbd_slam_split on two hosts over DDS: the same keyframe trajectory as one process, 20x "
    "fewer bytes than the frames",
    "[e2e][dds][rgbd]") {
  TESSERA_SHARED_DATA(data, "7scenes-redkitchen-rgbd");
  const fs::path out = test::scratchDir("rgbd_slam_split");
  const auto [robot_status, server_status] =
      runTwoHosts("rgbd_slam_split", out, " --set sim_rate=3 --set player.path=" + data.string());
  INFO("robot:\n" << readText(out / "robot.log").substr(0, 4000));
  INFO("server:\n" << readText(out / "server.log").substr(0, 4000));
  REQUIRE(robot_status == 0);
  REQUIRE(server_status == 0);

  fs::create_directories(out / "one");
  test::runProfile("rgbd_slam_split", out / "one", {"sim_rate=0", "player.path=" + data.string()});
  // The robot's front end sees every frame in both runs; the server optimises the same keyframes
  // and loops.
  const auto [one_keyframes, split_keyframes] = ateOneAndSplit(out, "keyframes.tum", "server");
  const auto [one_frames, split_frames] = ateOneAndSplit(out, "trajectory_optimized.tum", "server");
  INFO("keyframe ATE one process " << one_keyframes << " m, two hosts " << split_keyframes
                                   << " m; every frame " << one_frames << " / " << split_frames);
  CHECK(std::abs(split_keyframes - one_keyframes) < 0.001);
  CHECK(std::abs(split_frames - one_frames) < 0.001);
  const auto [one_tracked, split_tracked] = ateOneAndSplit(out, "trajectory.tum", "robot");
  CHECK(split_tracked == Approx(one_tracked));

  const auto server = nlohmann::json::parse(readText(out / "server" / "summary_server.json"));
  const auto robot = nlohmann::json::parse(readText(out / "robot" / "summary_robot.json"));
  checkNothingLost(robot, server, {"keyframes", "camera_pose"});
  CHECK(server["actors"]["loops"]["published"].get<std::int64_t>() >= 1);
  // The frames the robot read against everything it sent the server.
  const double frames = robot["topics"]["rgbd"]["bytes"].get<double>();
  double sent = 0;
  for (const auto& [topic, s] : robot["dds_topics"].items()) sent += s["bytes_sent"].get<double>();
  INFO("frames " << frames << " bytes, sent " << sent << " bytes");
  CHECK(frames > 20 * sent);
  CHECK(server["actors"]["mapper"]["keyframes_mapped"] ==
        robot["actors"]["front_end"]["keyframes"]);
  // The server's cloud is the one-process cloud.
  const auto one_cloud = mapping3d::readPcd(out / "one" / "cloud.pcd");
  const auto split_cloud = mapping3d::readPcd(out / "server" / "cloud.pcd");
  CHECK(one_cloud.size() > 10000);
  CHECK(std::abs(static_cast<double>(split_cloud.size()) - static_cast<double>(one_cloud.size())) <
        0.01 * static_cast<double>(one_cloud.size()));
}

/// `tessera ARGS` started in the background, output in `log`; its pid.
pid_t startTessera(const std::string& args, const fs::path& log) {
  const std::string command =
      "exec " + std::string(TESSERA_CLI_PATH) + " " + args + " > " + log.string() + " 2>&1";
  const char* argv[] = {"/bin/sh", "-c", command.c_str(), nullptr};
  pid_t pid = 0;
  REQUIRE(::posix_spawn(&pid, "/bin/sh", nullptr, nullptr, const_cast<char* const*>(argv),
                        environ) == 0);
  return pid;
}

int exitCode(pid_t pid) {
  int status = 0;
  if (::waitpid(pid, &status, 0) != pid) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST_CASE(
    "rgbd_slam_split: after the link drops or the server restarts, the server catches up to the "
    "one-process result",
    "[e2e][dds][rgbd]") {
  TESSERA_SHARED_DATA(data, "7scenes-redkitchen-rgbd");
  const fs::path out = test::scratchDir("rgbd_slam_split_link");
  fs::create_directories(out / "one");
  test::runProfile("rgbd_slam_split", out / "one", {"sim_rate=0", "player.path=" + data.string()});
  const auto keyframeAte = [&](const fs::path& dir) {
    return evaluation::computeAte(mapping::readTum(dir / "keyframes.tum"),
                                  mapping::readTum(out / "one" / "ground_truth.tum"))
        .translation.rmse;
  };
  const double one_keyframes = keyframeAte(out / "one");

  for (const std::string outage : {"link", "restart"}) {
    INFO(outage);
    const fs::path run = out / outage;
    fs::create_directories(run);
    const std::string dds = " --set dds.partition=tessera_e2e_" + outage + "_" +
                            std::to_string(::getpid()) +
                            " --set dds.interface=lo --set dds.peers=[127.0.0.1]"
                            " --set dds.lease_s=1.5";
    const auto server_args = [&](const std::string& dir) {
      return "launch rgbd_slam_split --host server --wait-peers 60 --out " + (run / dir).string() +
             dds;
    };
    pid_t server = startTessera(server_args("server"), run / "server.log");
    const pid_t robot = startTessera("launch rgbd_slam_split --host robot --wait-peers 60 --out " +
                                         (run / "robot").string() + dds +
                                         " --set sim_rate=1 --set player.path=" + data.string(),
                                     run / "robot.log");
    // The robot reads the 15 s of frames at their pace; 4 s in, the server goes away for 5 s:
    // frozen (a link that drops: the robot's lease on it runs out after 1.5 s) or killed and
    // started again with nothing (a restart: it gets back what it missed from the robot).
    std::this_thread::sleep_for(std::chrono::seconds(6));
    if (outage == "link") {
      ::kill(server, SIGSTOP);
      std::this_thread::sleep_for(std::chrono::seconds(5));
      ::kill(server, SIGCONT);
    } else {
      ::kill(server, SIGKILL);
      CHECK(exitCode(server) == -1);
      std::this_thread::sleep_for(std::chrono::seconds(5));
      server = startTessera(server_args("server"), run / "server2.log");
    }
    const int robot_status = exitCode(robot);
    const int server_status = exitCode(server);
    INFO("robot:\n" << readText(run / "robot.log").substr(0, 3000));
    INFO("server:\n"
         << readText(run / (outage == "link" ? "server.log" : "server2.log")).substr(0, 3000));
    REQUIRE(robot_status == 0);
    REQUIRE(server_status == 0);
    const double split_keyframes = keyframeAte(run / "server");
    INFO("keyframe ATE one process " << one_keyframes << " m, after the " << outage << " "
                                     << split_keyframes << " m");
    CHECK(std::abs(split_keyframes - one_keyframes) < 0.001);
    const auto server_summary =
        nlohmann::json::parse(readText(run / "server" / "summary_server.json"));
    const auto robot_summary =
        nlohmann::json::parse(readText(run / "robot" / "summary_robot.json"));
    checkNothingLost(robot_summary, server_summary, {"keyframes", "camera_pose"});
    CHECK(server_summary["actors"]["mapper"]["keyframes_mapped"] ==
          robot_summary["actors"]["front_end"]["keyframes"]);
  }
}

TEST_CASE("sim_multi_robot on three hosts: each robot gets the merged map and its pose in it",
          "[e2e][dds][multi_robot]") {
  const fs::path out = test::scratchDir("sim_multi_robot_hosts");
  // The profile runs as fast as it can in one process; over hosts the clock must be paced.
  const auto status =
      runHosts("sim_multi_robot", out, {"r1", "r2"}, " --set sim_rate=8", " --set sim_rate=8");
  INFO("r1:\n" << readText(out / "r1.log").substr(0, 3000));
  INFO("server:\n" << readText(out / "server.log").substr(0, 3000));
  REQUIRE(status == std::vector<int>{0, 0, 0});
  const auto server = nlohmann::json::parse(readText(out / "server" / "summary_server.json"));
  CHECK(server["robots_joined"] == 2);
  CHECK(server["inter_robot_closures_false"] == 0);
  CHECK(server["inter_robot_closures"].get<std::int64_t>() >= 10);
  std::vector<std::pair<std::vector<mapping::TumPose>, std::vector<mapping::TumPose>>> pairs;
  for (const std::string r : {"r1", "r2"}) {
    INFO(r);
    const auto robot = nlohmann::json::parse(readText(out / r / ("summary_" + r + ".json")));
    // Every message on the reliable topics arrived (poses and scans are keep_latest).
    checkNothingLost(
        robot, server,
        {(r + "/submaps").c_str(), (r + "/constraints").c_str(), (r + "/final_poses").c_str()});
    // What the robot received from the server: the merged map and its pose in it.
    CHECK(robot["dds_topics"]["map"]["received"].get<std::int64_t>() >= 1);
    CHECK(fs::exists(out / r / (r + "_received_map.yaml")));
    CHECK(mapping::readTum(out / r / (r + "_map_pose.tum")).size() > 500);
    pairs.emplace_back(mapping::readTum(out / "server" / (r + "_trajectory_merged.tum")),
                       mapping::readTum(out / r / (r + "_ground_truth.tum")));
  }
  const auto joint = evaluation::computeJointAte(pairs);
  for (std::size_t k = 0; k < 2; ++k) {
    INFO("r" << k + 1 << ": merged " << joint.joint[k].rmse << " m, alone "
             << joint.alone[k].translation.rmse << " m");
    CHECK(joint.joint[k].rmse <= joint.alone[k].translation.rmse + 0.05);
  }
}

}  // namespace split_hosts_test
