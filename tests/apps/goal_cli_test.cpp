// `tessera goal` argument errors: each names the argument and exits 2 before anything touches
// shared memory (the goal's way into a launched deployment is tested in tessera_shm_tests,
// tests/runtime/shm/launch_test.cpp).
#include "cli_run.hpp"

#include <filesystem>
#include <initializer_list>
#include <string>

using tessera::test::runCli;

namespace {
// One folder per test case: ctest runs the cases as parallel processes.
std::filesystem::path freshDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("tessera_test_goal_cli_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

struct UsageCase {
  const char* args;
  const char* named;  // what the error must say
};

/// Each command line exits 2 with an error that contains its `named` text, and sends nothing.
void checkUsageErrors(const std::string& name, std::initializer_list<UsageCase> cases) {
  const auto dir = freshDir(name);
  for (const auto& c : cases) {
    INFO(c.args);
    const auto run = runCli(c.args, dir);
    INFO(run.err);
    CHECK(run.exit_code == 2);
    CHECK(run.err.find(c.named) != std::string::npos);
    CHECK(run.out.find("sent") == std::string::npos);
  }
}
}  // namespace

TEST_CASE("tessera goal rejects missing, non-numeric and non-finite coordinates by name",
          "[cli][goal]") {
  checkUsageErrors("coordinates",
                   {
                       {"goal 1 2", "THETA"},
                       {"goal", "X"},
                       {"goal abc 2 0", "X: expected a finite number, got 'abc'"},
                       {"goal 1 2x 0", "Y: expected a finite number, got '2x'"},
                       {"goal nan 2 0", "X: expected a finite number, got 'nan'"},
                       {"goal 1 2 inf", "THETA: expected a finite number, got 'inf'"},
                       {"goal 1 '' 0", "Y: expected a finite number, got ''"},
                   });
}

TEST_CASE("tessera goal rejects bad tolerances and timeouts by name", "[cli][goal]") {
  checkUsageErrors(
      "options",
      {
          {"goal 1 2 0 --tolerance-xy -0.1", "--tolerance-xy: must be >= 0"},
          {"goal 1 2 0 --tolerance-xy nan", "--tolerance-xy: expected a finite number"},
          {"goal 1 2 0 --tolerance-yaw -1", "--tolerance-yaw: must be >= 0"},
          {"goal 1 2 0 --tolerance-yaw x", "--tolerance-yaw: expected a number, got 'x'"},
          {"goal 1 2 0 --wait --timeout 0", "--timeout"},
          {"goal 1 2 0 --wait --timeout nan", "--timeout"},
          {"goal 1 2 0 --wait --timeout soon", "--timeout"},
          {"goal 1 2 0 --topic ''", "--topic: empty"},
      });
}

TEST_CASE("tessera goal --help lists its arguments and exit codes", "[cli][goal]") {
  const auto dir = freshDir("help");
  const auto run = runCli("goal --help", dir);
  CHECK(run.exit_code == 0);
  for (const char* word : {"THETA", "--wait", "--timeout", "--tolerance-xy", "--id", "external:"}) {
    INFO(word);
    CHECK(run.out.find(word) != std::string::npos);
  }
}
