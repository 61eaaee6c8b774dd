#include <tessera/io/atomic_file.hpp>
#include <tessera/laser_slam/map_assembler.hpp>
#include <tessera/laser_slam/slam_state.hpp>

#include <yaml-cpp/yaml.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string_view>

namespace tessera::laser_slam {
namespace fs = std::filesystem;

namespace {

constexpr const char* kStateFile = "state.yaml";

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw SlamStateError(file.string() + ": " + what);
}

/// Written aside and renamed over any older file (io::AtomicFile): each file is whole.
void writeStateFile(const fs::path& path, std::string_view content) {
  try {
    io::writeFileAtomically(path, content);
  } catch (const io::FileWriteError& e) {
    fail(path, e.reason());
  }
}

/// Shortest text that reads back as the same double (std::to_chars without a precision).
std::string numberText(double v) {
  std::array<char, 64> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), res.ptr);
}

std::string poseText(const tessera::Pose2& p) {
  return "[" + numberText(p.x) + ", " + numberText(p.y) + ", " + numberText(p.theta) + "]";
}

/// FNV-1a, 64 bit: catches a cell file changed but not resized (not a security measure).
std::uint64_t fnv1a64(const std::vector<std::int8_t>& bytes) {
  std::uint64_t h = 14695981039346656037ull;
  for (const std::int8_t b : bytes) {
    h ^= static_cast<std::uint8_t>(b);
    h *= 1099511628211ull;
  }
  return h;
}

std::string hexText(std::uint64_t v) {
  std::array<char, 17> buf{};
  std::snprintf(buf.data(), buf.size(), "%016llx", static_cast<unsigned long long>(v));
  return std::string(buf.data(), 16);
}

std::string cellFileName(int id) {
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "submap_%04d.cells", id);
  return buf.data();
}

std::size_t cellCount(const tessera::grid::OccupancyMap& g) {
  return static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
}

/// The first cell value outside -1..100, or -1 when all are valid.
std::ptrdiff_t firstBadCell(const std::vector<std::int8_t>& cells) {
  const auto it =
      std::find_if(cells.begin(), cells.end(), [](std::int8_t v) { return v < -1 || v > 100; });
  return it == cells.end() ? -1 : it - cells.begin();
}

bool symmetricFinite(const Eigen::Matrix3d& m) {
  if (!m.allFinite()) return false;
  const double scale = std::max(1.0, m.cwiseAbs().maxCoeff());
  return (m - m.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale;
}

/// Positive semidefinite to rounding (the rule the g2o reader applies to information).
bool positiveSemidefinite(const Eigen::Matrix3d& m) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (m + m.transpose()));
  const double scale = std::max(1e-300, m.cwiseAbs().maxCoeff());
  return eig.eigenvalues().minCoeff() >= -1e-9 * scale;
}

// ---- checks shared by save and load: `where` names the submap or constraint ----

/// Empty when the submap is valid, else what is wrong (field: problem).
std::string submapProblem(const SavedSubmap& s) {
  const auto& g = s.grid;
  if (s.id < 0) return "id: must be >= 0, got " + std::to_string(s.id);
  if (!s.origin.isFinite()) return "origin: must be finite, got " + poseText(s.origin);
  if (!(std::isfinite(g.resolution) && g.resolution > 0))
    return "resolution: must be > 0 [m], got " + numberText(g.resolution);
  if (!g.origin.isFinite()) return "grid_origin: must be finite, got " + poseText(g.origin);
  if (g.width <= 0 || g.height <= 0)
    return "width x height: must be positive, got " + std::to_string(g.width) + " x " +
           std::to_string(g.height);
  if (g.cells.size() != cellCount(g))
    return "cells: " + std::to_string(g.cells.size()) + " values for " + std::to_string(g.width) +
           " x " + std::to_string(g.height);
  if (const auto k = firstBadCell(g.cells); k >= 0)
    return "cells: value " + std::to_string(g.cells[static_cast<std::size_t>(k)]) + " at index " +
           std::to_string(k) + " is outside -1..100";
  return {};
}

std::string cameraProblem(const SavedCamera& c, const std::set<int>& ids) {
  if (const std::string p = floorCameraCalibrationProblem(c); !p.empty()) return p;
  if (!ids.count(c.submap))
    return "submap: names submap " + std::to_string(c.submap) + ", not saved";
  return {};
}

