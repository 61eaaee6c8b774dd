#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/io/atomic_file.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace tessera::evaluation {
namespace {

std::string shortest(double v) {
  std::array<char, 64> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), res.ptr);
}

std::string quoted(std::string_view t) {
  std::string s(1, '\'');
  s.append(t.substr(0, 40));
  s.append(t.size() > 40 ? "...'" : "'");
  return s;
}

}  // namespace

std::vector<Landmark> parseLandmarks(std::string_view text, const std::string& name) {
  std::vector<Landmark> out;
  std::unordered_map<std::int64_t, std::size_t> line_of_id;
  std::size_t number = 0;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    std::string_view line = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
    ++number;
    const std::string where = name + ":" + std::to_string(number);

    std::array<std::string_view, 3> fields;
    std::size_t n = 0, i = 0;
    bool too_many = false;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
      if (i >= line.size()) break;
      const std::size_t start = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
      if (n == fields.size()) {
        too_many = true;
        break;
      }
      fields[n++] = line.substr(start, i - start);
    }
    if (n == 0 || fields[0].front() == '#') continue;
    if (too_many || n != 3)
      throw LandmarkFileError(where + ": expected 3 fields 'id x y', found " +
                              (too_many ? std::string("more") : std::to_string(n)));

    Landmark lm;
    {
      const std::string_view f = fields[0];
      const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), lm.id);
      if (ec != std::errc() || ptr != f.data() + f.size())
        throw LandmarkFileError(where + ": expected an integer id, found " + quoted(f));
    }
    for (int k = 0; k < 2; ++k) {
      const std::string_view f = fields[1 + k];
      double v = 0;
      const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v);
      if (ec != std::errc() || ptr != f.data() + f.size() || !std::isfinite(v))
        throw LandmarkFileError(where + ": expected a finite number for " + (k == 0 ? "x" : "y") +
                                ", found " + quoted(f));
      lm.position[k] = v;
    }
    const auto [it, inserted] = line_of_id.emplace(lm.id, number);
    if (!inserted)
      throw LandmarkFileError(where + ": duplicate landmark id " + std::to_string(lm.id) +
                              " (first on line " + std::to_string(it->second) + ")");
    out.push_back(lm);
  }
  return out;
}

std::vector<Landmark> readLandmarks(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw LandmarkFileError(path.string() + ": cannot open for reading");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) throw LandmarkFileError(path.string() + ": read error");
  return parseLandmarks(buffer.str(), path.string());
}

void writeLandmarks(const std::filesystem::path& path, const std::vector<Landmark>& landmarks) {
  std::ostringstream out;
  out << "# id x y\n";
  for (const auto& lm : landmarks)
    out << lm.id << ' ' << shortest(lm.position.x()) << ' ' << shortest(lm.position.y()) << '\n';
  try {
    io::writeFileAtomically(path, out.str());  // the old file or the new one, whole
  } catch (const io::FileWriteError& e) {
    throw LandmarkFileError(e.what());
  }
}

}  // namespace tessera::evaluation
