// Ceres stage: the g2o objective as Ceres residuals r = L eᵀ with Ω = Lᵀ L (full information,
// not only its diagonal), so χ² = 2 × Ceres' cost.
#include "solvers.hpp"

#include <tessera/geometry/pose2.hpp>

#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCore>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace tessera::pose_graph::detail {
namespace {

// normalizeAngle() (base/geometry) for Ceres' Jet types: the residual is differentiated through
// it, so it has to be written in operations Ceres overloads (floor on a Jet keeps the derivative).
template <class T>
T wrapAngle(const T& a) {
  const T two_pi = T(2.0 * M_PI);
  return a - two_pi * ceres::floor((a + T(M_PI)) / two_pi);
}

template <int D>
Eigen::Matrix<double, D, D> sqrtInformation(const Eigen::Matrix<double, D, D>& omega) {
  // Ω = V Λ Vᵀ → L = Λ^½ Vᵀ. Unlike a Cholesky factor this also takes the singular PSD
  // matrices some files hold (e.g. a zero rotation weight).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, D, D>> eig(omega);
  return eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal() * eig.eigenvectors().transpose();
}

struct Se2Residual {
  Eigen::Vector3d z;
  Eigen::Matrix3d sqrt_info;

  template <class T>
  bool operator()(const T* a, const T* b, T* out) const {
    const T ca = ceres::cos(a[2]), sa = ceres::sin(a[2]);
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    // X_a⁻¹ X_b, then Z⁻¹ (·).
    const T lx = ca * dx + sa * dy, ly = -sa * dx + ca * dy;
    const double cz = std::cos(z[2]), sz = std::sin(z[2]);
    Eigen::Matrix<T, 3, 1> e;
    e[0] = cz * (lx - z[0]) + sz * (ly - z[1]);
    e[1] = -sz * (lx - z[0]) + cz * (ly - z[1]);
    e[2] = wrapAngle(b[2] - a[2] - T(z[2]));
    Eigen::Map<Eigen::Matrix<T, 3, 1>> residual(out);
    residual = sqrt_info.cast<T>() * e;
    return true;
  }
};

struct Se3Residual {
  Pose3 z_inverse;
  Eigen::Matrix<double, 6, 6> sqrt_info;

  template <class T>
  bool operator()(const T* ta, const T* qa, const T* tb, const T* qb, T* out) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> pa(ta), pb(tb);
    const Eigen::Map<const Eigen::Quaternion<T>> ra(qa), rb(qb);
    const Eigen::Quaternion<T> ra_inv = ra.conjugate();
    const Eigen::Quaternion<T> zq = z_inverse.q.cast<T>();
    // Z⁻¹ (X_a⁻¹ X_b)
    const Eigen::Matrix<T, 3, 1> t_ab = ra_inv * (pb - pa);
    const Eigen::Quaternion<T> q_ab = ra_inv * rb;
    const Eigen::Matrix<T, 3, 1> t = zq * t_ab + z_inverse.t.cast<T>();
    Eigen::Quaternion<T> q = zq * q_ab;
    // Unit quaternions from the manifold stay unit up to rounding; normalise as g2o does.
    q.normalize();
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = t;
    if (q.w() < T(0)) {
      e.template tail<3>() = -q.vec();
    } else {
      e.template tail<3>() = q.vec();
    }
    Eigen::Map<Eigen::Matrix<T, 6, 1>> residual(out);
    residual = sqrt_info.cast<T>() * e;
    return true;
  }
};

ceres::Solver::Options solverOptions(const CeresOptions& options) {
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  o.trust_region_strategy_type =
      options.method == CeresOptions::Method::kDogleg ? ceres::DOGLEG : ceres::LEVENBERG_MARQUARDT;
  o.max_num_iterations = options.max_iterations;
  o.initial_trust_region_radius = options.initial_trust_region;
  o.function_tolerance = options.function_tolerance;
  o.gradient_tolerance = options.gradient_tolerance;
  o.parameter_tolerance = options.parameter_tolerance;
  o.num_threads = options.threads;
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  return o;
}

ceres::LossFunction* lossFor(bool robust, const CeresOptions& options) {
  if (!robust || options.huber_delta <= 0.0) return nullptr;
  return new ceres::HuberLoss(options.huber_delta);
}

