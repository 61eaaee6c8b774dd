// `tessera completion bash` end to end: the script is sourced in bash and asked to complete
// partial command lines the way bash would (COMP_WORDS / COMP_CWORD), and it offers the
// subcommands, options and profile names the CLI has.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "cli_run.hpp"

using tessera::test::runCli;
namespace fs = std::filesystem;

namespace {

/// What the generated function offers for `words` (the last one being completed).
std::string complete(const fs::path& script, const fs::path& dir, const std::string& words) {
  const fs::path probe = dir / "probe.sh";
  {
    std::ofstream out(probe);
    out << "source " << script.string() << "\n"
        << "COMP_WORDS=(" << words << ")\n"
        << "COMP_CWORD=$(( ${#COMP_WORDS[@]} - 1 ))\n"
        << "_tessera\n"
        << "echo \"${COMPREPLY[*]}\"\n";
  }
  const fs::path result = dir / "result.txt";
  REQUIRE(std::system(("bash " + probe.string() + " > " + result.string()).c_str()) == 0);
  std::ifstream in(result);
  std::string line;
  std::getline(in, line);
  return line;
}

}  // namespace

TEST_CASE("the bash completion offers subcommands, options and profiles", "[completion]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_completion";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto run = runCli("completion bash", dir);
  REQUIRE(run.exit_code == 0);
  const fs::path script = dir / "tessera.bash";
  std::ofstream(script) << run.out;
  CHECK_THAT(run.out, Catch::Contains("complete -o default -F _tessera tessera"));

  CHECK(complete(script, dir, "tessera ru") == "run");
  CHECK(complete(script, dir, "tessera run sim_ma") == "sim_mapping");
  CHECK(complete(script, dir, "tessera bench pl") == "planner");
  CHECK(complete(script, dir, "tessera eval a") == "ate");
  CHECK(complete(script, dir, "tessera run sim_nav --ou") == "--out");
  CHECK(complete(script, dir, "tessera replay x.trec --exp") == "--export");
  CHECK(complete(script, dir, "tessera replay x.trec --profile sim_nav_s") == "sim_nav_slam");
  // After an option that takes a value nothing is offered: bash completes file names.
  CHECK(complete(script, dir, "tessera run sim_nav --out \"\"").empty());
  // Internal commands stay out of sight.
  CHECK(complete(script, dir, "tessera wor").empty());
}

TEST_CASE("completion names the shells it knows", "[completion]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_completion_bad";
  fs::create_directories(dir);
  const auto zsh = runCli("completion zsh", dir);
  CHECK(zsh.exit_code == 2);
  CHECK_THAT(zsh.err, Catch::Contains("bash"));
}
