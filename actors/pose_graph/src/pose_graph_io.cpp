#include <tessera/geometry/pose2.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <deque>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <unordered_map>

namespace tessera::pose_graph {

using io::DatasetError;
using io::Fields;
using io::ParseReport;
using io::TextReader;
namespace {

enum class Tag {
  kVertexSE2,
  kEdgeSE2,
  kVertexSE3,
  kEdgeSE3,
  kFix,
  kVertex2,
  kEdge2,
  kOtherG2o,   // a g2o element this reader does not model
  kOtherToro,  // a TORO element this reader does not model
  kUnknown,
};

Tag classify(std::string_view t) {
  if (t == "VERTEX_SE2") return Tag::kVertexSE2;
  if (t == "EDGE_SE2") return Tag::kEdgeSE2;
  if (t == "VERTEX_SE3:QUAT") return Tag::kVertexSE3;
  if (t == "EDGE_SE3:QUAT") return Tag::kEdgeSE3;
  if (t == "FIX") return Tag::kFix;
  if (t == "VERTEX2") return Tag::kVertex2;
  if (t == "EDGE2") return Tag::kEdge2;
  if (t == "VERTEX3" || t == "EDGE3" || t == "EQUIV") return Tag::kOtherToro;
  if (t.starts_with("VERTEX_") || t.starts_with("EDGE_") || t.starts_with("PARAMS_"))
    return Tag::kOtherG2o;
  return Tag::kUnknown;
}

std::string shortened(std::string_view s) {
  constexpr std::size_t kMax = 40;
  return s.size() <= kMax ? std::string(s) : std::string(s.substr(0, kMax)) + "...";
}

std::string number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Symmetric positive semidefinite up to a relative tolerance; returns the smallest eigenvalue
// through `min_eig` for the message.
template <int N>
bool positiveSemidefinite(const Eigen::Matrix<double, N, N>& m, double& min_eig) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> solver(m, Eigen::EigenvaluesOnly);
  if (solver.info() != Eigen::Success) {
    min_eig = std::numeric_limits<double>::quiet_NaN();
    return false;
  }
  const auto& ev = solver.eigenvalues();
  min_eig = ev.minCoeff();
  const double scale = ev.cwiseAbs().maxCoeff();
  return std::isfinite(min_eig) && std::isfinite(scale) && min_eig >= -1e-9 * scale;
}

template <int N>
void checkInformation(const Fields& f, const Eigen::Matrix<double, N, N>& info) {
  double min_eig = 0;
  if (!positiveSemidefinite<N>(info, min_eig)) {
    f.fail("information matrix is not positive semidefinite (smallest eigenvalue " +
           number(min_eig) + ")");
  }
}

std::int64_t vertexId(const Fields& f, std::size_t i, std::string_view label) {
  return f.integerIn(i, label, 0, kMaxVertexId);
}

Eigen::Quaterniond readQuaternion(const Fields& f, std::size_t first) {
  const double x = f.real(first, "qx"), y = f.real(first + 1, "qy"), z = f.real(first + 2, "qz"),
               w = f.real(first + 3, "qw");
  Eigen::Quaterniond q(w, x, y, z);
  const double n = q.coeffs().stableNorm();
  if (!std::isfinite(n) || n < 1e-6)
    f.fail("quaternion (" + number(x) + ", " + number(y) + ", " + number(z) + ", " + number(w) +
           ") has no usable norm");
  // A quaternion already of unit norm (to rounding) is kept bit for bit, so write/read round
  // trips are exact.
  if (std::abs(n - 1.0) > 8 * std::numeric_limits<double>::epsilon()) q.coeffs() /= n;
  return q;
}

// 2D and 3D pose algebra for building initial poses from edges: the graph's own (pose_graph.hpp,
// Pose3), except that an inverted 2D edge keeps its heading unwrapped, as the file gave it.
Eigen::Vector3d composeEdge(const Eigen::Vector3d& a, const Eigen::Vector3d& d) {
  return compose(a, d);
}
Eigen::Vector3d invertEdge(const Eigen::Vector3d& d) {
  const double c = std::cos(d[2]), s = std::sin(d[2]);
  return {-c * d[0] - s * d[1], s * d[0] - c * d[1], -d[2]};
}
Pose3 composeEdge(const Pose3& a, const Pose3& d) {
  return a * d;
}
Pose3 invertEdge(const Pose3& d) {
  return d.inverse();
}

// The file as read, keyed by the file's ids: what the parsing rules (duplicates, references,
// building poses for a file without vertices) are checked on before it becomes a Graph.
template <class Pose, int Dim>
struct FileGraph {
  struct Edge {
    std::int64_t from = 0, to = 0;
    Pose measurement{};  // `to` in the frame of `from`
    Eigen::Matrix<double, Dim, Dim> information = Eigen::Matrix<double, Dim, Dim>::Identity();
  };
  std::map<std::int64_t, Pose> vertices;
  std::vector<Edge> edges;          // in file order
  std::vector<std::int64_t> fixed;  // ids from FIX lines
};
using FileGraph2D = FileGraph<Eigen::Vector3d, 3>;
using FileGraph3D = FileGraph<Pose3, 6>;

// Nodes in increasing id order, edges in file order, FIX ids as fixed nodes.
template <class G, class F>
G toGraph(const F& file) {
  G g;
  for (const auto& [id, pose] : file.vertices) g.addNode(id, pose);
  for (const auto id : file.fixed) g.fixed[static_cast<std::size_t>(g.index(id))] = true;
  for (const auto& e : file.edges) {
    typename G::EdgeType edge;
    edge.from = g.index(e.from);
    edge.to = g.index(e.to);
    edge.measurement = e.measurement;
    edge.information = e.information;
    g.edges.push_back(edge);
  }
  return g;
}

Eigen::Vector3d origin(const Eigen::Vector3d*) {
  return Eigen::Vector3d::Zero();
}
Pose3 origin(const Pose3*) {
  return Pose3{};
}

// Places the vertices of a graph read without vertex lines (see the header). Returns the number
// placed by the odometry chain and by the walk over other edges.
template <typename Graph>
std::pair<std::size_t, std::size_t> buildInitialPoses(Graph& g, const std::filesystem::path& file) {
  using PoseT = typename decltype(g.vertices)::mapped_type;
  std::set<std::int64_t> ids;
  std::unordered_map<std::int64_t, std::vector<std::size_t>> incident;
  std::unordered_map<std::int64_t, std::size_t> forward, backward;  // keyed by the later id
  for (std::size_t k = 0; k < g.edges.size(); ++k) {
    const auto& e = g.edges[k];
    ids.insert(e.from);
    ids.insert(e.to);
    incident[e.from].push_back(k);
    incident[e.to].push_back(k);
    if (e.to == e.from + 1) forward.emplace(e.to, k);
    if (e.from == e.to + 1) backward.emplace(e.from, k);
  }
  if (ids.empty()) return {0, 0};

  const std::int64_t first = *ids.begin();
  g.vertices.emplace(first, origin(static_cast<const PoseT*>(nullptr)));
  std::size_t chained = 1;
  for (auto it = std::next(ids.begin()); it != ids.end(); ++it) {
    const std::int64_t id = *it;
    const auto prev = g.vertices.find(id - 1);
    if (prev == g.vertices.end()) continue;
    if (auto f = forward.find(id); f != forward.end()) {
      g.vertices.emplace(id, composeEdge(prev->second, g.edges[f->second].measurement));
      ++chained;
    } else if (auto b = backward.find(id); b != backward.end()) {
      g.vertices.emplace(id, composeEdge(prev->second, invertEdge(g.edges[b->second].measurement)));
      ++chained;
    }
  }

  std::size_t walked = 0;
  if (g.vertices.size() < ids.size()) {
    std::deque<std::int64_t> queue;
    for (const auto& [id, pose] : g.vertices) queue.push_back(id);
    while (!queue.empty()) {
      const std::int64_t id = queue.front();
      queue.pop_front();
      const PoseT here = g.vertices.at(id);
      for (const std::size_t k : incident[id]) {
        const auto& e = g.edges[k];
        const bool outgoing = e.from == id;
        const std::int64_t other = outgoing ? e.to : e.from;
        if (g.vertices.count(other)) continue;
        g.vertices.emplace(other, outgoing ? composeEdge(here, e.measurement)
                                           : composeEdge(here, invertEdge(e.measurement)));
        ++walked;
        queue.push_back(other);
      }
    }
  }
  if (g.vertices.size() < ids.size()) {
    for (const std::int64_t id : ids) {
      if (!g.vertices.count(id)) {
        throw DatasetError(file, 0,
                           "the file has no vertices and vertex " + std::to_string(id) +
                               " is not connected to vertex " + std::to_string(first) + " (" +
                               std::to_string(ids.size() - g.vertices.size()) +
                               " vertices unreachable); cannot build initial poses");
      }
    }
  }
  return {chained, walked};
}

// Every edge must name defined vertices (file with vertices), and so must FIX lines.
template <typename Graph>
void checkReferences(const Graph& g, const std::vector<std::size_t>& edge_lines,
                     const std::vector<std::size_t>& fix_lines, const std::filesystem::path& file) {
  for (std::size_t k = 0; k < g.edges.size(); ++k) {
    for (const std::int64_t id : {g.edges[k].from, g.edges[k].to}) {
      if (!g.vertices.count(id))
        throw DatasetError(file, edge_lines[k],
                           "edge " + std::to_string(g.edges[k].from) + " -> " +
                               std::to_string(g.edges[k].to) + " refers to vertex " +
                               std::to_string(id) + ", which the file does not define");
    }
  }
  for (std::size_t k = 0; k < g.fixed.size(); ++k) {
    if (!g.vertices.count(g.fixed[k]))
      throw DatasetError(
          file, fix_lines[k],
          "FIX names vertex " + std::to_string(g.fixed[k]) + ", which is not in the graph");
  }
}

}  // namespace

