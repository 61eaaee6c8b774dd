#include <tessera/evaluation/loop_log.hpp>

#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace tessera::evaluation {

namespace {

constexpr std::array<const char*, 12> kRead = {"query_id",
                                               "candidate_id",
                                               "query_stamp_ns",
                                               "candidate_stamp_ns",
                                               "accepted",
                                               "x",
                                               "y",
                                               "z",
                                               "qx",
                                               "qy",
                                               "qz",
                                               "qw"};

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream s(line);
  while (std::getline(s, field, ',')) out.push_back(field);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

}  // namespace

std::vector<LoggedLoop> readLoopLog(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot open (did the run write it?)");
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path.string() + ": empty file");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  const std::vector<std::string> header = split(line);
  std::array<std::size_t, kRead.size()> column{};
  for (std::size_t k = 0; k < kRead.size(); ++k) {
    std::size_t c = 0;
    while (c < header.size() && header[c] != kRead[k]) ++c;
    if (c == header.size())
      throw std::runtime_error(path.string() + ":1: no column '" + kRead[k] +
                               "' in the header (a loops.csv of rgbd_loop_detector expected)");
    column[k] = c;
  }
  std::vector<LoggedLoop> rows;
  for (int n = 2; std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string where = path.string() + ":" + std::to_string(n);
    const std::vector<std::string> fields = split(line);
    if (fields.size() != header.size())
      throw std::runtime_error(where + ": " + std::to_string(fields.size()) +
                               " fields, the header has " + std::to_string(header.size()) +
                               " (cut short?)");
    std::array<double, kRead.size()> v{};
    for (std::size_t k = 0; k < kRead.size(); ++k) {
      const std::string& f = fields[column[k]];
      char* end = nullptr;
      v[k] = std::strtod(f.c_str(), &end);
      if (f.empty() || *end != '\0' || !std::isfinite(v[k]))
        throw std::runtime_error(where + ": column " + kRead[k] +
                                 ": expected a finite number, got '" + f + "'");
    }
    LoggedLoop r;
    r.query_id = static_cast<std::int64_t>(v[0]);
    r.candidate_id = static_cast<std::int64_t>(v[1]);
    r.query_stamp_ns = static_cast<std::int64_t>(v[2]);
    r.candidate_stamp_ns = static_cast<std::int64_t>(v[3]);
    if (v[4] != 0 && v[4] != 1)
      throw std::runtime_error(where + ": column accepted: expected 0 or 1, got " +
                               fields[column[4]]);
    r.accepted = v[4] == 1;
    const Eigen::Quaterniond q(v[11], v[8], v[9], v[10]);
    if (!(q.norm() > 1e-9))
      throw std::runtime_error(where + ": columns qx..qw: a quaternion of length 0");
    r.candidate_from_query = {Eigen::Vector3d(v[5], v[6], v[7]), q.normalized()};
    rows.push_back(r);
  }
  return rows;
}

std::vector<RelativeMeasurement> acceptedLoops(const std::vector<LoggedLoop>& loops) {
  std::vector<RelativeMeasurement> out;
  for (const auto& l : loops)
    if (l.accepted) out.push_back({l.candidate_stamp_ns, l.query_stamp_ns, l.candidate_from_query});
  return out;
}

}  // namespace tessera::evaluation
