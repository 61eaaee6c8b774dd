// Leftovers of crashed runs: findStaleShm() lists only what no live process owns, and
// `tessera doctor` reports them and removes them with --fix.
#include "../../apps/cli_run.hpp"
#include "launch_fixtures.hpp"

#include <tessera/shm/roudi_host.hpp>

#include <catch2/catch.hpp>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

TEST_CASE("stale shared memory lists control blocks of dead launchers, not of live ones",
          "[shm][doctor]") {
  REQUIRE_FALSE(tessera::rouDiRunning());  // the shm tests run one at a time
  const fs::path shm = tessera::test::freshDir("stale_shm_dir");
  const fs::path tmp = tessera::test::freshDir("stale_tmp_dir");
  // pid 999999999 is above any pid_max: no such process.
  for (const auto& name : {std::string("tessera_sync_999999999"),
                           "tessera_sync_" + std::to_string(::getpid()), std::string("other")})
    std::ofstream(shm / name) << "x";
  std::ofstream(tmp / "tessera_not_a_socket") << "x";
  const auto found = tessera::findStaleShm(shm, tmp);
  REQUIRE(found.size() == 1);
  CHECK(found[0] == (shm / "tessera_sync_999999999").string());
}

TEST_CASE("tessera doctor reports a crashed run's control block and --fix removes it",
          "[shm][doctor]") {
  REQUIRE_FALSE(tessera::rouDiRunning());
  const fs::path dir = tessera::test::freshDir("doctor_fix");
  const fs::path block = "/dev/shm/tessera_sync_999999998";
  std::ofstream(block) << "x";
  REQUIRE(fs::exists(block));

  const auto report = tessera::test::runCli("doctor --data " + dir.string(), dir);
  INFO(report.out << report.err);
  CHECK(report.out.find("left by a crashed run") != std::string::npos);
  CHECK(report.out.find(block.string()) != std::string::npos);
  CHECK(report.out.find("tessera doctor --fix") != std::string::npos);
  CHECK(fs::exists(block));  // reported, not touched

  const auto fixed = tessera::test::runCli("doctor --fix --data " + dir.string(), dir);
  INFO(fixed.out << fixed.err);
  CHECK(fixed.out.find("[fixed] removed") != std::string::npos);
  CHECK_FALSE(fs::exists(block));
  const auto again = tessera::test::runCli("doctor --data " + dir.string(), dir);
  CHECK(again.out.find("no shared memory or sockets left by a crashed run") != std::string::npos);
}