std::string constraintProblem(const SavedConstraint& c, const std::set<int>& ids) {
  if (!ids.count(c.from)) return "from: names submap " + std::to_string(c.from) + ", not saved";
  if (!ids.count(c.to)) return "to: names submap " + std::to_string(c.to) + ", not saved";
  if (c.from == c.to) return "to: links submap " + std::to_string(c.from) + " to itself";
  if (!c.relative.isFinite()) return "relative: must be finite, got " + poseText(c.relative);
  if (!symmetricFinite(c.information)) return "information: must be finite and symmetric";
  if (!positiveSemidefinite(c.information)) return "information: must be positive semidefinite";
  return {};
}

// ---- YAML reading with errors naming file:line and the field ----

class Reader {
 public:
  explicit Reader(fs::path file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const YAML::Node& n, const std::string& field,
                         const std::string& what) const {
    const std::string at = n.Mark().is_null()
                               ? file_.string()
                               : file_.string() + ":" + std::to_string(n.Mark().line + 1);
    throw SlamStateError(at + ": " + field + ": " + what);
  }

  YAML::Node key(const YAML::Node& parent, const char* k, const std::string& field) const {
    const YAML::Node n = parent[k];
    if (!n) fail(parent, field, "missing");
    return n;
  }

  static std::string text(const YAML::Node& n) {
    if (n.IsScalar()) return "'" + n.Scalar() + "'";
    YAML::Emitter e;
    e << YAML::Flow << n;
    std::string s = e.c_str();
    if (s.size() > 80) s = s.substr(0, 77) + "...";
    return s;
  }

  std::string string(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar() || n.Scalar().empty())
      fail(n, field, "must be a non-empty text, got " + text(n));
    return n.Scalar();
  }

  long long integer(const YAML::Node& n, const std::string& field, long long lo,
                    long long hi) const {
    long long v = 0;
    if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v))
      fail(n, field, "must be an integer, got " + text(n));
    if (v < lo || v > hi)
      fail(n, field,
           "must be in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + text(n));
    return v;
  }

  double number(const YAML::Node& n, const std::string& field) const {
    double v = 0;
    if (!n.IsScalar() || !YAML::convert<double>::decode(n, v))
      fail(n, field, "must be a number, got " + text(n));
    if (!std::isfinite(v)) fail(n, field, "must be finite, got " + text(n));
    return v;
  }

  bool boolean(const YAML::Node& n, const std::string& field) const {
    bool v = false;
    if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v))
      fail(n, field, "must be true or false, got " + text(n));
    return v;
  }

  std::vector<double> numbers(const YAML::Node& n, const std::string& field, std::size_t count,
                              const char* shape) const {
    if (!n.IsSequence() || n.size() != count)
      fail(n, field, std::string("must be a list ") + shape + ", got " + text(n));
    std::vector<double> out;
    for (std::size_t k = 0; k < count; ++k) {
      const YAML::Node e = n[k];
      double v = 0;
      if (!e.IsScalar() || !YAML::convert<double>::decode(e, v))
        fail(n, field, std::string("must be a list ") + shape + " of numbers, got " + text(n));
      if (!std::isfinite(v))
        fail(n, field,
             std::string("must be a list ") + shape + " of finite numbers, got " + text(n));
      out.push_back(v);
    }
    return out;
  }

  tessera::Pose2 pose(const YAML::Node& n, const std::string& field) const {
    const auto v = numbers(n, field, 3, "[x, y, theta]");
    return {v[0], v[1], v[2]};
  }

  const fs::path& file() const { return file_; }

 private:
  fs::path file_;
};

std::vector<std::int8_t> readCells(const fs::path& path, std::size_t expected,
                                   const std::string& field) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) fail(path, field + ": cell file missing");
  const auto size = fs::file_size(path, ec);
  if (ec) fail(path, field + ": cannot read its size: " + ec.message());
  if (size != expected)
    fail(path, field + ": holds " + std::to_string(size) + " bytes, expected " +
                   std::to_string(expected) + " (width x height; truncated or not this submap's)");
  std::vector<std::int8_t> cells(expected);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, field + ": cannot open for reading");
  in.read(reinterpret_cast<char*>(cells.data()), static_cast<std::streamsize>(expected));
  if (static_cast<std::size_t>(in.gcount()) != expected) fail(path, field + ": read failed");
  return cells;
}

void writeCells(const fs::path& path, const std::vector<std::int8_t>& cells) {
  writeStateFile(path, {reinterpret_cast<const char*>(cells.data()), cells.size()});
}

