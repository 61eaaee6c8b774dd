#include <tessera/landmark_slam/unscented.hpp>

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Cholesky>

#include <cmath>
#include <stdexcept>

namespace tessera::landmark_slam {
namespace {

// A square root L with L L^T = cov. LLT first; a semi-definite cov (e.g. an exactly known
// component) goes through LDLT with its pivoting.
Eigen::MatrixXd squareRoot(const Eigen::MatrixXd& cov) {
  const Eigen::LLT<Eigen::MatrixXd> llt(cov);
  if (llt.info() == Eigen::Success) return llt.matrixL();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(cov);
  const Eigen::VectorXd d = ldlt.vectorD();
  const double tol = 1e-12 * std::max(1.0, cov.diagonal().cwiseAbs().maxCoeff());
  if (ldlt.info() != Eigen::Success || (d.array() < -tol).any())
    throw std::invalid_argument("unscentedTransform: covariance is not positive semi-definite");
  const Eigen::MatrixXd L = ldlt.matrixL();
  const Eigen::MatrixXd LD = L * d.cwiseMax(0.0).cwiseSqrt().asDiagonal();
  return ldlt.transpositionsP().transpose() * LD;
}

}  // namespace

UnscentedResult unscentedTransform(const Eigen::VectorXd& mean, const Eigen::MatrixXd& cov,
                                   const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                   const std::vector<int>& angles_out,
                                   const UnscentedParams& params) {
  const auto n = mean.size();
  if (cov.rows() != n || cov.cols() != n || n == 0)
    throw std::invalid_argument("unscentedTransform: covariance size does not match the mean");
  if (!(params.alpha > 0) || !std::isfinite(params.beta) || !(n + params.kappa > 0))
    throw std::invalid_argument("unscentedTransform: need alpha > 0 and n + kappa > 0");
  if (!cov.isApprox(cov.transpose(), 1e-9) && !(cov - cov.transpose()).isZero(1e-12))
    throw std::invalid_argument("unscentedTransform: covariance is not symmetric");

  const double nd = static_cast<double>(n);
  const double lambda = params.alpha * params.alpha * (nd + params.kappa) - nd;
  const Eigen::MatrixXd L = std::sqrt(nd + lambda) * squareRoot(cov);
  const double w0m = lambda / (nd + lambda);
  const double w0c = w0m + 1.0 - params.alpha * params.alpha + params.beta;
  const double wi = 0.5 / (nd + lambda);

  const auto count = 2 * n + 1;
  Eigen::MatrixXd X(n, count);
  X.col(0) = mean;
  for (Eigen::Index i = 0; i < n; ++i) {
    X.col(1 + i) = mean + L.col(i);
    X.col(1 + n + i) = mean - L.col(i);
  }
  const Eigen::VectorXd y0 = f(X.col(0));
  const auto m = y0.size();
  Eigen::MatrixXd Y(m, count);
  Y.col(0) = y0;
  for (Eigen::Index i = 1; i < count; ++i) {
    Y.col(i) = f(X.col(i));
    if (Y.col(i).size() != m)
      throw std::invalid_argument("unscentedTransform: f returned vectors of different sizes");
  }
  // Angles: offsets from the central output, wrapped, so the average is taken on the circle.
  for (int a : angles_out)
    for (Eigen::Index i = 1; i < count; ++i) Y(a, i) = y0[a] + angleDiff(Y(a, i), y0[a]);

  UnscentedResult r;
  r.mean = w0m * Y.col(0);
  for (Eigen::Index i = 1; i < count; ++i) r.mean += wi * Y.col(i);
  Eigen::MatrixXd dY = Y.colwise() - r.mean;
  const Eigen::MatrixXd dX = X.colwise() - mean;
  r.covariance = w0c * dY.col(0) * dY.col(0).transpose();
  r.cross = w0c * dX.col(0) * dY.col(0).transpose();
  for (Eigen::Index i = 1; i < count; ++i) {
    r.covariance += wi * dY.col(i) * dY.col(i).transpose();
    r.cross += wi * dX.col(i) * dY.col(i).transpose();
  }
  for (int a : angles_out) r.mean[a] = normalizeAngle(r.mean[a]);
  return r;
}

}  // namespace tessera::landmark_slam
