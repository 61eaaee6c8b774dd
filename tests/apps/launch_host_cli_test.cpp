// `tessera launch PROFILE --host NAME` refuses what cannot run over several hosts, naming the
// file, key or value, before it joins any DDS domain; and a host whose peers never appear says
// which topics it waited for. The two-host run itself: tests/e2e/split_hosts_test.cpp.
#include "cli_run.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace launch_host_cli_test {

using tessera::test::runCli;

std::filesystem::path freshDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("tessera_test_launch_host_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// A two-group profile (a simulator on `robot`, a map writer on `server`) with `dds` as its
/// dds: section ("" for none) and `clock` lines.
std::string writeProfile(const std::filesystem::path& dir, const std::string& dds,
                         const std::string& clock = "clock: sim\nsim_rate: 4\n") {
  static int written = 0;
  const auto path = dir / ("split_" + std::to_string(++written) + ".yaml");
  std::ofstream(path) << "name: split\n"
                      << clock << dds
                      << "actors:\n"
                         "  sim:\n"
                         "    type: simulator\n"
                         "    process: robot\n"
                         "    params: {world: builtin:room}\n"
                         "  mapper:\n"
                         "    type: grid_mapper\n"
                         "    process: server\n"
                         "    remap: {pose: ground_truth}\n"
                         "  writer:\n"
                         "    type: map_writer\n"
                         "    process: server\n";
  return path.string();
}

const std::string kDds =
    "dds:\n  partition: tessera_cli_test\n  interface: lo\n"
    "  peers: [127.0.0.1]\n";

TEST_CASE("launch --host refuses a profile it cannot split over hosts, naming what is wrong",
          "[cli][dds]") {
  const auto dir = freshDir("errors");
  struct Case {
    std::string profile, args, named;
  };
  const std::vector<Case> cases{
      {writeProfile(dir, ""), "--host robot", "needs a `dds:` section"},
      {writeProfile(dir, kDds), "--host planner", "process groups: robot, server"},
      {writeProfile(dir, kDds, "clock: sim\n"), "--host robot", "needs a paced clock"},
      {writeProfile(dir, "dds:\n  domain: 3\n"), "--host robot", "dds.partition: missing"},
      {writeProfile(dir, kDds + "  colour: red\n"), "--host robot", "colour"},
      {writeProfile(dir, kDds + "  compression: {scan: 30}\n"), "--host robot",
       "dds.compression.scan: level 30"},
      {writeProfile(dir, kDds + "  compression: {no_topic: 3}\n"), "--host robot",
       "no_topic: no such topic crosses"},
      {writeProfile(dir, kDds), "--host robot --wait-peers 1 --set dds.domain=500",
       "dds.domain: 500"},
      {writeProfile(dir, "dds: [a, b]\n"), "--host robot", "dds: expected a mapping"},
      {writeProfile(dir, kDds + "  lease_s: .nan\n"), "--host robot", "dds.lease_s"},
      {writeProfile(dir, kDds + "  lease_s: soon\n"), "--host robot", "lease_s"},
      {writeProfile(dir, kDds + "  replay_depth: -3\n"), "--host robot", "replay_depth"},
      {writeProfile(dir, kDds), "--host robot --set dds.reconnect_timeout_s=-1",
       "dds.reconnect_timeout_s"},
  };
  for (const auto& c : cases) {
    const std::string args = "launch " + c.profile + " " + c.args;
    INFO(args);
    const auto run = runCli(args, dir);
    INFO(run.err);
    CHECK(run.exit_code == 2);
    CHECK(run.err.find(c.named) != std::string::npos);
    CHECK(run.err.find("waiting for") == std::string::npos);  // refused before joining DDS
  }
}

TEST_CASE("launch refuses an --orphan-grace that is not a positive number of seconds", "[cli]") {
  const auto dir = freshDir("orphan_grace");
  for (const std::string value : {"-1", "0", "nan", "soon", "''"}) {
    INFO(value);
    const auto run = runCli("launch sim_mapping --orphan-grace " + value, dir);
    CHECK(run.exit_code != 0);
    CHECK(run.err.find("--orphan-grace") != std::string::npos);
    CHECK(run.err.find("finite number") != std::string::npos);
  }
}

TEST_CASE("launch --host without its peers gives up naming the topics it waited for",
          "[cli][dds]") {
  const auto dir = freshDir("no_peer");
  const auto profile = writeProfile(dir, kDds);
  const auto run =
      runCli("launch " + profile + " --host server --wait-peers 1 --set dds.partition=" +
                 "tessera_cli_alone_" + std::to_string(::getpid()),
             dir);
  INFO(run.err);
  CHECK(run.exit_code == 1);
  CHECK(run.err.find("'scan' (no publisher)") != std::string::npos);
  CHECK(run.err.find("--host NAME") != std::string::npos);
}

}  // namespace launch_host_cli_test
