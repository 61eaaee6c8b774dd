// Pose-graph files through the solvers (graph_optimize.hpp): file graphs (vertex ids) to solver
// graphs (dense indices in increasing id order) and back.
#include "graph_optimize.hpp"

#include <tessera/runtime/options.hpp>

#include <cmath>

namespace tessera::app {

namespace pg = tessera::pose_graph;

namespace {

// --- file graphs <-> solver graphs (dense indices in increasing id order) --------------------

pg::Graph2D toSolverGraph(const pg::PoseGraph2D& in) {
  pg::Graph2D g;
  for (const auto& [id, pose] : in.vertices) g.addNode(id, pose);
  for (auto id : in.fixed) g.fixed[g.index(id)] = true;
  for (const auto& e : in.edges) {
    const int a = g.index(e.from), b = g.index(e.to);
    g.edges.push_back({a, b, e.measurement, e.information, std::abs(a - b) != 1});
  }
  return g;
}

pg::Graph3D toSolverGraph(const pg::PoseGraph3D& in) {
  pg::Graph3D g;
  for (const auto& [id, pose] : in.vertices) g.addNode(id, pose);
  for (auto id : in.fixed) g.fixed[g.index(id)] = true;
  for (const auto& e : in.edges) {
    const int a = g.index(e.from), b = g.index(e.to);
    g.edges.push_back({a, b, e.measurement, e.information, std::abs(a - b) != 1});
  }
  return g;
}

void copyPoses(const pg::Graph2D& g, pg::PoseGraph2D& out) {
  for (int i = 0; i < g.size(); ++i) out.vertices[g.ids[i]] = g.poses[i];
}

void copyPoses(const pg::Graph3D& g, pg::PoseGraph3D& out) {
  for (int i = 0; i < g.size(); ++i) out.vertices[g.ids[i]] = g.poses[i];
}

nlohmann::json summaryJson(const pg::OptimizerSummary& s, int nodes, std::size_t edges) {
  return {{"nodes", nodes},
          {"edges", edges},
          {"initial_chi2", s.initial_chi2},
          {"final_chi2", s.final_chi2},
          {"iterations", s.iterations},
          {"sgd_iterations", s.sgd_iterations},
          {"ceres_iterations", s.ceres_iterations},
          {"seconds", s.seconds},
          {"solver", pg::solverName(s.solver)},
          {"converged", s.converged},
          {"message", s.message}};
}

/// Takes the start poses from another file's vertices (e.g. an earlier solution); every node of
/// the graph must be there.
void startFrom(pg::Graph2D& graph, const std::string& path) {
  const auto other = pg::readPoseGraph2D(path);
  for (int i = 0; i < graph.size(); ++i) {
    const auto it = other.vertices.find(graph.ids[i]);
    if (it == other.vertices.end())
      throw ConfigError("--init-poses: " + path + " has no vertex " + std::to_string(graph.ids[i]));
    graph.poses[i] = it->second;
  }
}

void startFrom(pg::Graph3D& graph, const std::string& path) {
  const auto other = pg::readPoseGraph3D(path);
  for (int i = 0; i < graph.size(); ++i) {
    const auto it = other.vertices.find(graph.ids[i]);
    if (it == other.vertices.end())
      throw ConfigError("--init-poses: " + path + " has no vertex " + std::to_string(graph.ids[i]));
    graph.poses[i] = it->second;
  }
}

/// Reads, optionally re-initialises, optimises and (if asked) writes one graph.
template <class FileGraph>
nlohmann::json optimizeGraph(FileGraph file_graph, const OptimizeOptions& o,
                             const pg::OptimizerOptions& options) {
  auto graph = toSolverGraph(file_graph);
  if (o.init == "odometry") pg::initializeFromOdometry(graph);
  if (!o.init_poses.empty()) startFrom(graph, o.init_poses);
  const auto summary = pg::optimize(graph, options);
  if (!o.out.empty()) {
    copyPoses(graph, file_graph);
    pg::writeG2o(file_graph, o.out);
  }
  return summaryJson(summary, graph.size(), graph.edges.size());
}

}  // namespace

pg::OptimizerOptions solverOptions(const OptimizeOptions& o) {
  pg::OptimizerOptions options;
  options.solver = pg::parseSolver(o.solver);
  options.sgd.iterations = o.sgd_iterations;
  options.ceres.max_iterations = o.ceres_iterations;
  options.ceres.huber_delta = o.huber;
  options.ceres.method = pg::parseMethod(o.method);
  return options;
}

nlohmann::json optimizeFile(const pg::PoseGraphFile& file, const OptimizeOptions& o,
                            const pg::OptimizerOptions& options) {
  return file.dimension == 2 ? optimizeGraph(file.graph2d, o, options)
                             : optimizeGraph(file.graph3d, o, options);
}

}  // namespace tessera::app
