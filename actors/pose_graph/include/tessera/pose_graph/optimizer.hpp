// Pose-graph optimisation: minimises the g2o objective χ² = Σ eᵀ Ω e of pose_graph.hpp.
//
// Three solvers behind one call:
//  * kSgd      — stochastic gradient descent on the incremental parameterisation (Olson, Leonard,
//                Teller, ICRA 2006; docs/algorithms.md#sgd-on-the-incremental-parameterisation):
//                constraint by constraint, the residual is spread over the nodes between its ends
//                with a per-node preconditioner and a Robbins–Monro learning rate. Cheap per pass
//                and hard to trap in the local minima a bad initial estimate leads Gauss-Newton
//                into; slow to finish.
//  * kCeres    — Levenberg-Marquardt (or dogleg) in Ceres with sparse Cholesky (SuiteSparse),
//                or undamped Gauss-Newton on Ceres' Jacobians (sparse LDLT), whitening each
//                error with the full information matrix; an optional Huber loss on edges
//                marked `robust` (loop closures).
//  * kSgdCeres — SGD to get into the basin, then Ceres to finish.
// SE(3) graphs: SGD moves translations only (like SE(2) positions); rotations are left to Ceres.
// Node 0 anchors the gauge in every solver; Ceres also keeps nodes marked `fixed` in place.
// The graph's poses are changed in place; edges never are. Thread-safety: one call per graph.
#pragma once

#include <tessera/pose_graph/pose_graph.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

namespace tessera::pose_graph {

enum class Solver { kSgd, kCeres, kSgdCeres };
/// The solvers' names, for option files (found by argument-dependent lookup) and the CLI.
constexpr std::array<std::pair<const char*, Solver>, 3> optionNames(Solver) {
  return {{{"sgd", Solver::kSgd}, {"ceres", Solver::kCeres}, {"sgd+ceres", Solver::kSgdCeres}}};
}
/// A name of optionNames(Solver); throws std::invalid_argument naming the accepted values.
Solver parseSolver(std::string_view name);
std::string solverName(Solver solver);

struct SgdOptions {
  /// Passes over all constraints; each costs O(edges × nodes an edge spans). SGD drops χ²
  /// by orders of magnitude in the first passes and then hovers (every pass satisfies long
  /// loops in turn), so a few passes are enough to hand a good start to Ceres; on the shared
  /// graphs 5–30 passes all led Ceres to the same optimum.
  int iterations = 10;
  /// Stop early when a pass lowers χ² by less than this fraction (0 = always run all passes).
  double relative_decrease = 0.0;
  /// Seeds the constraint order, shuffled every pass as the paper does; runs are reproducible.
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("iterations", iterations, "passes over all constraints");
    v("relative_decrease", relative_decrease,
      "stop early when a pass lowers chi2 by less than this fraction; 0 = run every pass");
    v("seed", seed, "seeds the constraint order shuffled every pass (runs are reproducible)");
  }
};

struct CeresOptions {
  /// Badly started graphs take hundreds of small steps (Intel TORO: ~250), good starts < 10.
  int max_iterations = 500;
  /// kLevenbergMarquardt and kDogleg are Ceres' trust-region solvers (a step that raises the
  /// cost is refused). kGaussNewton takes every step undamped, as g2o's Gauss-Newton does:
  /// faster from a very poor start (TORO Intel: 215.83 in tens of iterations where LM creeps
  /// for hundreds), but it can diverge where a trust region would not.
  enum class Method { kLevenbergMarquardt, kDogleg, kGaussNewton };
  Method method = Method::kLevenbergMarquardt;
  /// First trust-region radius. Large, so the first steps are (nearly) Gauss-Newton steps:
  /// Ceres' default 1e4 took 27 LM iterations on M3500 where this takes 7.
  double initial_trust_region = 1e8;
  /// Huber loss scale on edges marked robust, in whitened units (√χ² of one edge). 0 = off:
  /// the solver then minimises exactly the g2o objective.
  double huber_delta = 0.0;
  /// Convergence: relative cost change, gradient max-norm and relative step size.
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  int threads = 1;

  template <class V>
  void visit(V& v) {
    v("max_iterations", max_iterations, "iterations (at most)");
    v("method", method,
      "lm (Levenberg-Marquardt), dogleg: trust region; gn: undamped Gauss-Newton, faster from a "
      "poor start but it can diverge");
    v("initial_trust_region", initial_trust_region, "first trust-region radius (lm, dogleg)");
    v("huber_delta", huber_delta,
      "Huber scale on robust (loop-closure) edges, whitened units; 0 = plain least squares");
    v("function_tolerance", function_tolerance, "converged: relative cost change below this");
    v("gradient_tolerance", gradient_tolerance, "converged: gradient max-norm below this");
    v("parameter_tolerance", parameter_tolerance, "converged: relative step size below this");
    v("threads", threads, "Ceres threads");
  }
};

/// The methods' names, for option files (found by argument-dependent lookup) and the CLI.
constexpr std::array<std::pair<const char*, CeresOptions::Method>, 3> optionNames(
    CeresOptions::Method) {
  return {{{"lm", CeresOptions::Method::kLevenbergMarquardt},
           {"dogleg", CeresOptions::Method::kDogleg},
           {"gn", CeresOptions::Method::kGaussNewton}}};
}
/// A name of optionNames(CeresOptions::Method); throws std::invalid_argument naming the accepted
/// values.
CeresOptions::Method parseMethod(std::string_view name);

struct OptimizerOptions {
  Solver solver = Solver::kSgdCeres;
  SgdOptions sgd;
  CeresOptions ceres;

  template <class V>
  void visit(V& v) {
    v("solver", solver,
      "sgd: SGD alone; ceres: Ceres alone; sgd+ceres: SGD to get into the basin, Ceres to finish");
    v("sgd", sgd, "the SGD stage");
    v("ceres", ceres, "the Ceres stage");
  }
};

/// "" when `options` can be used, else what is wrong, naming the key inside OptimizerOptions
/// (e.g. "ceres.max_iterations must be >= 1").
std::string optionsError(const OptimizerOptions& options);

struct OptimizerSummary {
  Solver solver = Solver::kSgdCeres;
  double initial_chi2 = 0.0;
  double sgd_chi2 = 0.0;    ///< after the SGD stage (when there is one)
  double final_chi2 = 0.0;  ///< with the robust loss off: the plain g2o objective
  int sgd_iterations = 0;
  int ceres_iterations = 0;
  int iterations = 0;    ///< sgd_iterations + ceres_iterations
  double seconds = 0.0;  ///< optimisation only (wall clock)
  bool converged = false;
  std::string message;  ///< the last stage's own words (e.g. Ceres' termination message)
};

/// Optimises in place. Throws GraphError for an empty or invalid graph (see validate()).
OptimizerSummary optimize(Graph2D& graph, const OptimizerOptions& options = {});
OptimizerSummary optimize(Graph3D& graph, const OptimizerOptions& options = {});

}  // namespace tessera::pose_graph
