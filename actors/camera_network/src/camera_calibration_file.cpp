#include <tessera/camera_network/camera_calibration_file.hpp>
#include <tessera/io/atomic_file.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

namespace tessera::camera_network {

namespace camera_calibration_file_detail {

namespace fs = std::filesystem;

constexpr std::array<const char*, 9> kEntryKeys = {"id",         "submap", "stamp_ns",
                                                   "homography", "rms_px", "coverage",
                                                   "condition",  "pairs",  "inliers"};

std::string entryKeyList() {
  std::string out;
  for (const char* k : kEntryKeys) out += (out.empty() ? "" : ", ") + std::string(k);
  return out;
}

/// Shortest text that reads back as the same double.
std::string numberText(double v) {
  std::array<char, 64> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), res.ptr);
}

std::string singularProblem(const Eigen::Matrix3d& h) {
  return "is singular (σ_min/σ_max = " + numberText(homographyInverseCondition(h)) +
         "); expected an invertible floor -> pixel homography";
}

/// "FIELD: PROBLEM" split at the first ": ".
std::pair<std::string, std::string> splitProblem(const std::string& p) {
  const auto at = p.find(": ");
  if (at == std::string::npos) return {"", p};
  return {p.substr(0, at), p.substr(at + 2)};
}

std::string nodeText(const YAML::Node& n) {
  if (!n.IsDefined() || n.IsNull()) return "nothing";
  if (n.IsScalar()) return "'" + n.Scalar() + "'";
  YAML::Emitter e;
  e << YAML::Flow << n;
  std::string s = e.c_str();
  if (s.size() > 80) s = s.substr(0, 77) + "...";
  return s;
}

class Reader {
 public:
  explicit Reader(fs::path file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const YAML::Node& n, const std::string& field,
                         const std::string& what) const {
    const int line = n.Mark().is_null() ? 0 : n.Mark().line + 1;
    throw CameraCalibrationFileError(file_, line, field, what);
  }

  YAML::Node key(const YAML::Node& parent, const char* k, const std::string& at) const {
    const YAML::Node n = parent[k];
    if (!n) fail(parent, at + ": " + k, "missing (each camera has " + entryKeyList() + ")");
    return n;
  }

  long long integer(const YAML::Node& n, const std::string& field, long long lo,
                    long long hi) const {
    long long v = 0;
    if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v))
      fail(n, field, "must be an integer, got " + nodeText(n));
    if (v < lo || v > hi) {
      const std::string range = lo == std::numeric_limits<long long>::min()
                                    ? "<= " + std::to_string(hi)
                                : hi == std::numeric_limits<int>::max()
                                    ? ">= " + std::to_string(lo)
                                    : "in " + std::to_string(lo) + ".." + std::to_string(hi);
      fail(n, field, "must be " + range + ", got " + nodeText(n));
    }
    return v;
  }

  double number(const YAML::Node& n, const std::string& field, double lo, double hi) const {
    double v = 0;
    if (!n.IsScalar() || !YAML::convert<double>::decode(n, v))
      fail(n, field, "must be a number, got " + nodeText(n));
    if (!std::isfinite(v)) fail(n, field, "must be a finite number, got " + nodeText(n));
    if (v < lo || v > hi) {
      const std::string range = hi == std::numeric_limits<double>::max()
                                    ? ">= " + numberText(lo)
                                    : "in " + numberText(lo) + ".." + numberText(hi);
      fail(n, field, "must be " + range + ", got " + nodeText(n));
    }
    return v;
  }

  Eigen::Matrix3d homography(const YAML::Node& n, const std::string& field) const {
    const std::string shape = "a list of 9 numbers (3x3 floor -> pixel homography, row-major)";
    if (!n.IsSequence() || n.size() != 9) {
      const std::string count = n.IsSequence() ? " of " + std::to_string(n.size()) + " values" : "";
      fail(n, field, "must be " + shape + ", got " + nodeText(n) + count);
    }
    Eigen::Matrix3d h;
    for (std::size_t k = 0; k < 9; ++k) {
      const YAML::Node e = n[k];
      double v = 0;
      if (!e.IsScalar() || !YAML::convert<double>::decode(e, v))
        fail(n, field,
             "must be " + shape + ", element " + std::to_string(k) + " is " + nodeText(e));
      if (!std::isfinite(v))
        fail(n, field,
             "must be finite numbers, element " + std::to_string(k) + " is " + nodeText(e));
      h(static_cast<Eigen::Index>(k / 3), static_cast<Eigen::Index>(k % 3)) = v;
    }
    if (!(homographyInverseCondition(h) > kMinHomographyInverseCondition))
      fail(n, field, singularProblem(h));
    return h;
  }

 private:
  fs::path file_;
};

