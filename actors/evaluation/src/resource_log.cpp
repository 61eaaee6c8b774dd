#include <tessera/evaluation/resource_log.hpp>

#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>

namespace tessera::evaluation {

namespace {
constexpr std::array<const char*, 7> kColumns = {"t_s",     "rss_mb",      "cpu_s",  "scans",
                                                 "submaps", "graph_nodes", "trimmed"};
}  // namespace

std::vector<ResourceSample> readResourceLog(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot open (did the run write it?)");
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path.string() + ": empty file");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  if (line != kResourceLogHeader) {
    throw std::runtime_error(path.string() + ":1: expected the header '" +
                             std::string(kResourceLogHeader) + "', got '" + line + "'");
  }
  std::vector<ResourceSample> rows;
  for (int n = 2; std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string where = path.string() + ":" + std::to_string(n);
    std::array<double, 7> v{};
    const char* p = line.c_str();
    for (std::size_t c = 0; c < v.size(); ++c) {
      char* end = nullptr;
      v[c] = std::strtod(p, &end);
      const bool last = c + 1 == v.size();
      if (end == p || !std::isfinite(v[c]) || (last ? *end != '\0' : *end != ',')) {
        throw std::runtime_error(where + ": column " + kColumns[c] + ": expected a finite number" +
                                 (last ? " at the end of the line" : " then ','") +
                                 " (7 columns: " + std::string(kResourceLogHeader) + ")");
      }
      p = end + (last ? 0 : 1);
    }
    ResourceSample s{v[0], v[1], v[2], v[3], v[4], v[5], v[6]};
    if (!rows.empty() && s.t_s < rows.back().t_s) {
      throw std::runtime_error(where + ": t_s " + std::to_string(s.t_s) +
                               " is earlier than the row before (" +
                               std::to_string(rows.back().t_s) + ")");
    }
    rows.push_back(s);
  }
  return rows;
}

}  // namespace tessera::evaluation
