#include <tessera/pose_graph/pose_graph_io.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "../../hw/datasets/mutate.hpp"
#include "../../shared_data.hpp"

namespace fs = std::filesystem;
using namespace tessera::pose_graph;
using namespace tessera::io;
using namespace tessera;

namespace {

PoseGraphFile readText(const std::string& text, const std::string& name = "test.g2o") {
  TextReader reader = TextReader::fromString(name, text);
  return readPoseGraph(reader);
}

std::string errorOf(const std::string& text) {
  try {
    readText(text);
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "";
}

Eigen::Vector3d composeSe2(const Eigen::Vector3d& a, const Eigen::Vector3d& d) {
  const double c = std::cos(a[2]), s = std::sin(a[2]);
  return {a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], a[2] + d[2]};
}

double angleDiff(double a, double b) {
  return std::abs(std::remainder(a - b, 2 * M_PI));
}

void requireSame(const Graph2D& a, const Graph2D& b) {
  REQUIRE(a.size() == b.size());
  REQUIRE(a.edges.size() == b.edges.size());
  CHECK(a.ids == b.ids);
  CHECK(a.poses == b.poses);
  for (std::size_t k = 0; k < a.edges.size(); ++k) {
    CHECK(a.edges[k].from == b.edges[k].from);
    CHECK(a.edges[k].to == b.edges[k].to);
    CHECK(a.edges[k].measurement == b.edges[k].measurement);
    CHECK(a.edges[k].information == b.edges[k].information);
  }
  CHECK(a.fixed == b.fixed);
}

struct Expected {
  const char* file;
  GraphFormat format;
  int dimension;
  std::size_t vertices, edges, vertex_lines;
};

// Counts from each folder's PROVENANCE.md (and checked with awk on the files).
const Expected kRealGraphs[] = {
    {"posegraph-g2o/intel.g2o", GraphFormat::kG2o, 2, 1728, 2512, 1728},
    {"posegraph-g2o/manhattan.g2o", GraphFormat::kG2o, 2, 3500, 5453, 0},
    {"posegraph-g2o/sphere2500.g2o", GraphFormat::kG2o, 3, 2500, 4949, 2500},
    {"posegraph-toro/INTEL_P_toro.graph", GraphFormat::kToro, 2, 1228, 1505, 1228},
    {"posegraph-toro/M3500_P_toro.graph", GraphFormat::kToro, 2, 3500, 5453, 3500},
    {"posegraph-toro/input_INTEL_g2o.graph", GraphFormat::kG2o, 2, 1228, 1483, 1228},
    {"posegraphs/M3500.g2o", GraphFormat::kG2o, 2, 3500, 5453, 3500},
    {"posegraphs/manhattanOlson3500.g2o", GraphFormat::kG2o, 2, 3500, 5598, 3500},
};

}  // namespace

TEST_CASE("Pose graphs: every shared file reads with the documented counts", "[datasets][graph]") {
  for (const auto& x : kRealGraphs) {
    TESSERA_SHARED_DATA(path, x.file);
    const auto start = std::chrono::steady_clock::now();
    const PoseGraphFile g = readPoseGraph(path);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    INFO(x.file << ": " << g.report.describe() << ", " << ms << " ms");
    CHECK(g.format == x.format);
    REQUIRE(g.dimension == x.dimension);
    const std::size_t v = x.dimension == 2 ? g.graph2d.size() : g.graph3d.size();
    const std::size_t e = x.dimension == 2 ? g.graph2d.edges.size() : g.graph3d.edges.size();
    CHECK(v == x.vertices);
    CHECK(e == x.edges);
    CHECK(g.vertex_lines == x.vertex_lines);
    CHECK(g.report.skipped == 0);
    CHECK(g.report.records == x.vertex_lines + x.edges);
    // Printed with `-s` for the report: parse time of each file.
    UNSCOPED_INFO(x.file << " parsed in " << ms << " ms");
  }
}

