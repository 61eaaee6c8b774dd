// ScanMatcher's non-template parts: option checks, kernel offsets, scan preparation, and the
// proposal and covariance fits from sampled log-likelihoods.
#include "scan_matcher_impl.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::scan_matching {
namespace {

void check(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("ScanMatcher: " + what);
}

bool positive(double v) {
  return std::isfinite(v) && v > 0.0;
}

// Bounds of MatchResult::covariance, as standard deviations in proposal-grid steps.
constexpr double kMaxStdSteps = 100.0;
constexpr double kMinStdSteps = 0.01;
// Eigenvalues of the prior covariance are raised to this, so a zero-noise motion model still
// gives a proper (very narrow) Gaussian.
constexpr double kMinPriorEigenvalue = 1e-12;

}  // namespace

ScanMatcher::ScanMatcher(ScanMatcherOptions o) : options_(o) {
  check(positive(o.max_range), "max_range must be > 0 m");
  check(o.beam_step >= 1, "beam_step must be >= 1");
  check(o.kernel_radius >= 0, "kernel_radius must be >= 0 cells");
  check(positive(o.sigma), "sigma must be > 0 m");
  check(positive(o.likelihood_sigma), "likelihood_sigma must be > 0 m");
  check(positive(o.likelihood_gain), "likelihood_gain must be > 0");
  check(std::isfinite(o.no_hit_distance) && o.no_hit_distance >= 0.0 && o.no_hit_distance < 1e3,
        "no_hit_distance must be in [0, 1000) m");
  check(std::isfinite(o.occupied_threshold), "occupied_threshold must be finite");
  check(!std::isnan(o.free_check_offset) && o.free_check_offset < 1e6,
        "free_check_offset must be a number of metres");
  check(positive(o.linear_step), "linear_step must be > 0 m");
  check(positive(o.angular_step), "angular_step must be > 0 rad");
  check(o.refinements >= 0, "refinements must be >= 0");
  check(o.max_iterations >= 1, "max_iterations must be >= 1");
  check(o.min_score_fraction >= 0.0 && o.min_score_fraction <= 1.0,
        "min_score_fraction must be in [0, 1]");
  check(positive(o.proposal_linear), "proposal_linear must be > 0 m");
  check(positive(o.proposal_angular), "proposal_angular must be > 0 rad");
  // One step per side is the least a quadratic fit and a covariance need; 10 (9261 samples)
  // is far beyond any sensible use and keeps (2s+1)^3 in int range.
  check(o.proposal_steps >= 1 && o.proposal_steps <= 10, "proposal_steps must be in [1, 10]");
  check(positive(o.covariance_linear), "covariance_linear must be > 0 m");
  check(positive(o.covariance_angular), "covariance_angular must be > 0 rad");
  check(o.covariance_steps >= 1 && o.covariance_steps <= 10, "covariance_steps must be in [1, 10]");
  const int r = o.kernel_radius;
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx)
      kernel_.push_back({dx, dy, std::sqrt(static_cast<float>(dx * dx + dy * dy)), 0.0f});
  std::stable_sort(
      kernel_.begin(), kernel_.end(),
      [](const KernelOffset& a, const KernelOffset& b) { return a.distance < b.distance; });
  float floor = std::numeric_limits<float>::infinity();
  for (auto k = kernel_.rbegin(); k != kernel_.rend(); ++k) {
    const float bx = std::max(std::abs(static_cast<float>(k->dx)) - 0.5f, 0.0f);
    const float by = std::max(std::abs(static_cast<float>(k->dy)) - 0.5f, 0.0f);
    floor = std::min(floor, std::sqrt(bx * bx + by * by));
    k->square_floor = floor;
  }
}

ScanPoints ScanMatcher::prepare(const grid::RangeScan& scan, const Pose2& mount) const {
  ScanPoints points;
  points.beams_total = scan.ranges.size();
  points.origin = mount.translation().cast<float>();
  if (!mount.isFinite() || !std::isfinite(scan.angle_min) || !std::isfinite(scan.angle_increment))
    return points;
  points.endpoints.reserve(scan.ranges.size() / static_cast<std::size_t>(options_.beam_step) + 1);
  std::size_t valid = 0;
  for (std::size_t k = 0; k < scan.ranges.size(); ++k) {
    const double r = scan.ranges[k];
    // Written so that NaN ranges or limits reject the beam.
    if (!(r >= scan.range_min) || !(r > 0.0)) continue;
    if (r >= scan.range_max || !(r <= options_.max_range)) continue;  // no return / too far
    if (valid++ % static_cast<std::size_t>(options_.beam_step) != 0) continue;
    const double a = scan.angle_min + static_cast<double>(k) * scan.angle_increment;
    points.endpoints.push_back(
        (mount * Eigen::Vector2d(r * std::cos(a), r * std::sin(a))).cast<float>());
  }
  return points;
}