std::string versionProblem(int version) {
  if (version >= SlamState::kOldestFormatVersion && version <= SlamState::kFormatVersion) return {};
  return "version: this build writes version " + std::to_string(SlamState::kFormatVersion) +
         " (from states of versions " + std::to_string(SlamState::kOldestFormatVersion) + " to " +
         std::to_string(SlamState::kFormatVersion) + "), the state says " + std::to_string(version);
}

std::string cameraAt(std::size_t k, const SavedCamera& c) {
  return "cameras[" + std::to_string(k) + "] (camera " + std::to_string(c.camera) + "): ";
}

}  // namespace

/// What state.yaml says of a submap once its cells are on disk.
struct SlamStateWriter::Impl {
  struct SubmapHeader {
    tessera::Pose2 origin;
    bool finished = true;
    double resolution = 0;
    int width = 0;
    int height = 0;
    tessera::Pose2 grid_origin;
    std::string file;
    std::uint64_t checksum = 0;
  };
  fs::path dir;
  fs::path yaml_path;
  std::string frame_id;
  std::map<int, SubmapHeader> submaps;
  std::set<int> ids;
  std::vector<SavedConstraint> constraints;
  std::map<int, SavedCamera> cameras;
  bool dir_ready = false;
  bool finished = false;

  void ensureDirectory() {
    if (dir_ready) return;
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) fail(dir, "cannot create directory: " + ec.message());
    dir_ready = true;
  }
  void checkOpen() const {
    if (finished) fail(yaml_path, "already written: a writer writes one state");
  }
};

SlamStateWriter::SlamStateWriter(fs::path dir, std::string frame_id, int format_version)
    : impl_(std::make_unique<Impl>()) {
  impl_->yaml_path = dir / kStateFile;
  impl_->dir = std::move(dir);
  if (const std::string p = versionProblem(format_version); !p.empty()) fail(impl_->yaml_path, p);
  if (frame_id.empty()) fail(impl_->yaml_path, "frame_id: must not be empty");
  impl_->frame_id = std::move(frame_id);
}

SlamStateWriter::~SlamStateWriter() = default;

std::size_t SlamStateWriter::submaps() const {
  return impl_->submaps.size();
}

void SlamStateWriter::addSubmap(const SavedSubmap& s) {
  Impl& m = *impl_;
  m.checkOpen();
  if (const std::string p = submapProblem(s); !p.empty())
    fail(m.yaml_path, "submap " + std::to_string(s.id) + ": " + p);
  if (m.ids.count(s.id)) fail(m.yaml_path, "submap " + std::to_string(s.id) + ": id: twice");
  m.ensureDirectory();
  Impl::SubmapHeader h{s.origin,      s.finished,    s.grid.resolution,  s.grid.width,
                       s.grid.height, s.grid.origin, cellFileName(s.id), fnv1a64(s.grid.cells)};
  writeCells(m.dir / h.file, s.grid.cells);
  m.submaps.emplace(s.id, std::move(h));
  m.ids.insert(s.id);
}

void SlamStateWriter::addConstraint(const SavedConstraint& c) {
  Impl& m = *impl_;
  m.checkOpen();
  if (const std::string p = constraintProblem(c, m.ids); !p.empty())
    fail(m.yaml_path, "constraints[" + std::to_string(m.constraints.size()) + "]: " + p);
  m.constraints.push_back(c);
}

void SlamStateWriter::addCamera(const SavedCamera& c) {
  Impl& m = *impl_;
  m.checkOpen();
  const std::string at = cameraAt(m.cameras.size(), c);
  if (const std::string p = cameraProblem(c, m.ids); !p.empty()) fail(m.yaml_path, at + p);
  if (!m.cameras.emplace(c.camera, c).second) fail(m.yaml_path, at + "id: twice");
}

