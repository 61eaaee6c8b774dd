// Pose-graph files through the solvers (graph_optimize.hpp): the graph a file reads into is the
// graph the solvers change and the writer writes.
#include "graph_optimize.hpp"

#include <tessera/runtime/options.hpp>

#include <cmath>

namespace tessera::app {

namespace pg = tessera::pose_graph;

namespace {

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
template <class G>
void startFrom(G& graph, const G& other, const std::string& path) {
  for (int i = 0; i < graph.size(); ++i) {
    if (!other.contains(graph.ids[i]))
      throw ConfigError("--init-poses: " + path + " has no vertex " + std::to_string(graph.ids[i]));
    graph.poses[i] = other.poses[other.index(graph.ids[i])];
  }
}

void startFrom(pg::Graph2D& graph, const std::string& path) {
  startFrom(graph, pg::readPoseGraph2D(path), path);
}

void startFrom(pg::Graph3D& graph, const std::string& path) {
  startFrom(graph, pg::readPoseGraph3D(path), path);
}

/// Optionally re-initialises, optimises and (if asked) writes one graph.
template <class Graph>
nlohmann::json optimizeGraph(Graph graph, const OptimizeOptions& o,
                             const pg::OptimizerOptions& options) {
  // Edges between consecutive nodes are odometry; the others are loop closures, which get the
  // robust loss when one is asked for.
  for (auto& e : graph.edges) e.robust = std::abs(e.from - e.to) != 1;
  if (o.init == "odometry") pg::initializeFromOdometry(graph);
  if (!o.init_poses.empty()) startFrom(graph, o.init_poses);
  const auto summary = pg::optimize(graph, options);
  if (!o.out.empty()) pg::writeG2o(graph, o.out);
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