namespace detail {

Eigen::Vector3i SampleGrid::index(int k) const {
  const int n = 2 * steps + 1;
  return {k / (n * n) - steps, (k / n) % n - steps, k % n - steps};
}

Pose2 SampleGrid::at(const Pose2& centre, int k) const {
  const Eigen::Vector3i i = index(k);
  return {centre.x + i.x() * linear, centre.y + i.y() * linear, centre.theta + i.z() * angular};
}

Eigen::Matrix3d laplaceCovariance(const SampleGrid& g, std::span<const double> ll) {
  // Least-squares fit of f(q) = c + g·q + ½ qᵀHq in sample-grid units q (one step = 1), which
  // keeps the system well conditioned and the eigenvalue bounds unit-free.
  const int n = static_cast<int>(ll.size());
  Eigen::MatrixXd a(n, 10);
  Eigen::VectorXd b(n);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d q = g.index(k).cast<double>();
    a.row(k) << 1.0, q.x(), q.y(), q.z(), 0.5 * q.x() * q.x(), 0.5 * q.y() * q.y(),
        0.5 * q.z() * q.z(), q.x() * q.y(), q.x() * q.z(), q.y() * q.z();
    b(k) = ll[static_cast<std::size_t>(k)];
  }
  const Eigen::VectorXd p = a.colPivHouseholderQr().solve(b);
  Eigen::Matrix3d neg_hessian;
  neg_hessian << p(4), p(7), p(8), p(7), p(5), p(9), p(8), p(9), p(6);
  neg_hessian = -neg_hessian;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(neg_hessian);
  const Eigen::Vector3d lambda = eig.eigenvalues()
                                     .cwiseMax(1.0 / (kMaxStdSteps * kMaxStdSteps))
                                     .cwiseMin(1.0 / (kMinStdSteps * kMinStdSteps));
  const Eigen::Matrix3d cov_steps =
      eig.eigenvectors() * lambda.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  const Eigen::Vector3d scale(g.linear, g.linear, g.angular);
  return scale.asDiagonal() * cov_steps * scale.asDiagonal();
}

ProposalFit fitProposalFromSamples(const ScanMatcherOptions& o, std::span<const double> ll,
                                   const Pose2& mode, const Pose2& prior_mean,
                                   const Eigen::Matrix3d& prior_cov) {
  if (!prior_mean.isFinite() || !prior_cov.allFinite())
    throw std::invalid_argument("ScanMatcher::fitProposal: non-finite prior");
  const Eigen::Matrix3d sym = 0.5 * (prior_cov + prior_cov.transpose());
  if ((sym - prior_cov).cwiseAbs().maxCoeff() > 1e-9 * (1.0 + prior_cov.cwiseAbs().maxCoeff()))
    throw std::invalid_argument("ScanMatcher::fitProposal: prior covariance is not symmetric");
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sym);
  if (eig.eigenvalues().minCoeff() < -1e-9 * (1.0 + eig.eigenvalues().cwiseAbs().maxCoeff()))
    throw std::invalid_argument(
        "ScanMatcher::fitProposal: prior covariance is not positive "
        "semi-definite");
  const Eigen::Vector3d lambda = eig.eigenvalues().cwiseMax(kMinPriorEigenvalue);
  const Eigen::Matrix3d info =
      eig.eigenvectors() * lambda.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  const double log_norm =
      -0.5 * (3.0 * std::log(2.0 * std::numbers::pi) + lambda.array().log().sum());

  // Log-weights, then log-sum-exp relative to the largest so nothing underflows.
  const SampleGrid g = proposalGrid(o);
  const int n = static_cast<int>(ll.size());
  std::vector<double> w(ll.size());
  std::vector<Eigen::Vector3d> offset(ll.size());  // sample − mode, angle exact (no wrap needed)
  double max_log_w = -std::numeric_limits<double>::infinity();
  for (int k = 0; k < n; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    const Eigen::Vector3d step = g.index(k).cast<double>();
    offset[i] = {step.x() * g.linear, step.y() * g.linear, step.z() * g.angular};
    const Pose2 x = g.at(mode, k);
    const Eigen::Vector3d d(x.x - prior_mean.x, x.y - prior_mean.y,
                            angleDiff(x.theta, prior_mean.theta));
    w[i] = ll[i] + log_norm - 0.5 * d.dot(info * d);  // log-weight for now
    max_log_w = std::max(max_log_w, w[i]);
  }
  double sum = 0.0;
  Eigen::Vector3d mean_offset = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < w.size(); ++i) {
    w[i] = std::exp(w[i] - max_log_w);  // the weight scaled into (0, 1]
    sum += w[i];
    mean_offset += w[i] * offset[i];
  }
  mean_offset /= sum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < w.size(); ++i) {
    const Eigen::Vector3d d = offset[i] - mean_offset;
    cov += w[i] * d * d.transpose();
  }
  cov /= sum;
  cov.diagonal() +=
      Eigen::Vector3d(g.linear * g.linear, g.linear * g.linear, g.angular * g.angular) / 12.0;

  ProposalFit fit;
  fit.mean =
      Pose2(mode.x + mean_offset.x(), mode.y + mean_offset.y(), mode.theta + mean_offset.z());
  fit.covariance = cov;
  fit.log_eta = max_log_w + std::log(sum);
  fit.samples = n;
  return fit;
}

}  // namespace detail
}  // namespace tessera::scan_matching
