// sim_slam_split as two hosts: `tessera launch --host server` and `--host robot` as two processes
// that share no memory, their topics over Cyclone DDS on the loopback interface (unicast
// discovery, a partition of this test alone), checked against the same profile in one process.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <unistd.h>
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>

#include "../shared_data.hpp"
#include "run_profile.hpp"

namespace split_hosts_test {

using namespace tessera;
namespace fs = std::filesystem;

/// `tessera ARGS`, output in `log`; the exit status.
int runTessera(const std::string& args, const fs::path& log) {
  const std::string command =
      std::string(TESSERA_CLI_PATH) + " " + args + " > " + log.string() + " 2>&1";
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

TEST_CASE("sim_slam_split on two hosts over DDS maps as one process does, nothing reliable lost",
          "[e2e][dds]") {
  const fs::path out = test::scratchDir("sim_slam_split");
  const std::string dds = " --set dds.partition=tessera_e2e_" + std::to_string(::getpid()) +
                          " --set dds.interface=lo --set dds.peers=[127.0.0.1]";
  int server_status = -1;
  std::thread server_host([&] {
    server_status = runTessera("launch sim_slam_split --host server --wait-peers 60 --out " +
                                   (out / "server").string() + dds,
                               out / "server.log");
  });
  const int robot_status = runTessera("launch sim_slam_split --host robot --wait-peers 60 --out " +
                                          (out / "robot").string() + dds + " --set sim_rate=12",
                                      out / "robot.log");
  server_host.join();
  INFO("robot:\n" << readText(out / "robot.log").substr(0, 4000));
  INFO("server:\n" << readText(out / "server.log").substr(0, 4000));
  REQUIRE(robot_status == 0);
  REQUIRE(server_status == 0);

  const RunReport one = test::runProfile("sim_slam_split", out / "one", {"sim_rate=0"});
  const auto truth = mapping::readTum(out / "one" / "ground_truth.tum");
  const auto ate = [&](const fs::path& tum) {
    return evaluation::computeAte(mapping::readTum(tum), truth).translation.rmse;
  };
  const double one_final = ate(out / "one" / "trajectory_final.tum");
  const double split_final = ate(out / "server" / "trajectory_final.tum");
  const double one_live = ate(out / "one" / "trajectory.tum");
  const double split_live = ate(out / "robot" / "trajectory.tum");
  INFO("final ATE one process " << one_final << " m, two hosts " << split_final << " m; live ATE "
                                << one_live << " / " << split_live << " m");
  CHECK(split_final < one_final + 0.03);
  CHECK(split_live < one_live + 0.05);

  const auto server = nlohmann::json::parse(readText(out / "server" / "summary_server.json"));
  const auto robot = nlohmann::json::parse(readText(out / "robot" / "summary_robot.json"));
  // Every message the robot sent on a reliable topic arrived (the scans are keep_latest).
  for (const char* topic : {"submaps", "chained_pose", "constraints", "ground_truth"}) {
    INFO(topic);
    CHECK(robot["dds_topics"][topic]["sent"].get<std::int64_t>() > 0);
    CHECK(server["dds_topics"][topic]["received"] == robot["dds_topics"][topic]["sent"]);
    CHECK(server["dds_topics"][topic]["lost"] == 0);
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

}  // namespace split_hosts_test
