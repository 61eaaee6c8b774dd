// `tessera actors` and the actors' tables of moved option keys: nested keys are listed by their
// dotted path, and every moved key points at keys that exist.
#include "cli_run.hpp"

#include <tessera/runtime/registry.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <filesystem>
#include <sstream>

using tessera::test::runCli;
namespace fs = std::filesystem;

TEST_CASE("tessera actors lists nested option keys by their dotted path", "[cli][options]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_actors_cli_test";
  fs::create_directories(dir);
  const auto run = runCli("actors rbpf_submap_builder", dir);
  REQUIRE(run.exit_code == 0);
  for (const char* key : {"rbpf.particles", "rbpf.motion.srr", "rbpf.grid.log_odds.miss",
                          "rbpf.insert.max_range", "rbpf.matcher.sigma", "submap_distance"}) {
    INFO(key);
    CHECK(run.out.find(std::string("    ") + key + " ") != std::string::npos);
  }
  fs::remove_all(dir);
}

TEST_CASE("every moved option key names keys its actor has", "[options]") {
  for (const auto& [type, entry] : tessera::ActorRegistry::instance().entries()) {
    std::vector<std::string> keys;
    for (const auto& row : entry.options()) keys.push_back(row[0]);
    const auto has = [&](const std::string& k) {
      return std::find(keys.begin(), keys.end(), k) != keys.end();
    };
    for (const auto& r : entry.renamed) {
      INFO(type << ": " << r.old_key << " -> " << r.new_key);
      CHECK_FALSE(has(r.old_key));
      std::istringstream words(r.new_key);
      for (std::string w; words >> w;) {
        if (w != "and") CHECK(has(w));
      }
    }
  }
}
