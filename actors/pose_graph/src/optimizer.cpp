#include <tessera/pose_graph/optimizer.hpp>

#include "solvers.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>

namespace tessera::pose_graph {

namespace {

/// The value `name` names in E's optionNames table; throws std::invalid_argument listing them.
template <class E>
E parseName(std::string_view name, const char* what) {
  std::string choices;
  for (const auto& [n, v] : optionNames(E{})) {
    if (name == n) return v;
    choices += (choices.empty() ? "" : " | ") + std::string(n);
  }
  throw std::invalid_argument("unknown " + std::string(what) + " '" + std::string(name) +
                              "' (expected " + choices + ")");
}

}  // namespace

Solver parseSolver(std::string_view name) {
  return parseName<Solver>(name, "solver");
}

std::string solverName(Solver solver) {
  for (const auto& [n, v] : optionNames(solver))
    if (v == solver) return n;
  return "?";
}

CeresOptions::Method parseMethod(std::string_view name) {
  return parseName<CeresOptions::Method>(name, "method");
}

std::string optionsError(const OptimizerOptions& o) {
  const auto nonNegative = [](double v) { return std::isfinite(v) && v >= 0; };
  if (o.sgd.iterations < 0) return "sgd.iterations must be >= 0";
  if (!nonNegative(o.sgd.relative_decrease)) return "sgd.relative_decrease must be >= 0";
  if (o.ceres.max_iterations < 1) return "ceres.max_iterations must be >= 1";
  if (!(std::isfinite(o.ceres.initial_trust_region) && o.ceres.initial_trust_region > 0))
    return "ceres.initial_trust_region must be > 0";
  if (!nonNegative(o.ceres.huber_delta)) return "ceres.huber_delta must be >= 0";
  const std::pair<const char*, double> tolerances[] = {
      {"function_tolerance", o.ceres.function_tolerance},
      {"gradient_tolerance", o.ceres.gradient_tolerance},
      {"parameter_tolerance", o.ceres.parameter_tolerance}};
  for (const auto& [key, value] : tolerances)
    if (!nonNegative(value)) return "ceres." + std::string(key) + " must be >= 0";
  if (o.ceres.threads < 1) return "ceres.threads must be >= 1";
  return "";
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
