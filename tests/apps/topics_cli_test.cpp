// `tessera topics` and `tessera echo` against a running `tessera run sim_slam_global --view 0`:
// the topics with their schemas and rates, messages printed one JSON per line, and the errors a
// user meets (no viewer there, an unknown topic, a wrong token).
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <sstream>

#include "cli_child.hpp"
#include "cli_run.hpp"

// Everything in a namespace of its own: unity builds put test files together.
namespace topics_cli_test {

namespace fs = std::filesystem;
using tessera::test::runCli;

TEST_CASE("topics and echo look into a running stack through its viewer", "[viewer][cli]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_topics_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  tessera::test::CliChild run("run sim_slam_global --view 0 --rate 2 --view-token abc --quiet",
                              dir / "run.txt");
  const std::string url = tessera::test::waitForViewerUrl(dir / "run.txt");
  REQUIRE_FALSE(url.empty());
  const std::string port = url.substr(17, url.size() - 18);  // http://127.0.0.1:PORT/

  const auto topics = runCli("topics --port " + port + " --token abc --hz 1", dir);
  INFO(topics.err);
  REQUIRE(topics.exit_code == 0);
  CHECK_THAT(topics.out, Catch::Contains("tessera at ws://127.0.0.1:" + port));
  CHECK_THAT(topics.out,
             Catch::Matches(R"((.|\n)*scan +foxglove\.LaserScan +json +[0-9.]+ Hz(.|\n)*)"));
  CHECK_THAT(topics.out, Catch::Contains("map/tiles") && Catch::Contains("tessera.tiles"));

  const auto echo = runCli("echo scan -n 3 --port " + port + " --token abc --timeout 30", dir);
  INFO(echo.err);
  REQUIRE(echo.exit_code == 0);
  std::istringstream lines(echo.out);
  std::string line;
  int n = 0;
  while (std::getline(lines, line)) {
    const auto j = nlohmann::json::parse(line);
    CHECK(j["ranges"].size() > 100);
    ++n;
  }
  CHECK(n == 3);
  const auto tiles =
      runCli("echo map/tiles -n 1 --port " + port + " --token abc --timeout 60", dir);
  CHECK_THAT(tiles.out, Catch::Contains("\"encoding\":\"tessera.tiles\",\"bytes\":"));

  const auto unknown = runCli("echo nosuch --port " + port + " --token abc", dir);
  CHECK(unknown.exit_code == 2);
  CHECK_THAT(unknown.err, Catch::Contains("no topic 'nosuch'") && Catch::Contains("scan"));
  const auto no_token = runCli("topics --port " + port, dir);
  CHECK(no_token.exit_code == 1);
  CHECK_THAT(no_token.err, Catch::Contains("token"));
  CHECK(run.interrupt() == 130);

  const auto nobody = runCli("topics --port " + port, dir);  // the run is gone
  CHECK(nobody.exit_code == 1);
  CHECK_THAT(nobody.err, Catch::Contains("nothing answers") && Catch::Contains("--view"));
  const auto bad_url = runCli("topics --url http:/nope", dir);
  CHECK(bad_url.exit_code == 1);
  CHECK_THAT(bad_url.err, Catch::Contains("not a WebSocket URL"));
}

}  // namespace topics_cli_test
