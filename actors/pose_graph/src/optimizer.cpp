#include <tessera/pose_graph/optimizer.hpp>

#include "solvers.hpp"

#include <chrono>
#include <stdexcept>

namespace tessera::pose_graph {

Solver parseSolver(std::string_view name) {
  if (name == "sgd") return Solver::kSgd;
  if (name == "ceres") return Solver::kCeres;
  if (name == "sgd+ceres") return Solver::kSgdCeres;
  throw std::invalid_argument("unknown solver '" + std::string(name) +
                              "' (expected sgd, ceres or sgd+ceres)");
}

std::string solverName(Solver solver) {
  switch (solver) {
    case Solver::kSgd:
      return "sgd";
    case Solver::kCeres:
      return "ceres";
    case Solver::kSgdCeres:
      return "sgd+ceres";
  }
  return "?";
}

CeresOptions::Method parseMethod(std::string_view name) {
  if (name == "lm") return CeresOptions::Method::kLevenbergMarquardt;
  if (name == "dogleg") return CeresOptions::Method::kDogleg;
  if (name == "gn") return CeresOptions::Method::kGaussNewton;
  throw std::invalid_argument("unknown method '" + std::string(name) +
                              "' (expected lm, dogleg or gn)");
}

namespace {

template <class G>
OptimizerSummary optimizeGraph(G& graph, const OptimizerOptions& options) {
  validate(graph);
  if (graph.size() == 0) throw GraphError("pose graph: nothing to optimise (no nodes)");
  OptimizerSummary summary;
  summary.solver = options.solver;
  summary.initial_chi2 = chi2(graph);
  summary.sgd_chi2 = summary.initial_chi2;
  const auto start = std::chrono::steady_clock::now();
  detail::StageResult last;
  if (options.solver != Solver::kCeres) {
    last = detail::runSgd(graph, options.sgd);
    summary.sgd_iterations = last.iterations;
    summary.sgd_chi2 = chi2(graph);
  }
  if (options.solver != Solver::kSgd) {
    last = detail::runCeres(graph, options.ceres);
    summary.ceres_iterations = last.iterations;
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.iterations = summary.sgd_iterations + summary.ceres_iterations;
  summary.converged = last.converged;
  summary.message = last.message;
  summary.final_chi2 = chi2(graph);
  return summary;
}

}  // namespace

OptimizerSummary optimize(Graph2D& graph, const OptimizerOptions& options) {
  return optimizeGraph(graph, options);
}

OptimizerSummary optimize(Graph3D& graph, const OptimizerOptions& options) {
  return optimizeGraph(graph, options);
}

}  // namespace tessera::pose_graph