TEST_CASE("Pose graphs: a file without vertices gets poses chained from its odometry",
          "[datasets][graph]") {
  TESSERA_SHARED_DATA(edges_only, "posegraph-g2o/manhattan.g2o");
  TESSERA_SHARED_DATA(with_vertices, "posegraphs/M3500.g2o");
  const PoseGraphFile a = readPoseGraph(edges_only);
  CHECK(a.chained_vertices == 3500);
  CHECK(a.walked_vertices == 0);
  CHECK(a.graph2d.poses[a.graph2d.index(0)] == Eigen::Vector3d::Zero());
  // M3500.g2o's vertices are the same odometry chained by its publisher and printed to 6
  // decimals, so the two agree up to rounding that accumulates along the 3500 poses (measured:
  // 7e-7 m at pose 10, 9e-4 m at pose 3499, 1.0e-3 m at worst).
  const Graph2D b = readPoseGraph2D(with_vertices);
  CHECK((b.poses[b.index(10)] - a.graph2d.poses[a.graph2d.index(10)]).norm() < 1e-5);
  double worst = 0;
  for (int i = 0; i < b.size(); ++i) {
    const Eigen::Vector3d& p = b.poses[i];
    const Eigen::Vector3d& q = a.graph2d.poses[a.graph2d.index(b.ids[i])];
    worst = std::max({worst, (p.head<2>() - q.head<2>()).norm(), angleDiff(p[2], q[2])});
  }
  INFO("largest difference " << worst);
  CHECK(worst < 2e-3);
}

TEST_CASE("Pose graphs: an edge i -> j holds pose j in the frame of i (g2o and TORO)",
          "[datasets][graph]") {
  for (const char* file : {"posegraphs/M3500.g2o", "posegraph-toro/M3500_P_toro.graph"}) {
    TESSERA_SHARED_DATA(path, file);
    const Graph2D g = readPoseGraph2D(path);
    std::size_t odometry = 0;
    for (const auto& e : g.edges) {
      if (e.to != e.from + 1) continue;
      ++odometry;
      const Eigen::Vector3d predicted = composeSe2(g.poses[e.from], e.measurement);
      const Eigen::Vector3d& actual = g.poses[e.to];
      INFO(file << " edge " << e.from << " -> " << e.to);
      REQUIRE((predicted.head<2>() - actual.head<2>()).norm() < 1e-4);
      REQUIRE(angleDiff(predicted[2], actual[2]) < 1e-4);
    }
    CHECK(odometry == 3499);
  }
}

TEST_CASE("Pose graphs: TORO information order is ff fs ss rr fr sr", "[datasets][graph]") {
  TESSERA_SHARED_DATA(toro, "posegraph-toro/M3500_P_toro.graph");
  // EDGE2 0 1 1.030390 0.011350 -0.012958 44.484755 -3.659513 376.666983 9745.791650 0 0
  const Graph2D t = readPoseGraph2D(toro);
  const Eigen::Matrix3d& I = t.edges.front().information;
  CHECK(I(0, 0) == 44.484755);
  CHECK(I(0, 1) == -3.659513);
  CHECK(I(1, 0) == -3.659513);
  CHECK(I(1, 1) == 376.666983);
  CHECK(I(2, 2) == 9745.791650);
  CHECK(I(0, 2) == 0.0);
  CHECK(I(1, 2) == 0.0);

  // The same Intel graph in both files: rotation information must land in I(2,2) either way.
  TESSERA_SHARED_DATA(intel_toro, "posegraph-toro/INTEL_P_toro.graph");
  TESSERA_SHARED_DATA(intel_g2o, "posegraph-toro/input_INTEL_g2o.graph");
  const Graph2D a = readPoseGraph2D(intel_toro);
  const Graph2D b = readPoseGraph2D(intel_g2o);
  CHECK(a.edges[0].information(2, 2) == 2496.793089);
  CHECK(b.edges[0].information(2, 2) == 2496.793089);
  CHECK(a.edges[1].information(2, 2) == b.edges[1].information(2, 2));

  // Synthetic: distinct values show where each entry goes.
  const auto g = readText("VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 11 12 22 33 13 23\n");
  Eigen::Matrix3d expected;
  expected << 11, 12, 13, 12, 22, 23, 13, 23, 33;
  // (This matrix is positive definite: determinant 873.)
  CHECK(g.graph2d.edges[0].information == expected);
}

