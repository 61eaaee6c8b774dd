// `tessera doctor`: the checks it prints and what it says to fix, on this machine.
#include "cli_run.hpp"

#include "../shared_data.hpp"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

TEST_CASE("tessera doctor checks shared memory and names every missing dataset", "[cli][doctor]") {
  const fs::path dir = tessera::test::scratchDir("doctor_cli");
  const fs::path data = dir / "data";
  fs::create_directories(data / "intel-lab-mrpt");
  std::ofstream(data / "intel-lab-mrpt" / "intel.clf.gz") << "x";

  const auto run = tessera::test::runCli("doctor --data " + data.string(), dir);
  INFO(run.out << run.err);
  // This machine runs the shared-memory tests, so nothing fails; warnings may.
  CHECK(run.exit_code == 0);
  CHECK(run.out.find("/dev/shm: ") != std::string::npos);
  CHECK(run.out.find("[ok]    shared memory: a segment was created, mapped and removed") !=
        std::string::npos);
  CHECK(run.out.find("transparent huge pages") != std::string::npos);
  CHECK(run.out.find("1 of 12 found") != std::string::npos);
  CHECK(run.out.find("missing " + (data / "intel-lab-mrpt" / "frame_times.txt").string()) !=
        std::string::npos);
  CHECK(run.out.find("used by eval relations, bench rbpf") != std::string::npos);
  CHECK(run.out.find("missing " + (data / "intel-lab-mrpt" / "intel.clf.gz").string()) ==
        std::string::npos);
  CHECK(run.out.find("ready: 0 failed") != std::string::npos);
}

TEST_CASE("tessera doctor says how to point it at the datasets when the folder is absent",
          "[cli][doctor]") {
  const fs::path dir = tessera::test::scratchDir("doctor_cli_nodata");
  const auto run = tessera::test::runCli("doctor --data " + (dir / "nowhere").string(), dir);
  INFO(run.out << run.err);
  CHECK(run.exit_code == 0);
  CHECK(run.out.find("[warn]  no dataset folder at " + (dir / "nowhere").string()) !=
        std::string::npos);
  CHECK(run.out.find("pass --data DIR") != std::string::npos);
  const auto bad = tessera::test::runCli("doctor --no-such-flag", dir);
  CHECK(bad.exit_code == 2);
}