/// For a YAML syntax error at 1-based `line`: the entry and key written last before it (what a
/// truncated file was cut in), e.g. "cameras[1]: homography"; empty when none.
std::string fieldNear(const std::string& text, int line) {
  std::istringstream in(text);
  std::string l, key;
  int entry = -1;
  for (int k = 1; std::getline(in, l) && k <= line; ++k) {
    std::size_t p = l.find_first_not_of(' ');
    if (p == std::string::npos || l[p] == '#') continue;
    if (l[p] == '-') {
      ++entry;
      key.clear();
      p = l.find_first_not_of(' ', p + 1);
      if (p == std::string::npos) continue;
    }
    std::size_t e = p;
    while (e < l.size() && (std::isalnum(static_cast<unsigned char>(l[e])) || l[e] == '_')) ++e;
    if (e > p && e < l.size() && l[e] == ':') key = l.substr(p, e - p);
  }
  if (key == "cameras") return key;
  if (entry < 0) return key;
  return "cameras[" + std::to_string(entry) + "]" + (key.empty() ? "" : ": " + key);
}

/// The last non-blank line at or before 1-based `line` (the parser may point past the end).
int lastLineAtOrBefore(const std::string& text, int line) {
  std::istringstream in(text);
  std::string l;
  int found = 0;
  for (int k = 1; std::getline(in, l) && k <= line; ++k)
    if (l.find_first_not_of(" \t\r") != std::string::npos) found = k;
  return found;
}

std::string lineText(const std::string& text, int line) {
  std::istringstream in(text);
  std::string l;
  for (int k = 1; std::getline(in, l); ++k)
    if (k == line) {
      const auto b = l.find_first_not_of(' ');
      l = b == std::string::npos ? "" : l.substr(b);
      return l.size() > 60 ? l.substr(0, 57) + "..." : l;
    }
  return {};
}

}  // namespace camera_calibration_file_detail

namespace detail_ccf = camera_calibration_file_detail;

CameraCalibrationFileError::CameraCalibrationFileError(const std::filesystem::path& file, int line,
                                                       const std::string& field,
                                                       const std::string& problem)
    : std::runtime_error(file.string() + (line > 0 ? ":" + std::to_string(line) : "") + ": " +
                         (field.empty() ? "" : field + ": ") + problem),
      file_(file),
      line_(line),
      field_(field) {}

CameraCalibrationRecord calibrationRecord(const CameraCalibration& c) {
  CameraCalibrationRecord r;
  r.camera = c.camera;
  r.submap = static_cast<int>(c.submap);
  r.stamp_ns = c.stamp_ns;
  r.floor_to_pixel = c.homography.h;
  const auto& q = c.homography.quality;
  r.rms_px = q.rms_px;
  r.coverage = q.coverage;
  r.condition = q.condition;
  r.pairs = q.pairs;
  r.inliers = q.inliers;
  return r;
}

void writeCameraCalibrations(const std::filesystem::path& path,
                             const std::vector<CameraCalibrationRecord>& records) {
  using detail_ccf::numberText;
  std::map<int, const CameraCalibrationRecord*> by_id;
  for (std::size_t k = 0; k < records.size(); ++k) {
    const CameraCalibrationRecord& r = records[k];
    const std::string at =
        "records[" + std::to_string(k) + "] (camera " + std::to_string(r.camera) + ")";
    if (const std::string p = floorCameraCalibrationProblem(r); !p.empty()) {
      const auto [field, what] = detail_ccf::splitProblem(p);
      throw CameraCalibrationFileError(path, 0, at + ": " + field, what);
    }
    if (!by_id.emplace(r.camera, &r).second)
      throw CameraCalibrationFileError(path, 0, at + ": id",
                                       "camera " + std::to_string(r.camera) + " is given twice");
  }
  std::ostringstream out;
  out << "# Environment cameras calibrated from the robot's motion (docs/algorithms.md"
         "#camera-network-calibration):\n# floor (submap frame, m) -> pixel homography, "
         "row-major, h22 = 1.\ncameras:"
      << (by_id.empty() ? " []" : "") << "\n";
  for (const auto& [id, r] : by_id) {
    out << "  - id: " << id << "\n    submap: " << r->submap << "\n    stamp_ns: " << r->stamp_ns
        << "\n    homography: [";
    for (int k = 0; k < 9; ++k)
      out << (k ? ", " : "") << numberText(r->floor_to_pixel(k / 3, k % 3));
    out << "]\n    rms_px: " << numberText(r->rms_px)
        << "\n    coverage: " << numberText(r->coverage)
        << "\n    condition: " << numberText(r->condition) << "\n    pairs: " << r->pairs
        << "\n    inliers: " << r->inliers << "\n";
  }
  try {
    io::writeFileAtomically(path, out.str());
  } catch (const io::FileWriteError& e) {
    throw CameraCalibrationFileError(path, 0, "", e.reason());
  }
}