TEST_CASE("Pose graphs: write then read gives identical values (g2o, TORO, 3D)",
          "[datasets][graph]") {
  const auto dir = tessera::test::scratchDir("pose_graph_round_trip");
  for (const char* file :
       {"posegraph-g2o/intel.g2o", "posegraph-g2o/manhattan.g2o",
        "posegraph-toro/INTEL_P_toro.graph", "posegraphs/manhattanOlson3500.g2o"}) {
    TESSERA_SHARED_DATA(path, file);
    const Graph2D g = readPoseGraph2D(path);
    writeG2o(g, dir / "out.g2o");
    writeToro(g, dir / "out.graph");
    const PoseGraphFile as_g2o = readPoseGraph(dir / "out.g2o");
    const PoseGraphFile as_toro = readPoseGraph(dir / "out.graph");
    CHECK(as_g2o.format == GraphFormat::kG2o);
    CHECK(as_toro.format == GraphFormat::kToro);
    INFO(file);
    requireSame(g, as_g2o.graph2d);
    Graph2D no_fix = g;
    std::fill(no_fix.fixed.begin(), no_fix.fixed.end(), false);
    requireSame(no_fix, as_toro.graph2d);
  }
  TESSERA_SHARED_DATA(sphere, "posegraph-g2o/sphere2500.g2o");
  Graph3D g = readPoseGraph3D(sphere);
  g.fixed[g.index(0)] = true;
  writeG2o(g, dir / "sphere.g2o");
  const Graph3D back = readPoseGraph3D(dir / "sphere.g2o");
  REQUIRE(back.size() == g.size());
  REQUIRE(back.edges.size() == g.edges.size());
  for (int i = 0; i < g.size(); ++i) {
    CHECK(back.ids[i] == g.ids[i]);
    CHECK(back.poses[i].t == g.poses[i].t);
    CHECK(back.poses[i].q.coeffs() == g.poses[i].q.coeffs());
  }
  for (std::size_t k = 0; k < g.edges.size(); ++k) {
    CHECK(back.edges[k].measurement.t == g.edges[k].measurement.t);
    CHECK(back.edges[k].measurement.q.coeffs() == g.edges[k].measurement.q.coeffs());
    CHECK(back.edges[k].information == g.edges[k].information);
  }
  CHECK(std::count(back.fixed.begin(), back.fixed.end(), true) == 1);
  CHECK(back.fixed[back.index(0)]);
}

TEST_CASE("Pose graphs: the format comes from the content, not the file name",
          "[datasets][graph]") {
  const auto dir = tessera::test::scratchDir("pose_graph_names");
  std::ofstream(dir / "g2o_content.graph") << "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
                                              "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n";
  std::ofstream(dir / "toro_content.g2o") << "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\n"
                                             "EDGE2 0 1 1 0 0 1 0 1 1 0 0\n";
  CHECK(readPoseGraph(dir / "g2o_content.graph").format == GraphFormat::kG2o);
  CHECK(readPoseGraph(dir / "toro_content.g2o").format == GraphFormat::kToro);
  CHECK_THROWS_AS(readPoseGraph3D(dir / "toro_content.g2o"), DatasetError);
}

TEST_CASE("Pose graphs: mixing g2o and TORO, or 2D and 3D, is an error", "[datasets][graph]") {
  CHECK_THAT(errorOf("VERTEX2 0 0 0 0\nVERTEX_SE2 1 0 0 0\n"),
             Catch::Contains("test.g2o:2") && Catch::Contains("mixes formats"));
  CHECK_THAT(errorOf("VERTEX_SE2 0 0 0 0\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\n"),
             Catch::Contains("mixes formats"));
  CHECK_THAT(errorOf("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n"),
             Catch::Contains("test.g2o:2") && Catch::Contains("2D and 3D"));
  CHECK_THAT(errorOf("FIX 0\nVERTEX2 0 0 0 0\n"), Catch::Contains("mixes formats"));
}

