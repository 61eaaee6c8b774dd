// Optimising one pose-graph file (g2o or TORO, SE(2) or SE(3)) the way `tessera graph optimize`
// does: shared by that command and by `tessera bench graph`, so both run the same code.
#pragma once

#include <tessera/pose_graph/optimizer.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>

#include <nlohmann/json.hpp>

#include <string>

namespace tessera::app {

/// What `tessera graph optimize` was asked to do (`bench graph` sets the solver fields).
struct OptimizeOptions {
  std::string input;
  std::string solver = "sgd+ceres";
  std::string init = "file";
  std::string out;
  std::string init_poses;  // a g2o/TORO file whose vertices give the start (same ids)
  int sgd_iterations = pose_graph::SgdOptions{}.iterations;
  int ceres_iterations = pose_graph::CeresOptions{}.max_iterations;
  double huber = 0.0;
  std::string method = "lm";
  bool json = false;
};

/// The solver settings `o` names; throws std::invalid_argument for an unknown solver or method.
pose_graph::OptimizerOptions solverOptions(const OptimizeOptions& o);

/// Optionally re-initialises (o.init, o.init_poses), optimises and (if o.out is set) writes the
/// graph of `file`; returns what the solver did (nodes, edges, chi2 before and after, iterations,
/// seconds, solver, converged, message).
nlohmann::json optimizeFile(const pose_graph::PoseGraphFile& file, const OptimizeOptions& o,
                            const pose_graph::OptimizerOptions& options);

}  // namespace tessera::app
