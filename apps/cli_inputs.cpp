#include "cli_inputs.hpp"

#include <tessera/datasets/relations.hpp>
#include <tessera/runtime/options.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace tessera::app {

namespace fs = std::filesystem;

void requireFile(const std::string& path, const char* option) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    throw ConfigError(std::string(option) + " " + path +
                      (fs::exists(path, ec) ? ": not a regular file" : ": no such file"));
}

CLI::Validator finiteNumberIn(double lo, double hi, bool above) {
  std::ostringstream range;
  range << (above ? "(" : "[") << lo << ", " << hi << "]";
  const std::string expected = "a finite number in " + range.str();
  return CLI::Validator(
      [lo, hi, above, expected](std::string& value) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(value.c_str(), &end);
        const bool whole = !value.empty() && *end == '\0';
        if (!whole || !std::isfinite(v) || v < lo || (above && v == lo) || v > hi)
          return "expected " + expected + ", got '" + value + "'";
        return {};
      },
      "NUMBER in " + range.str());
}

std::vector<std::string> profileSearchDirs() {
  return {std::string(TESSERA_SOURCE_DIR) + "/apps/profiles", "apps/profiles"};
}

std::vector<tessera::evaluation::PoseRelation> loadPoseRelations(const std::string& path,
                                                                 const char* option) {
  requireFile(path, option);
  const auto file = datasets::readRelations(path);
  std::vector<tessera::evaluation::PoseRelation> relations;
  relations.reserve(file.relations.size());
  for (const auto& r : file.relations)
    relations.push_back({r.t1_ns, r.t2_ns, tessera::Pose2(r.dx, r.dy, r.yaw)});
  return relations;
}

}  // namespace tessera::app