TEST_CASE("Pose graphs: comments, FIX and unmodelled tags", "[datasets][graph]") {
  const auto g = readText(
      "# a comment\n\nVERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 7 1 2\n"
      "EDGE_SE2_XY 0 7 1 2 1 0 1\nFIX 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nHELLO world\n");
  CHECK(g.graph2d.size() == 2);
  CHECK(g.graph2d.edges.size() == 1);
  CHECK(std::count(g.graph2d.fixed.begin(), g.graph2d.fixed.end(), true) == 1);
  CHECK(g.graph2d.fixed[g.graph2d.index(0)]);
  CHECK(g.report.skipped == 3);
  CHECK(g.report.skipped_by_reason.at("unsupported g2o tag VERTEX_XY") == 1);
  CHECK(g.report.skipped_by_reason.at("unsupported g2o tag EDGE_SE2_XY") == 1);
  CHECK(g.report.skipped_by_reason.at("unknown tag") == 1);
  CHECK(g.report.records == 4);
  CHECK_THAT(errorOf("VERTEX_SE2 0 0 0 0\nFIX 3\n"), Catch::Contains("test.g2o:2"));
}

TEST_CASE("Pose graphs: malformed lines are DatasetErrors naming file:line", "[datasets][graph]") {
  const std::string v = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n";
  const std::string info = " 1 0 0 1 0 1\n";
  struct Case {
    const char* what;
    std::string text;
    const char* expect;
  };
  const std::vector<Case> cases = {
      {"too few fields", v + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", "expected 12 fields"},
      {"too many fields", "VERTEX_SE2 0 0 0 0 9\n", "expected 5 fields"},
      {"NaN", v + "EDGE_SE2 0 1 nan 0 0" + info, "finite"},
      {"inf", "VERTEX_SE2 0 inf 0 0\n", "finite"},
      {"1e999", "VERTEX_SE2 0 1e999 0 0\n", "out of range"},
      {"huge id", "VERTEX_SE2 99999999999999999999 0 0 0\n", "out of range"},
      {"id above int", "VERTEX_SE2 2147483648 0 0 0\n", "0..2147483647"},
      {"negative id", "VERTEX_SE2 -1 0 0 0\n", "0..2147483647"},
      {"truncated line", v + "EDGE_SE2 0 1 1 0", "expected 12 fields"},
      {"garbage number", "VERTEX_SE2 0 0x 0 0\n", "expected a number"},
      {"binary garbage", std::string("VERTEX_SE2 0 \x01\x02\xff 0 0\n"), "expected a number"},
      {"non-PSD information", v + "EDGE_SE2 0 1 1 0 0 1 5 0 1 0 1\n", "positive semidefinite"},
      {"negative information", v + "EDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1\n", "positive semidefinite"},
      {"unknown vertex", v + "EDGE_SE2 0 7" + std::string(" 1 0 0") + info, "vertex 7"},
      {"duplicate vertex", v + "VERTEX_SE2 1 2 0 0\n", "defined twice"},
      {"self loop", v + "EDGE_SE2 1 1 1 0 0" + info, "to itself"},
      {"zero quaternion", "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n", "quaternion"},
      {"tiny quaternion", "VERTEX_SE3:QUAT 0 0 0 0 1e-9 0 0 0\n", "quaternion"},
      {"empty file", "", "no pose-graph vertex or edge"},
      {"only comments", "# nothing\n\n", "no pose-graph vertex or edge"},
      {"only unknown tags", "foo bar\nbaz\n", "no pose-graph vertex or edge"},
  };
  for (const auto& c : cases) {
    INFO(c.what);
    const std::string e = errorOf(c.text);
    CHECK_THAT(e, Catch::Contains("test.g2o") && Catch::Contains(c.expect));
  }
  // The unknown-vertex error points at the edge's line, not the end of the file.
  CHECK_THAT(errorOf(v + "EDGE_SE2 0 7 1 0 0" + info + "VERTEX_SE2 2 0 0 0\n"),
             Catch::Contains("test.g2o:3"));
  // A 3D edge with a non-PSD 6x6 information.
  std::string e3 =
      "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
      "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1";
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) e3 += r == c ? (r == 5 ? " -1" : " 1") : " 0";
  CHECK_THAT(errorOf(e3 + "\n"), Catch::Contains("test.g2o:3") && Catch::Contains("semidefinite"));
}

