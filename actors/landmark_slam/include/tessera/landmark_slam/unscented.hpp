// Unscented transform (Julier & Uhlmann; scaled form of van der Merwe): propagates a Gaussian
// (mean, covariance) through a nonlinear function with 2n + 1 sigma points, and returns the
// output mean, covariance and the input-output cross-covariance (what a UKF needs for its gain).
//
// Angular outputs: indices listed in `angles_out` are angles [rad]; they are averaged as offsets
// from the central sigma point's output and their deviations are wrapped to (-pi, pi], so a
// mean near ±pi is not torn apart. Returned angular means are wrapped. Input angles need no
// care: sigma points are spread from the input mean and f sees them unwrapped.
//
// Defaults alpha = 1, beta = 2, kappa = 0 (lambda = 0: the central point carries no mean
// weight; spread sqrt(n) sigma). Small alphas make the central weight hugely negative and the
// covariance lose positive definiteness in double precision for these small state sizes.
// Dynamic-size Eigen; each call allocates.
#pragma once

#include <Eigen/Core>

#include <functional>
#include <vector>

namespace tessera::landmark_slam {

struct UnscentedParams {
  double alpha = 1.0;  ///< spread of the sigma points, (0, 1]
  double beta = 2.0;   ///< prior knowledge of the distribution (2 = Gaussian)
  double kappa = 0.0;  ///< secondary scaling

  template <class V>
  void visit(V& v) {
    v("alpha", alpha, "spread of the sigma points, (0, 1]");
    v("beta", beta, "prior knowledge of the distribution (2 = Gaussian)");
    v("kappa", kappa, "secondary scaling (> -3)");
  }
};

struct UnscentedResult {
  Eigen::VectorXd mean;
  Eigen::MatrixXd covariance;
  Eigen::MatrixXd cross;  ///< sum w_c (X_i - mean_in)(Y_i - mean)^T, n_in x n_out
};

/// Transforms (mean, cov) by f. Throws std::invalid_argument when cov is not symmetric
/// positive semi-definite up to rounding (checked through an LDLT factorisation), or sizes
/// disagree.
UnscentedResult unscentedTransform(const Eigen::VectorXd& mean, const Eigen::MatrixXd& cov,
                                   const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                   const std::vector<int>& angles_out = {},
                                   const UnscentedParams& params = {});

}  // namespace tessera::landmark_slam