PoseGraphFile readPoseGraph(TextReader& reader) {
  PoseGraphFile out;
  FileGraph2D file2d;
  FileGraph3D file3d;
  ParseReport& report = out.report;
  enum class Family { kNone, kG2o, kToro } family = Family::kNone;
  std::size_t family_line = 0, dimension_line = 0;
  int dimension = 0;
  std::vector<std::size_t> edge_lines, fix_lines;
  std::map<std::int64_t, std::size_t> vertex_lines;

  auto setFamily = [&](Family f, const Fields& fields) {
    if (family == Family::kNone) {
      family = f;
      family_line = reader.lineNumber();
    } else if (family != f) {
      fields.fail(std::string("mixes formats: tag '") + shortened(fields[0]) + "' is " +
                  (f == Family::kG2o ? "g2o" : "TORO") + " but line " +
                  std::to_string(family_line) + " was " +
                  (family == Family::kG2o ? "g2o" : "TORO"));
    }
  };
  auto setDimension = [&](int d, const Fields& fields) {
    if (dimension == 0) {
      dimension = d;
      dimension_line = reader.lineNumber();
    } else if (dimension != d) {
      fields.fail("mixes 2D and 3D elements: '" + shortened(fields[0]) + "' is " +
                  std::to_string(d) + "D but line " + std::to_string(dimension_line) + " was " +
                  std::to_string(dimension) + "D");
    }
  };
  auto newVertex = [&](std::int64_t id, const Fields& fields) {
    const auto [it, inserted] = vertex_lines.emplace(id, reader.lineNumber());
    if (!inserted)
      fields.fail("vertex " + std::to_string(id) + " is defined twice (first at line " +
                  std::to_string(it->second) + ")");
  };
  auto endpoints = [&](const Fields& fields) {
    const std::int64_t from = vertexId(fields, 1, "from id");
    const std::int64_t to = vertexId(fields, 2, "to id");
    if (from == to) fields.fail("edge from vertex " + std::to_string(from) + " to itself");
    edge_lines.push_back(reader.lineNumber());
    return std::pair{from, to};
  };

  std::string line;
  while (reader.next(line)) {
    ++report.lines;
    const Fields f(reader, line);
    if (f.empty() || f[0].front() == '#') continue;
    const Tag tag = classify(f[0]);
    switch (tag) {
      case Tag::kVertexSE2:
      case Tag::kVertex2: {
        setFamily(tag == Tag::kVertex2 ? Family::kToro : Family::kG2o, f);
        setDimension(2, f);
        f.requireExactly(5, f[0]);
        const std::int64_t id = vertexId(f, 1, "id");
        const Eigen::Vector3d pose(f.real(2, "x"), f.real(3, "y"), f.real(4, "theta"));
        newVertex(id, f);
        file2d.vertices.emplace(id, pose);
        break;
      }
      case Tag::kEdgeSE2:
      case Tag::kEdge2: {
        const bool toro = tag == Tag::kEdge2;
        setFamily(toro ? Family::kToro : Family::kG2o, f);
        setDimension(2, f);
        f.requireExactly(12, f[0]);
        FileGraph2D::Edge e;
        std::tie(e.from, e.to) = endpoints(f);
        e.measurement = {f.real(3, "dx"), f.real(4, "dy"), f.real(5, "dtheta")};
        std::array<double, 6> v{};
        for (std::size_t i = 0; i < 6; ++i) v[i] = f.real(6 + i, "information");
        Eigen::Matrix3d& I = e.information;
        if (toro) {  // ff fs ss rr fr sr
          I << v[0], v[1], v[4], v[1], v[2], v[5], v[4], v[5], v[3];
        } else {  // 11 12 13 22 23 33
          I << v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5];
        }
        checkInformation<3>(f, I);
        file2d.edges.push_back(e);
        break;
      }
      case Tag::kVertexSE3: {
        setFamily(Family::kG2o, f);
        setDimension(3, f);
        f.requireExactly(9, f[0]);
        const std::int64_t id = vertexId(f, 1, "id");
        Pose3 p;
        p.t = {f.real(2, "x"), f.real(3, "y"), f.real(4, "z")};
        p.q = readQuaternion(f, 5);
        newVertex(id, f);
        file3d.vertices.emplace(id, p);
        break;
      }
      case Tag::kEdgeSE3: {
        setFamily(Family::kG2o, f);
        setDimension(3, f);
        f.requireExactly(31, f[0]);
        FileGraph3D::Edge e;
        std::tie(e.from, e.to) = endpoints(f);
        e.measurement.t = {f.real(3, "dx"), f.real(4, "dy"), f.real(5, "dz")};
        e.measurement.q = readQuaternion(f, 6);
        std::size_t i = 10;
        for (int r = 0; r < 6; ++r) {
          for (int c = r; c < 6; ++c) {
            e.information(r, c) = e.information(c, r) = f.real(i++, "information");
          }
        }
        checkInformation<6>(f, e.information);
        file3d.edges.push_back(e);
        break;
      }
      case Tag::kFix: {
        setFamily(Family::kG2o, f);
        f.requireAtLeast(2, "FIX");
        for (std::size_t i = 1; i < f.size(); ++i) {
          file2d.fixed.push_back(vertexId(f, i, "id"));
          fix_lines.push_back(reader.lineNumber());
        }
        break;
      }
      case Tag::kOtherG2o:
        setFamily(Family::kG2o, f);
        report.skip(reader, "unsupported g2o tag " + shortened(f[0]));
        continue;
      case Tag::kOtherToro:
        setFamily(Family::kToro, f);
        report.skip(reader, "unsupported TORO tag " + shortened(f[0]));
        continue;
      case Tag::kUnknown:
        report.skip(reader, "unknown tag");
        continue;
    }
    ++report.records;
  }

  if (dimension == 0)
    throw DatasetError(reader.path(), 0,
                       "no pose-graph vertex or edge found (expected g2o VERTEX_SE2/EDGE_SE2/"
                       "VERTEX_SE3:QUAT/EDGE_SE3:QUAT or TORO VERTEX2/EDGE2 lines)");
  out.format = family == Family::kToro ? GraphFormat::kToro : GraphFormat::kG2o;
  out.dimension = dimension;
  out.vertex_lines = vertex_lines.size();
  auto finish = [&](auto& graph) {
    if (graph.vertices.empty()) {
      std::tie(out.chained_vertices, out.walked_vertices) = buildInitialPoses(graph, reader.path());
    }
    checkReferences(graph, edge_lines, fix_lines, reader.path());
  };
  if (dimension == 2) {
    finish(file2d);
    out.graph2d = toGraph<Graph2D>(file2d);
  } else {
    file3d.fixed = std::move(file2d.fixed);
    finish(file3d);
    out.graph3d = toGraph<Graph3D>(file3d);
  }
  return out;
}