void SlamStateWriter::finish() {
  Impl& m = *impl_;
  m.checkOpen();
  m.ensureDirectory();
  std::ostringstream y;
  YAML::Emitter frame;
  frame << m.frame_id;
  y << "# Tessera laser SLAM state (docs/architecture.md#saved-slam-state)\n"
    << "format: " << SlamState::kFormatName << "\n"
    << "version: " << SlamState::kFormatVersion << "\n"
    << "frame_id: " << frame.c_str() << "\n"
    << "submaps:" << (m.submaps.empty() ? " []" : "") << "\n";
  for (const auto& [id, s] : m.submaps) {
    y << "  - id: " << id << "\n"
      << "    origin: " << poseText(s.origin) << "\n"
      << "    finished: " << (s.finished ? "true" : "false") << "\n"
      << "    resolution: " << numberText(s.resolution) << "\n"
      << "    width: " << s.width << "\n"
      << "    height: " << s.height << "\n"
      << "    grid_origin: " << poseText(s.grid_origin) << "\n"
      << "    file: " << s.file << "\n"
      << "    fnv1a64: \"" << hexText(s.checksum) << "\"\n";
  }
  y << "constraints:" << (m.constraints.empty() ? " []" : "") << "\n";
  for (const SavedConstraint& c : m.constraints) {
    y << "  - from: " << c.from << "\n"
      << "    to: " << c.to << "\n"
      << "    kind: " << (c.revisit ? "revisit" : "hand_over") << "\n"
      << "    relative: " << poseText(c.relative) << "\n"
      << "    information: [";
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k)
        y << numberText(c.information(r, k)) << (r == 2 && k == 2 ? "" : ", ");
    y << "]\n";
  }
  y << "cameras:" << (m.cameras.empty() ? " []" : "") << "\n";
  for (const auto& [id, c] : m.cameras) {
    y << "  - id: " << c.camera << "\n"
      << "    submap: " << c.submap << "\n"
      << "    stamp_ns: " << c.stamp_ns << "\n"
      << "    homography: [";
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k)
        y << numberText(c.floor_to_pixel(r, k)) << (r == 2 && k == 2 ? "" : ", ");
    y << "]\n"
      << "    rms_px: " << numberText(c.rms_px) << "\n"
      << "    coverage: " << numberText(c.coverage) << "\n"
      << "    condition: " << numberText(c.condition) << "\n"
      << "    pairs: " << c.pairs << "\n"
      << "    inliers: " << c.inliers << "\n";
  }
  // state.yaml appears only once complete: written aside, then renamed over any older one.
  writeStateFile(m.yaml_path, y.str());
  m.finished = true;
}

void saveSlamState(const SlamState& state, const fs::path& dir) {
  SlamStateWriter writer(dir, state.frame_id, state.format_version);
  // The whole state is checked before any file is written; the writer checks each part again.
  const fs::path yaml_path = dir / kStateFile;
  std::vector<const SavedSubmap*> submaps;
  std::set<int> ids;
  for (const SavedSubmap& s : state.submaps) {
    if (const std::string p = submapProblem(s); !p.empty())
      fail(yaml_path, "submap " + std::to_string(s.id) + ": " + p);
    if (!ids.insert(s.id).second) fail(yaml_path, "submap " + std::to_string(s.id) + ": id: twice");
    submaps.push_back(&s);
  }
  std::sort(submaps.begin(), submaps.end(),
            [](const SavedSubmap* a, const SavedSubmap* b) { return a->id < b->id; });
  for (std::size_t k = 0; k < state.constraints.size(); ++k)
    if (const std::string p = constraintProblem(state.constraints[k], ids); !p.empty())
      fail(yaml_path, "constraints[" + std::to_string(k) + "]: " + p);
  std::set<int> camera_ids;
  for (std::size_t k = 0; k < state.cameras.size(); ++k) {
    const SavedCamera& c = state.cameras[k];
    if (const std::string p = cameraProblem(c, ids); !p.empty())
      fail(yaml_path, cameraAt(k, c) + p);
    if (!camera_ids.insert(c.camera).second) fail(yaml_path, cameraAt(k, c) + "id: twice");
  }
  for (const SavedSubmap* s : submaps) writer.addSubmap(*s);
  for (const SavedConstraint& c : state.constraints) writer.addConstraint(c);
  for (const SavedCamera& c : state.cameras) writer.addCamera(c);
  writer.finish();
}