TEST_CASE("Pose graphs: a vertexless file chains, walks around gaps, rejects islands",
          "[datasets][graph]") {
  const std::string info = " 1 0 0 1 0 1\n";
  // 0 -> 1 forward, 2 -> 1 backwards (chained through its inverse), 4 only through 0 -> 4.
  const auto g = readText("EDGE_SE2 0 1 1 0 1.5707963267948966" + info + "EDGE_SE2 2 1 -1 0 0" +
                          info + "EDGE_SE2 0 4 0 2 0" + info);
  REQUIRE(g.graph2d.size() == 4);
  CHECK(g.chained_vertices == 3);
  CHECK(g.walked_vertices == 1);
  auto p = [&g](std::int64_t id) { return g.graph2d.poses[g.graph2d.index(id)]; };
  CHECK(p(1).x() == Approx(1));
  CHECK(p(1).z() == Approx(M_PI / 2));
  // Pose 2 = pose 1 composed with the inverse of (-1, 0, 0) = one metre ahead of pose 1 (+y).
  CHECK(p(2).x() == Approx(1));
  CHECK(p(2).y() == Approx(1));
  CHECK(p(4).y() == Approx(2));
  CHECK_THAT(errorOf("EDGE_SE2 0 1 1 0 0" + info + "EDGE_SE2 5 6 1 0 0" + info),
             Catch::Contains("vertex 5 is not connected to vertex 0"));
  // 3D: vertices chained from edges too.
  std::string e3 = "EDGE_SE3:QUAT 3 4 1 2 3 0 0 0 1";
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) e3 += r == c ? " 1" : " 0";
  const auto g3 = readText(e3 + "\n");
  REQUIRE(g3.dimension == 3);
  CHECK(g3.graph3d.poses[g3.graph3d.index(4)].t == Eigen::Vector3d(1, 2, 3));
}

TEST_CASE("Pose graphs: quaternions are normalised", "[datasets][graph]") {
  const auto g = readText("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 2\n");
  CHECK(g.graph3d.poses[g.graph3d.index(0)].q.w() == 1.0);
}

TEST_CASE("Pose graphs: writers refuse non-finite values and unwritable paths",
          "[datasets][graph]") {
  Graph2D g;
  g.addNode(0, Eigen::Vector3d(0, std::nan(""), 0));
  const auto dir = tessera::test::scratchDir("pose_graph_write_errors");
  CHECK_THROWS_AS(writeG2o(g, dir / "x.g2o"), DatasetError);
  g.poses[0] = Eigen::Vector3d::Zero();
  CHECK_THROWS_AS(writeToro(g, dir / "missing" / "x.graph"), DatasetError);
}

TEST_CASE("Pose graphs: thousands of random mutations either parse or throw DatasetError",
          "[datasets][graph][fuzz]") {
  // Samples: about 200 lines of real files, vertices 0..99 and the edges between them, so that
  // an unmutated sample parses.
  struct Source {
    const char* file;
    std::size_t lines;
  };
  const Source sources[] = {{"posegraph-g2o/intel.g2o", 100},
                            {"posegraph-g2o/manhattan.g2o", 200},
                            {"posegraph-g2o/sphere2500.g2o", 100},
                            {"posegraph-toro/M3500_P_toro.graph", 100}};
  tessera::test::Mutator mutator(20240517);
  for (const auto& s : sources) {
    TESSERA_SHARED_DATA(path, s.file);
    std::string sample;
    std::size_t taken = 0;
    for (const auto& line : readLines(path)) {
      std::istringstream in(line);
      std::string tag;
      long a = 0, b = 0;
      in >> tag >> a >> b;
      const bool vertex = tag.rfind("VERTEX", 0) == 0;
      if ((vertex && a < static_cast<long>(s.lines)) ||
          (!vertex && a < static_cast<long>(s.lines) && b < static_cast<long>(s.lines))) {
        sample += line + "\n";
        if (++taken == 2 * s.lines) break;
      }
    }
    REQUIRE_NOTHROW(readText(sample));
    std::size_t ok = 0, rejected = 0;
    for (int i = 0; i < 2500; ++i) {
      const std::string text = mutator.mutate(sample);
      try {
        readText(text);
        ++ok;
      } catch (const DatasetError&) {
        ++rejected;
      } catch (const std::exception& e) {
        FAIL(s.file << ": mutation " << i << " threw a non-DatasetError: " << e.what());
      }
    }
    INFO(s.file << ": " << ok << " parsed, " << rejected << " rejected");
    CHECK(ok > 0);
    CHECK(rejected > 0);
  }
}