PoseGraphFile readPoseGraph(const std::filesystem::path& path) {
  TextReader reader(path);
  return readPoseGraph(reader);
}

Graph2D readPoseGraph2D(const std::filesystem::path& path, ParseReport* report) {
  PoseGraphFile file = readPoseGraph(path);
  if (file.dimension != 2) throw DatasetError(path, 0, "holds a 3D pose graph; expected 2D");
  if (report) *report = std::move(file.report);
  return std::move(file.graph2d);
}

Graph3D readPoseGraph3D(const std::filesystem::path& path, ParseReport* report) {
  PoseGraphFile file = readPoseGraph(path);
  if (file.dimension != 3) throw DatasetError(path, 0, "holds a 2D pose graph; expected 3D");
  if (report) *report = std::move(file.report);
  return std::move(file.graph3d);
}

// ---- writers ----
namespace {

class LineWriter {
 public:
  explicit LineWriter(std::filesystem::path path) : path_(std::move(path)) {}

  LineWriter& tag(std::string_view t) {
    text_.append(t);
    return *this;
  }
  LineWriter& id(std::int64_t v) {
    text_.push_back(' ');
    text_.append(std::to_string(v));
    return *this;
  }
  // Shortest representation that reads back to the same double.
  LineWriter& num(double v, std::string_view what) {
    if (!std::isfinite(v))
      throw DatasetError(path_, 0, "cannot write " + std::string(what) + ": value is not finite");
    char buf[32];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    text_.push_back(' ');
    text_.append(buf, end);
    return *this;
  }
  void endLine() { text_.push_back('\n'); }