SlamState loadSlamState(const fs::path& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) fail(dir, "no such directory (expected a SLAM state directory)");
  if (!fs::is_directory(dir, ec))
    fail(dir, "not a directory (a SLAM state is a directory holding state.yaml)");
  const fs::path yaml_path = dir / kStateFile;
  if (!fs::exists(yaml_path, ec))
    fail(yaml_path,
         "missing: the directory holds no SLAM state (map_assembler writes one with "
         "state_dir)");
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path.string());  // it exists: a failure is unreadable or bad YAML
  } catch (const YAML::Exception& e) {
    fail(yaml_path, std::string("not readable as YAML: ") + e.what());
  }
  const Reader r(yaml_path);
  if (!root.IsMap()) fail(yaml_path, "expected a YAML mapping (format, version, submaps, ...)");

  const YAML::Node format = r.key(root, "format", "format");
  if (!format.IsScalar() || format.Scalar() != SlamState::kFormatName)
    r.fail(format, "format",
           Reader::text(format) + " is not '" + SlamState::kFormatName + "' (not a SLAM state)");
  const YAML::Node version = r.key(root, "version", "version");
  const long long v = r.integer(version, "version", std::numeric_limits<int>::min(),
                                std::numeric_limits<int>::max());
  if (v < SlamState::kOldestFormatVersion || v > SlamState::kFormatVersion)
    r.fail(version, "version",
           std::to_string(v) + " is not supported: this build reads versions " +
               std::to_string(SlamState::kOldestFormatVersion) + " to " +
               std::to_string(SlamState::kFormatVersion));

  SlamState state;
  state.format_version = static_cast<int>(v);
  state.frame_id = r.string(r.key(root, "frame_id", "frame_id"), "frame_id");

  const YAML::Node submaps = r.key(root, "submaps", "submaps");
  if (!submaps.IsSequence()) r.fail(submaps, "submaps", "must be a list");
  std::set<int> ids;
  for (std::size_t k = 0; k < submaps.size(); ++k) {
    const YAML::Node n = submaps[k];
    const std::string at = "submaps[" + std::to_string(k) + "]";
    if (!n.IsMap()) r.fail(n, at, "must be a mapping (id, origin, ...)");
    SavedSubmap s;
    s.id = static_cast<int>(
        r.integer(r.key(n, "id", at + ".id"), at + ".id", 0, std::numeric_limits<int>::max()));
    if (!ids.insert(s.id).second)
      r.fail(n["id"], at + ".id", "submap " + std::to_string(s.id) + " is listed twice");
    s.origin = r.pose(r.key(n, "origin", at + ".origin"), at + ".origin");
    s.finished = r.boolean(r.key(n, "finished", at + ".finished"), at + ".finished");
    s.grid.resolution = r.number(r.key(n, "resolution", at + ".resolution"), at + ".resolution");
    if (!(s.grid.resolution > 0))
      r.fail(n["resolution"], at + ".resolution",
             "must be > 0 [m], got " + Reader::text(n["resolution"]));
    const int max_side = std::numeric_limits<int>::max();
    s.grid.width =
        static_cast<int>(r.integer(r.key(n, "width", at + ".width"), at + ".width", 1, max_side));
    s.grid.height = static_cast<int>(
        r.integer(r.key(n, "height", at + ".height"), at + ".height", 1, max_side));
    s.grid.origin = r.pose(r.key(n, "grid_origin", at + ".grid_origin"), at + ".grid_origin");
    const YAML::Node file_node = r.key(n, "file", at + ".file");
    const std::string file = r.string(file_node, at + ".file");
    if (fs::path(file).filename().string() != file || file == "." || file == "..")
      r.fail(file_node, at + ".file",
             "must be a file name inside the state directory, got " + Reader::text(file_node));
    const YAML::Node sum_node = r.key(n, "fnv1a64", at + ".fnv1a64");
    const std::string sum = r.string(sum_node, at + ".fnv1a64");

    const fs::path cell_path = dir / file;
    const std::string field = "submap " + std::to_string(s.id);
    s.grid.cells = readCells(cell_path, cellCount(s.grid), field);
    if (hexText(fnv1a64(s.grid.cells)) != sum)
      fail(cell_path, field + ": checksum " + hexText(fnv1a64(s.grid.cells)) +
                          " differs from state.yaml's fnv1a64 " + sum + " (file changed)");
    if (const auto bad = firstBadCell(s.grid.cells); bad >= 0)
      fail(cell_path, field + ": cell value " +
                          std::to_string(s.grid.cells[static_cast<std::size_t>(bad)]) +
                          " at byte " + std::to_string(bad) + " is outside -1..100");
    state.submaps.push_back(std::move(s));
  }
  std::sort(state.submaps.begin(), state.submaps.end(),
            [](const SavedSubmap& a, const SavedSubmap& b) { return a.id < b.id; });

  const YAML::Node constraints = r.key(root, "constraints", "constraints");
  if (!constraints.IsSequence()) r.fail(constraints, "constraints", "must be a list");
  for (std::size_t k = 0; k < constraints.size(); ++k) {
    const YAML::Node n = constraints[k];
    const std::string at = "constraints[" + std::to_string(k) + "]";
    if (!n.IsMap()) r.fail(n, at, "must be a mapping (from, to, kind, relative, information)");
    SavedConstraint c;
    const int max_id = std::numeric_limits<int>::max();
    c.from = static_cast<int>(r.integer(r.key(n, "from", at + ".from"), at + ".from", 0, max_id));
    c.to = static_cast<int>(r.integer(r.key(n, "to", at + ".to"), at + ".to", 0, max_id));
    const YAML::Node kind = r.key(n, "kind", at + ".kind");
    const std::string kind_text = r.string(kind, at + ".kind");
    if (kind_text != "hand_over" && kind_text != "revisit")
      r.fail(kind, at + ".kind", "must be hand_over or revisit, got " + Reader::text(kind));
    c.revisit = kind_text == "revisit";
    c.relative = r.pose(r.key(n, "relative", at + ".relative"), at + ".relative");
    const YAML::Node info = r.key(n, "information", at + ".information");
    const auto m = r.numbers(info, at + ".information", 9, "of 9 values (3x3, row-major)");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c.information(i, j) = m[static_cast<std::size_t>(i * 3 + j)];
    if (const std::string p = constraintProblem(c, ids); !p.empty())
      r.fail(n, at + "." + p.substr(0, p.find(':')), p.substr(p.find(':') + 2));
    state.constraints.push_back(c);
  }

  // Version 2: the cameras' calibrations, each in a saved submap.
  const YAML::Node cameras = root["cameras"];
  if (v < 2) {
    if (cameras)
      r.fail(cameras, "cameras",
             "not part of version " + std::to_string(v) + " (cameras came with version 2)");
    return state;
  }
  if (!cameras)
    r.fail(root, "cameras", "missing (version 2 lists the camera calibrations, [] for none)");
  if (!cameras.IsSequence()) r.fail(cameras, "cameras", "must be a list");
  std::set<int> camera_ids;
  for (std::size_t k = 0; k < cameras.size(); ++k) {
    const YAML::Node n = cameras[k];
    const std::string at = "cameras[" + std::to_string(k) + "]";
    if (!n.IsMap())
      r.fail(n, at, "must be a mapping (id, submap, stamp_ns, homography, rms_px, ...)");
    SavedCamera c;
    const long long max_int = std::numeric_limits<int>::max();
    c.camera = static_cast<int>(r.integer(r.key(n, "id", at + ".id"), at + ".id", 0, max_int));
    if (!camera_ids.insert(c.camera).second)
      r.fail(n["id"], at + ".id", "camera " + std::to_string(c.camera) + " is listed twice");
    c.submap =
        static_cast<int>(r.integer(r.key(n, "submap", at + ".submap"), at + ".submap", 0, max_int));
    c.stamp_ns =
        r.integer(r.key(n, "stamp_ns", at + ".stamp_ns"), at + ".stamp_ns",
                  std::numeric_limits<long long>::min(), std::numeric_limits<long long>::max());
    const auto h = r.numbers(r.key(n, "homography", at + ".homography"), at + ".homography", 9,
                             "of 9 values (3x3 floor -> pixel homography, row-major)");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c.floor_to_pixel(i, j) = h[static_cast<std::size_t>(i * 3 + j)];
    c.rms_px = r.number(r.key(n, "rms_px", at + ".rms_px"), at + ".rms_px");
    c.coverage = r.number(r.key(n, "coverage", at + ".coverage"), at + ".coverage");
    c.condition = r.number(r.key(n, "condition", at + ".condition"), at + ".condition");
    c.pairs =
        static_cast<int>(r.integer(r.key(n, "pairs", at + ".pairs"), at + ".pairs", 0, max_int));
    c.inliers = static_cast<int>(
        r.integer(r.key(n, "inliers", at + ".inliers"), at + ".inliers", 0, max_int));
    if (const std::string p = cameraProblem(c, ids); !p.empty()) {
      const std::string field = p.substr(0, p.find(':'));
      r.fail(n[field], at + "." + field, p.substr(p.find(':') + 2));
    }
    state.cameras.push_back(c);
  }
  std::sort(state.cameras.begin(), state.cameras.end(),
            [](const SavedCamera& a, const SavedCamera& b) { return a.camera < b.camera; });
  return state;
}

tessera::grid::OccupancyMap assembleSlamState(const SlamState& state, double resolution) {
  MapAssembler assembler(resolution);
  for (const SavedSubmap& s : state.submaps) {
    assembler.setSubmap(s.id, s.grid);
    assembler.setPose(s.id, s.origin);
  }
  return assembler.assemble();
}

}  // namespace tessera::laser_slam