std::vector<CameraCalibrationRecord> readCameraCalibrations(const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  using detail_ccf::nodeText;
  const auto failFile = [&path](const std::string& what) {
    throw CameraCalibrationFileError(path, 0, "", what);
  };
  std::error_code ec;
  if (!fs::exists(path, ec))
    failFile(
        "missing: no such file (camera_network_slam writes it with calibrations_file and an "
        "output folder)");
  if (!fs::is_regular_file(path, ec)) failFile("not a regular file");
  std::string text;
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) failFile("cannot open for reading");
    std::ostringstream s;
    s << in.rdbuf();
    text = s.str();
  }
  if (text.find_first_not_of(" \t\r\n") == std::string::npos)
    failFile("empty file (expected a 'cameras:' list)");

  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    const int at = e.mark.is_null() ? 0 : e.mark.line + 1;
    const int line = at > 0 ? detail_ccf::lastLineAtOrBefore(text, at) : 0;
    const std::string reads =
        line > 0 ? "; the line reads '" + detail_ccf::lineText(text, line) + "'" : "";
    throw CameraCalibrationFileError(
        path, line, line > 0 ? detail_ccf::fieldNear(text, line) : "",
        "not valid YAML, truncated or malformed (" + e.msg + ")" + reads);
  }
  const detail_ccf::Reader r(path);
  if (root.IsNull()) failFile("empty file: no YAML content (expected a 'cameras:' list)");
  if (!root.IsMap())
    r.fail(root, "", "expected a YAML mapping with a 'cameras:' list, got " + nodeText(root));
  for (const auto& kv : root) {
    const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : nodeText(kv.first);
    if (k != "cameras") r.fail(kv.first, k, "unknown key (the file holds only a 'cameras:' list)");
  }
  const YAML::Node cameras = root["cameras"];
  if (!cameras) r.fail(root, "cameras", "missing (expected a list of cameras)");
  if (!cameras.IsSequence())
    r.fail(cameras, "cameras",
           "must be a list of cameras ('[]' for none), got " + nodeText(cameras));

  std::vector<CameraCalibrationRecord> out;
  std::map<int, std::size_t> seen;  // id -> index
  const long long max_int = std::numeric_limits<int>::max();
  const double max_double = std::numeric_limits<double>::max();
  for (std::size_t k = 0; k < cameras.size(); ++k) {
    const YAML::Node n = cameras[k];
    std::string at = "cameras[" + std::to_string(k) + "]";
    if (!n.IsMap())
      r.fail(n, at, "must be a mapping (" + detail_ccf::entryKeyList() + "), got " + nodeText(n));
    CameraCalibrationRecord c;
    const YAML::Node id = r.key(n, "id", at);
    c.camera = static_cast<int>(r.integer(id, at + ": id", 0, max_int));
    at += " (camera " + std::to_string(c.camera) + ")";
    if (const auto [it, fresh] = seen.emplace(c.camera, k); !fresh)
      r.fail(id, at + ": id",
             "camera " + std::to_string(c.camera) + " is listed twice (also cameras[" +
                 std::to_string(it->second) + "])");
    for (const auto& kv : n) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : nodeText(kv.first);
      if (std::find_if(detail_ccf::kEntryKeys.begin(), detail_ccf::kEntryKeys.end(),
                       [&](const char* e) { return key == e; }) == detail_ccf::kEntryKeys.end())
        r.fail(kv.first, at + ": " + key,
               "unknown key (expected " + detail_ccf::entryKeyList() + ")");
    }
    c.submap = static_cast<int>(r.integer(r.key(n, "submap", at), at + ": submap", 0, max_int));
    c.stamp_ns =
        r.integer(r.key(n, "stamp_ns", at), at + ": stamp_ns",
                  std::numeric_limits<long long>::min(), std::numeric_limits<long long>::max());
    c.floor_to_pixel = r.homography(r.key(n, "homography", at), at + ": homography");
    c.rms_px = r.number(r.key(n, "rms_px", at), at + ": rms_px", 0.0, max_double);
    c.coverage = r.number(r.key(n, "coverage", at), at + ": coverage", 0.0, 1.0);
    c.condition = r.number(r.key(n, "condition", at), at + ": condition", 0.0, max_double);
    c.pairs = static_cast<int>(r.integer(r.key(n, "pairs", at), at + ": pairs", 0, max_int));
    c.inliers = static_cast<int>(r.integer(r.key(n, "inliers", at), at + ": inliers", 0, c.pairs));
    out.push_back(c);
  }
  return out;
}

}  // namespace tessera::camera_network
