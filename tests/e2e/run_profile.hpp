// End-to-end test helpers: run an apps/profiles profile in-process into an output folder, and
// read an actor's summary figures from the report.
#pragma once

#include <tessera/runtime/profile.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::test {

inline RunReport runProfile(const std::string& name, const std::filesystem::path& out,
                            const std::vector<std::string>& overrides = {}) {
  auto profile =
      loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/" + name + ".yaml", overrides);
  RuntimeOptions options;
  options.show_progress = false;
  options.output_dir = out.string();
  options.threads = 2;
  auto runtime = buildRuntime(profile, options);
  return runtime->run();
}

inline const Summary& summaryOf(const RunReport& r, const std::string& actor) {
  for (const auto& a : r.actors)
    if (a.name == actor) return a.summary;
  FAIL("no actor " << actor);
  throw std::logic_error("unreachable");
}

inline std::int64_t summaryInt(const RunReport& r, const std::string& actor,
                               const std::string& key) {
  return std::get<std::int64_t>(summaryOf(r, actor).at(key));
}

}  // namespace tessera::test