  void save() {
    // Written aside and renamed into place: the file is the old graph or the new one, whole.
    try {
      io::writeFileAtomically(path_, text_);
    } catch (const io::FileWriteError& e) {
      throw DatasetError(path_, 0, e.reason());
    }
  }

 private:
  std::filesystem::path path_;
  std::string text_;
};

std::string vertexWhat(std::int64_t id) {
  return "vertex " + std::to_string(id);
}
std::string edgeWhat(std::int64_t a, std::int64_t b) {
  return "edge " + std::to_string(a) + " -> " + std::to_string(b);
}

// Node indices in increasing id order (files list vertices that way).
template <class G>
std::vector<std::size_t> byId(const G& g) {
  std::vector<std::size_t> order(g.ids.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&g](std::size_t a, std::size_t b) { return g.ids[a] < g.ids[b]; });
  return order;
}

template <class G>
std::int64_t idOf(const G& g, int node) {
  return g.ids[static_cast<std::size_t>(node)];
}

void writeVertices2D(const Graph2D& g, const std::vector<std::size_t>& order, LineWriter& w,
                     std::string_view tag) {
  for (const std::size_t i : order) {
    const std::int64_t id = g.ids[i];
    const Eigen::Vector3d& p = g.poses[i];
    const std::string what = vertexWhat(id);
    w.tag(tag).id(id).num(p[0], what).num(p[1], what).num(p[2], what).endLine();
  }
}