/// Undamped Gauss-Newton as g2o runs it: every step is taken, whatever it does to the cost.
/// Ceres evaluates residuals and Jacobians (in the manifolds' tangent spaces); the normal
/// equations are solved by CHOLMOD.
StageResult gaussNewton(ceres::Problem& problem, const CeresOptions& options) {
  std::vector<double*> all, blocks;
  problem.GetParameterBlocks(&all);
  for (double* b : all)
    if (!problem.IsParameterBlockConstant(b)) blocks.push_back(b);
  ceres::Problem::EvaluateOptions eval;
  eval.parameter_blocks = blocks;
  StageResult result;
  double cost = 0.0;
  problem.Evaluate(eval, &cost, nullptr, nullptr, nullptr);
  // CHOLMOD's supernodal Cholesky (SuiteSparse, as Ceres uses): 1.7x faster than Eigen's
  // simplicial LDLT on sphere2500.
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> ldlt;
  bool analysed = false;
  std::vector<double> residuals;
  ceres::CRSMatrix crs;
  for (int it = 0; it < options.max_iterations; ++it) {
    problem.Evaluate(eval, nullptr, &residuals, nullptr, &crs);
    const Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> jacobian(
        crs.num_rows, crs.num_cols, static_cast<Eigen::Index>(crs.values.size()), crs.rows.data(),
        crs.cols.data(), crs.values.data());
    const Eigen::Map<const Eigen::VectorXd> r(residuals.data(),
                                              static_cast<Eigen::Index>(residuals.size()));
    const Eigen::SparseMatrix<double> h = jacobian.transpose() * jacobian;
    const Eigen::VectorXd g = jacobian.transpose() * r;
    if (!analysed) {
      ldlt.analyzePattern(h);
      analysed = true;
    }
    ldlt.factorize(h);
    if (ldlt.info() != Eigen::Success)
      throw GraphError(
          "pose graph: Gauss-Newton: the normal equations are singular (is a part "
          "of the graph unconnected to the fixed nodes?)");
    const Eigen::VectorXd step = ldlt.solve(-g);
    int offset = 0;
    double largest_step = 0.0, largest_value = 0.0;
    for (double* b : blocks) {
      const int tangent = problem.ParameterBlockTangentSize(b);
      const int size = problem.ParameterBlockSize(b);
      const ceres::Manifold* manifold = problem.GetManifold(b);
      std::vector<double> moved(static_cast<std::size_t>(size));
      if (manifold != nullptr) {
        manifold->Plus(b, step.data() + offset, moved.data());
      } else {
        for (int k = 0; k < size; ++k) moved[k] = b[k] + step[offset + k];
      }
      for (int k = 0; k < size; ++k) {
        largest_value = std::max(largest_value, std::abs(b[k]));
        b[k] = moved[k];
      }
      offset += tangent;
    }
    largest_step = step.cwiseAbs().maxCoeff();
    double new_cost = 0.0;
    problem.Evaluate(eval, &new_cost, nullptr, nullptr, nullptr);
    result.iterations = it + 1;
    const bool small_change = std::abs(cost - new_cost) <= options.function_tolerance * cost;
    const bool small_step =
        largest_step <= options.parameter_tolerance * (largest_value + options.parameter_tolerance);
    cost = new_cost;
    if (!std::isfinite(cost)) throw GraphError("pose graph: Gauss-Newton diverged");
    if (small_change || small_step) {
      result.converged = true;
      break;
    }
  }
  result.message = std::string("Gauss-Newton: ") +
                   (result.converged ? "converged" : "iteration limit") + " after " +
                   std::to_string(result.iterations) + " iterations";
  return result;
}

StageResult solve(ceres::Problem& problem, const CeresOptions& options) {
  if (options.method == CeresOptions::Method::kGaussNewton) return gaussNewton(problem, options);
  ceres::Solver::Summary summary;
  ceres::Solve(solverOptions(options), &problem, &summary);
  StageResult result;
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;  // [0] is the start
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.message = "Ceres: " + summary.message;
  if (summary.termination_type == ceres::FAILURE)
    throw GraphError("pose graph: Ceres failed: " + summary.message);
  return result;
}

}  // namespace

StageResult runCeres(Graph2D& graph, const CeresOptions& options) {
  ceres::Problem problem;
  for (const auto& e : graph.edges) {
    auto* cost = new ceres::AutoDiffCostFunction<Se2Residual, 3, 3, 3>(
        new Se2Residual{e.measurement, sqrtInformation<3>(e.information)});
    problem.AddResidualBlock(cost, lossFor(e.robust, options), graph.poses[e.from].data(),
                             graph.poses[e.to].data());
  }
  for (int i = 0; i < graph.size(); ++i)
    if ((i == 0 || graph.fixed[i]) && problem.HasParameterBlock(graph.poses[i].data()))
      problem.SetParameterBlockConstant(graph.poses[i].data());
  StageResult result = solve(problem, options);
  for (auto& p : graph.poses) p.z() = normalizeAngle(p.z());
  return result;
}

StageResult runCeres(Graph3D& graph, const CeresOptions& options) {
  ceres::Problem problem;
  for (const auto& e : graph.edges) {
    auto* cost = new ceres::AutoDiffCostFunction<Se3Residual, 6, 3, 4, 3, 4>(
        new Se3Residual{e.measurement.inverse(), sqrtInformation<6>(e.information)});
    problem.AddResidualBlock(cost, lossFor(e.robust, options), graph.poses[e.from].t.data(),
                             graph.poses[e.from].q.coeffs().data(), graph.poses[e.to].t.data(),
                             graph.poses[e.to].q.coeffs().data());
  }
  for (int i = 0; i < graph.size(); ++i) {
    double* q = graph.poses[i].q.coeffs().data();
    if (!problem.HasParameterBlock(q)) continue;
    problem.SetManifold(q, new ceres::EigenQuaternionManifold);
    if (i == 0 || graph.fixed[i]) {
      problem.SetParameterBlockConstant(graph.poses[i].t.data());
      problem.SetParameterBlockConstant(q);
    }
  }
  StageResult result = solve(problem, options);
  for (auto& p : graph.poses) p.q.normalize();
  return result;
}

}  // namespace tessera::pose_graph::detail