template <class G>
void writeFixed(const G& g, const std::vector<std::size_t>& order, LineWriter& w) {
  for (const std::size_t i : order)
    if (g.fixed[i]) w.tag("FIX").id(g.ids[i]).endLine();
}

}  // namespace

void writeG2o(const Graph2D& graph, const std::filesystem::path& path) {
  LineWriter w(path);
  const auto order = byId(graph);
  writeVertices2D(graph, order, w, "VERTEX_SE2");
  for (const auto& e : graph.edges) {
    const std::int64_t from = idOf(graph, e.from), to = idOf(graph, e.to);
    const std::string what = edgeWhat(from, to);
    w.tag("EDGE_SE2").id(from).id(to);
    for (int i = 0; i < 3; ++i) w.num(e.measurement[i], what);
    for (int r = 0; r < 3; ++r)
      for (int c = r; c < 3; ++c) w.num(e.information(r, c), what);
    w.endLine();
  }
  writeFixed(graph, order, w);
  w.save();
}

void writeG2o(const Graph3D& graph, const std::filesystem::path& path) {
  LineWriter w(path);
  const auto order = byId(graph);
  auto pose = [&w](const Pose3& p, const std::string& what) {
    for (int i = 0; i < 3; ++i) w.num(p.t[i], what);
    w.num(p.q.x(), what).num(p.q.y(), what).num(p.q.z(), what);
    w.num(p.q.w(), what);
  };
  for (const std::size_t i : order) {
    w.tag("VERTEX_SE3:QUAT").id(graph.ids[i]);
    pose(graph.poses[i], vertexWhat(graph.ids[i]));
    w.endLine();
  }
  for (const auto& e : graph.edges) {
    const std::int64_t from = idOf(graph, e.from), to = idOf(graph, e.to);
    const std::string what = edgeWhat(from, to);
    w.tag("EDGE_SE3:QUAT").id(from).id(to);
    pose(e.measurement, what);
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) w.num(e.information(r, c), what);
    w.endLine();
  }
  writeFixed(graph, order, w);
  w.save();
}

void writeToro(const Graph2D& graph, const std::filesystem::path& path) {
  LineWriter w(path);
  writeVertices2D(graph, byId(graph), w, "VERTEX2");
  for (const auto& e : graph.edges) {
    const std::int64_t from = idOf(graph, e.from), to = idOf(graph, e.to);
    const std::string what = edgeWhat(from, to);
    const Eigen::Matrix3d& I = e.information;
    w.tag("EDGE2").id(from).id(to);
    for (int i = 0; i < 3; ++i) w.num(e.measurement[i], what);
    w.num(I(0, 0), what).num(I(0, 1), what).num(I(1, 1), what);
    w.num(I(2, 2), what).num(I(0, 2), what).num(I(1, 2), what);
    w.endLine();
  }
  w.save();
}

}  // namespace tessera::pose_graph
